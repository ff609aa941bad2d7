"""`torchrun --nproc_per_node=2 blindgrasp-train-teacher ...` on CPU: rsl-rl's multi-GPU mode with gloo.

End to end through torchrun: two processes, each with half of the envs (disjoint env seeds), rank 0's parameters
broadcast at the start and gradients all-reduced at every update, so both ranks finish with the same actor.
Only rank 0 writes the run directory. Uses the batch backend: the distribution does not depend on the physics
backend, and Warp on CPU would make this test take many minutes.
"""

from __future__ import annotations

import json
import socket
import subprocess
import sys
import textwrap

import pytest

DRIVER = textwrap.dedent(
    """
    import json, sys
    from dataclasses import replace
    from pathlib import Path
    import torch
    from lerobot_blindgrasp.presets import teacher as presets
    from lerobot_blindgrasp.teacher import distributed, train

    # A staged preset (as the shipped recipe): `quick` for 1 iteration first, then this one resumes it.
    presets.TEACHER_PRESETS["quick_staged"] = replace(presets.QUICK, name="quick_staged", stages=(("quick", 1),))

    seen = {}
    make = distributed.runner_class

    def spy(device):  # keep a handle on this rank's runner and env to report them after training
        cls = make(device)

        class Spy(cls):
            def __init__(self, env, *a, **k):
                super().__init__(env, *a, **k)
                seen["runner"], seen["env"] = self, env.env

        return Spy

    train.distributed.runner_class = spy
    cfg = train.parse_config(train.TrainTeacherConfig, sys.argv[1:])
    train.train(cfg)
    size, rank, _ = distributed.world()
    params = torch.cat([p.detach().flatten() for p in seen["runner"].alg.get_policy().parameters()])
    report = {
        "rank": rank, "world_size": size, "distributed": seen["runner"].is_distributed,
        "backend": torch.distributed.get_backend() if torch.distributed.is_initialized() else None,
        "env_seeds": seen["env"].env_seeds.tolist(), "params": params.tolist(),
    }
    (Path(cfg.output_dir) / f"rank{rank}.json").write_text(json.dumps(report))
    """
)


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


@pytest.mark.slow
def test_torchrun_two_cpu_processes_split_envs_and_sync_gradients(tmp_path):
    driver = tmp_path / "driver.py"
    driver.write_text(DRIVER)
    out = tmp_path / "run"
    cmd = [
        sys.executable, "-m", "torch.distributed.run", "--nproc_per_node=2", f"--master_port={_free_port()}",
        str(driver), "--preset=quick_staged", f"--output_dir={out}", "--iterations=2", "--num_envs=36", "--threads=1",
        "--export=false",
    ]  # fmt: skip
    proc = subprocess.run(
        cmd, capture_output=True, text=True, timeout=480
    )  # ~15 s of training; the rest is two cold imports (3 min on a loaded 2-core box)
    assert proc.returncode == 0, proc.stderr[-3000:]
    r0, r1 = (json.loads((out / f"rank{r}.json").read_text()) for r in (0, 1))
    assert r0["distributed"] and r1["distributed"] and r0["backend"] == "gloo" and r0["world_size"] == 2
    # envs split: 18 + 18, disjoint consecutive seeds covering the single-process run's 36
    assert len(r0["env_seeds"]) == len(r1["env_seeds"]) == 18
    assert sorted(r0["env_seeds"] + r1["env_seeds"]) == list(range(r0["env_seeds"][0], r0["env_seeds"][0] + 36))
    # gradients synced: the same actor and critic on both ranks after PPO updates on different data
    assert r0["params"] == r1["params"]
    # rank 0 alone writes the run: checkpoint, summary counting all ranks' env steps; the first stage ran
    # iteration 0, this one resumed its checkpoint and ran iteration 1
    summary = json.loads((out / "train_summary.json").read_text())
    assert summary["iterations"] == 2 and summary["env_steps_this_session"] == 1 * 24 * 36
    stage = json.loads((out / "stages" / "quick" / "train_summary.json").read_text())
    assert stage["iterations"] == 1 and stage["env_steps_this_session"] == 1 * 24 * 36
    assert (out / "model_0.pt").read_bytes() == (out / "stages" / "quick" / "model_0.pt").read_bytes()
    assert (out / "model_1.pt").exists() and (out / "train_console_rank1.log").exists()
