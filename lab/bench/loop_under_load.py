"""The real stack's 20 Hz control loop on a PC doing other work: its period under `stress-ng --cpu N`, with and
without the host mitigations (real-time priority, locked memory, no garbage collection inside a trial).

    python -m lab.bench.loop_under_load --loads=[0,2,4] --episodes=3 --episode_s=5 \\
        --output=docs/results/loop_under_load.json

The gripper is the physics twin (`lerobot_blindgrasp/twin/`), run in this process with its threads real-time: they
stand in for the servos' and the force board's own processors, which answer whatever the PC does. The host is
lerobot-eval's own pipeline (`--env.type=blindgrasp_real`, the shipped student, its processors, the robot's shipped
timing defaults) in a child process: per condition one child, one object, `--episodes` trials from the same seed,
each its whole `--episode_s` (the twin places the object; success is not the question here, so no criterion ends
a trial early).
The twin is calibrated once through `blindgrasp-twin-calibrate`, at no extra load.

Per condition it records every period the robot's `PeriodMonitor` measured (the trials and the homing between
them), their p50 / p99 / max, the overruns (> 1.5 periods), whether the run stopped (and why), and the 1-minute
load average sampled through the run (the machine is shared: the load is what it was, not what stress-ng added).
"""

from __future__ import annotations

import contextlib
import json
import os
import platform
import shutil
import subprocess
import sys
import tempfile
import threading
import time
from collections import deque
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[2]
BIN = Path(sys.executable).parent
# The host's side of each condition: no mitigation, the trial's GC pause, with a real-time priority, and all three.
CONDITIONS = {
    "none": ["--env.pause_gc=false"],
    "gc_pause": ["--env.pause_gc=true"],
    "gc_pause_realtime": ["--env.pause_gc=true", "--env.robot.realtime_priority=5"],
    "all": ["--env.pause_gc=true", "--env.robot.realtime_priority=5", "--env.robot.lock_memory=true"],
}


@dataclass
class LoopBenchConfig:
    loads: list[int] = field(default_factory=lambda: [0, 2, 4])  # stress-ng --cpu N workers per condition
    conditions: list[str] = field(default_factory=lambda: list(CONDITIONS))  # keys of CONDITIONS
    episodes: int = 3  # trials per condition
    episode_s: float = 5.0  # seconds per trial (the paper's is 10)
    object: str = "sphere_medium"
    seed: int = 1000  # every condition places the object from the same start states
    twin_realtime_priority: int = 10  # above the host's 5: the twin is the gripper's hardware
    output: Path | None = None  # JSON of every condition (written atomically)
    profile: bool = False  # cProfile each host's trials (host_<condition>_<load>.prof next to --output)
    host_args: Path | None = None  # internal: a JSON file of one condition's host (the child process runs it)


def host_argv(a: dict) -> list[str]:
    scale = ",".join(str(s) for s in a["scale_n_per_count"])
    return ["--policy.path=models/student_cpu", "--policy.device=cpu", "--env.type=blindgrasp_real",
            f"--env.task={a['object']}", "--env.robot.type=blindgrasp_gripper", "--env.robot.id=twin",
            f"--env.robot.calibration_dir={a['calibration_dir']}", f"--env.robot.port={a['dynamixel_port']}",
            f"--env.robot.force_sensor.port={a['force_port']}", f"--env.robot.force_sensor.scale_n_per_count=[{scale}]",
            f"--env.operator_socket={a['operator_socket']}", f"--env.episode_s={a['episode_s']}",
            # Every trial runs its whole episode_s (the same number of periods in each condition): the twin places
            # the object and presses ENTER, and no force criterion ends a trial early.
            "--env.success_mode=force", "--env.hold_force_n=1000",
            f"--env.trial_log={a['output_dir']}/trials.jsonl", *CONDITIONS[a["condition"]],
            f"--eval.n_episodes={a['episodes']}", "--eval.batch_size=1", "--eval.use_async_envs=false",
            f"--seed={a['seed']}", f"--output_dir={a['output_dir']}/eval"]  # fmt: skip


def run_host(a: dict) -> None:
    """lerobot-eval's `eval_main`, step for step, with the session's robot in reach: its PeriodMonitor keeps every
    period. Prints one JSON line."""
    from lerobot.configs import parser
    from lerobot.scripts import lerobot_eval as le

    le.register_third_party_plugins()
    sys.argv = ["lerobot-eval", *host_argv(a)]
    out: dict = {}

    def run(cfg) -> None:
        import torch

        le.set_seed(cfg.seed)
        envs = le.make_env(cfg.env, n_envs=1, use_async_envs=False, trust_remote_code=cfg.trust_remote_code)
        robot = next(iter(envs.values()))[0].envs[0].session.robot
        robot.timing.recent = deque()  # every period, not the last 200
        policy = le.make_policy(cfg=cfg.policy, env_cfg=cfg.env, rename_map=cfg.rename_map)
        policy.eval()
        pre, post = le.make_pre_post_processors(policy_cfg=cfg.policy, pretrained_path=cfg.policy.pretrained_path,
                                                preprocessor_overrides={"device_processor": {"device": "cpu"}, "rename_observations_processor": {"rename_map": cfg.rename_map}})  # fmt: skip
        env_pre, env_post = le.make_env_pre_post_processors(env_cfg=cfg.env, policy_cfg=cfg.policy)
        try:
            with torch.no_grad(), profiled(a.get("profile")):
                le.eval_policy_all(envs=envs, policy=policy, env_preprocessor=env_pre, env_postprocessor=env_post,
                                   preprocessor=pre, postprocessor=post, n_episodes=cfg.eval.n_episodes,
                                   max_episodes_rendered=10, videos_dir=Path(cfg.output_dir) / "videos",
                                   start_seed=cfg.seed, max_parallel_tasks=1)  # fmt: skip
        except Exception as e:  # the robot's safety latch: torque off, ports closed
            out["stopped"] = f"{type(e).__name__}: {e}"
        finally:
            le.close_envs(envs)
        out["periods_s"] = list(robot.timing.recent)
        out["overruns"] = robot.timing.overruns
        out["host_setup"] = getattr(robot, "host_setup", None)
        status = Path("/proc/self/status").read_text().splitlines()
        out["memory_kb"] = {
            k: int(v.split()[0]) for k, v in (x.split(":") for x in status) if k in ("VmRSS", "VmLck")
        }

    run.__annotations__["cfg"] = le.EvalPipelineConfig  # parser.wrap reads the type (this module's are strings)
    parser.wrap()(run)()
    print("RESULT " + json.dumps(out), flush=True)


@contextlib.contextmanager
def profiled(path: str | None):
    """cProfile over the trials (the host's `--profile` run), its stats written to `path`."""
    if not path:
        yield
        return
    import cProfile

    prof = cProfile.Profile()
    prof.enable()
    try:
        yield
    finally:
        prof.disable()
        prof.dump_stats(path)


def summarize(periods_s: list[float]) -> dict:
    v = np.asarray(periods_s) * 1e3
    if v.size == 0:
        return {"periods": 0}
    pct = {f"p{p}_ms": round(float(np.percentile(v, p)), 1) for p in (50, 99)}
    return {"periods": int(v.size), **pct, "max_ms": round(float(v.max()), 1)}


class LoadSampler(threading.Thread):
    """The 1-minute load average every 2 s, while a condition runs."""

    def __init__(self):
        super().__init__(daemon=True)
        self.samples: list[float] = []
        self.halt = threading.Event()

    def run(self) -> None:
        while not self.halt.wait(2.0):
            self.samples.append(os.getloadavg()[0])


def run_condition(cfg: LoopBenchConfig, ports: dict, calib: Path, condition: str, load: int, tmp: Path) -> dict:
    out_dir = tmp / f"{condition}_{load}"
    a = {**ports, "calibration_dir": str(calib), "object": cfg.object, "seed": cfg.seed, "episodes": cfg.episodes,
         "episode_s": cfg.episode_s, "condition": condition, "output_dir": str(out_dir)}  # fmt: skip
    if cfg.profile and cfg.output is not None:
        a["profile"] = str(cfg.output.with_name(f"host_{condition}_{load}.prof").resolve())
    stress = None
    if load > 0:
        stress = subprocess.Popen(["stress-ng", "--cpu", str(load), "--quiet"], start_new_session=True)
        time.sleep(3.0)  # the workers are spinning before the host starts
    sampler = LoadSampler()
    sampler.start()
    started = time.time()
    out_dir.mkdir(parents=True)
    (out_dir / "host.json").write_text(json.dumps(a))
    cmd = [sys.executable, "-m", "lab.bench.loop_under_load", f"--host_args={out_dir / 'host.json'}"]
    try:
        res = subprocess.run(cmd, cwd=ROOT, capture_output=True, text=True, timeout=600, env=host_env(tmp))
    finally:
        sampler.halt.set()
        if stress is not None:
            os.killpg(stress.pid, 15)
            stress.wait(timeout=30)
    line = [s for s in res.stdout.splitlines() if s.startswith("RESULT ")]
    if not line:
        raise RuntimeError(f"{condition} at load {load}: the host printed no result:\n{res.stderr[-3000:]}")
    r = json.loads(line[-1][len("RESULT ") :])
    trials = []
    if (out_dir / "trials.jsonl").is_file():
        trials = [json.loads(s) for s in (out_dir / "trials.jsonl").read_text().splitlines() if s.strip()]
    loadavg = sampler.samples or [os.getloadavg()[0]]
    return {"condition": condition, "stress_ng_cpu": load, **summarize(r["periods_s"]), "overruns": r["overruns"],
            "stopped": r.get("stopped"), "trials_completed": len(trials),
            "trial_overruns": [t["loop_overruns"] for t in trials], "step_ms": [t["step_ms"] for t in trials],
            "host_setup": r["host_setup"], "memory_kb": r["memory_kb"], "loadavg_1min": {"median": round(float(np.median(loadavg)), 2),
            "max": round(max(loadavg), 2)}, "wall_s": round(time.time() - started, 1)}  # fmt: skip


def host_env(tmp: Path) -> dict[str, str]:
    return {**os.environ, "HF_HUB_OFFLINE": "1", "HF_HOME": str(tmp / "hf"), "WANDB_MODE": "disabled",
            "PYTHONPATH": os.pathsep.join([str(ROOT), os.environ.get("PYTHONPATH", "")])}  # fmt: skip


def calibrate(ports: dict, tmp: Path) -> Path:
    from lerobot_blindgrasp import durable

    durable.atomic_write_json(tmp / "ports.json", ports)
    cmd = [str(BIN / "blindgrasp-twin-calibrate"), f"--ports_json={tmp / 'ports.json'}", "--robot_id=twin",
           f"--calibration_dir={tmp}", "--force=false"]  # fmt: skip
    res = subprocess.run(cmd, capture_output=True, text=True, timeout=300, env=host_env(tmp))
    if res.returncode != 0:
        raise RuntimeError(f"blindgrasp-twin-calibrate failed:\n{res.stdout[-3000:]}{res.stderr[-3000:]}")
    return tmp


def machine() -> dict:
    lscpu = subprocess.run(["lscpu"], capture_output=True, text=True).stdout
    model = next((s.split(":", 1)[1].strip() for s in lscpu.splitlines() if s.startswith("Model name")), "?")
    return {"cpu_model": model, "cpus": os.cpu_count(), "kernel": platform.release(),
            "rt_runtime_us": Path("/proc/sys/kernel/sched_rt_runtime_us").read_text().strip()}  # fmt: skip


def bench(cfg: LoopBenchConfig) -> dict:
    from lerobot_blindgrasp import durable
    from lerobot_blindgrasp.twin.command import TwinConfig
    from lerobot_blindgrasp.twin.runner import Twin

    if shutil.which("stress-ng") is None and any(cfg.loads):
        raise SystemExit("stress-ng is not installed (apt install stress-ng)")
    record = {"command": " ".join(["python -m lab.bench.loop_under_load", *sys.argv[1:]]),
              "date": time.strftime("%Y-%m-%d %H:%M UTC", time.gmtime()), "machine": machine(),
              "settings": {k: v for k, v in vars(cfg).items() if k not in ("output", "host_args", "profile")}, "runs": []}  # fmt: skip
    with tempfile.TemporaryDirectory(prefix="loopbench_") as d:
        tmp = Path(d)
        twin_cfg = TwinConfig(socket=str(tmp / "twin.sock"), realtime_priority=cfg.twin_realtime_priority)
        with Twin(twin_cfg) as twin:
            record["twin_realtime"] = twin.realtime
            calib = calibrate(twin.ports(), tmp)
            for load in cfg.loads:  # both conditions at one load back to back: the shared machine's load drifts
                for condition in cfg.conditions:
                    row = run_condition(cfg, twin.ports(), calib, condition, load, tmp)
                    print(json.dumps({k: v for k, v in row.items() if k != "step_ms"}), flush=True)
                    record["runs"].append(row)
                    if cfg.output is not None:
                        durable.atomic_write_json(cfg.output, record, indent=1)
    return record


def main(argv: list[str] | None = None) -> None:
    from lerobot_blindgrasp.cli import parse_config

    cfg = parse_config(LoopBenchConfig, argv)
    if cfg.host_args is not None:
        run_host(json.loads(cfg.host_args.read_text()))
        return
    bench(cfg)


if __name__ == "__main__":
    main()
