"""`blindgrasp-pipeline --preset {quick,cpu,paper}`: the whole method, end to end, ending in a report.

    blindgrasp-pipeline --preset quick                # ~10-15 min on a 2-core laptop: checks the plumbing
    blindgrasp-pipeline --preset cpu                  # hours on 2 cores: where success is measured
    blindgrasp-pipeline --preset paper                # the paper's tables: a GPU machine

Stages, each a real CLI run as a subprocess (its command and log are kept in <out>/logs/):
1. teacher training (`blindgrasp-train-teacher`) and its per-object success (`blindgrasp-eval-teacher`);
2. curated demos (`blindgrasp-collect-demos`) as a LeRobotDataset;
3. the student (`lerobot-train --policy.type=blindgrasp_transformer`);
4. the student in sim (`lerobot-eval --env.type=blindgrasp --env.task=all`);
5. `report.md` with PNG plots: teacher vs student success per object, learning curves, demo yield, and the
   commands to go bigger.
A stage whose output is complete is skipped, so re-running after an interruption continues where it stopped.
"""

from __future__ import annotations

import argparse
import json
import os
import re
import shlex
import subprocess
import sys
import time
from dataclasses import asdict, dataclass
from pathlib import Path



@dataclass(frozen=True)
class PipelinePreset:
    name: str
    teacher_preset: str
    teacher_eval_episodes: int  # per object and mode
    demo_episodes_per_object: int
    demo_max_rollouts_per_object: int
    demo_num_envs: int
    # Below this many curated episodes the student cannot learn anything; the pipeline then also collects the
    # uncurated ("w/o curation") set and trains on it, and says so in the report.
    min_curated_episodes: int
    student_size: str
    student_steps: int
    student_batch: int
    eval_episodes_per_object: int
    eval_task: str = "all"  # lerobot-eval --env.task
    teacher_iterations: int | None = None  # None: the teacher preset's own
    teacher_num_envs: int | None = None


PRESETS = {
    p.name: p
    for p in (
        PipelinePreset("quick", "quick", 4, 4, 8, 144, 18, "quick", 300, 64, 2),
        # lerobot-train reads ~2 ms per 30-frame sample here: 5000 steps at batch 256 is about an hour.
        PipelinePreset("cpu", "cpu", 20, 40, 400, 360, 90, "cpu", 5_000, 256, 10),
        # Paper: 89,500 curated samples, 2000 epochs at batch 256 (Table IV) = 700k steps; 500 envs per object.
        PipelinePreset("paper", "paper", 50, 5000, 20_000, 9000, 1000, "paper", 700_000, 256, 50),
        # CI smoke test of the plumbing only: every stage runs for seconds.
        PipelinePreset("smoke", "quick", 1, 1, 2, 36, 18, "quick", 4, 8, 1, eval_task="cylinder_a_medium",
                       teacher_iterations=2, teacher_num_envs=36),
    )
}

BIGGER = """\
Go bigger (same command, another preset):

    blindgrasp-pipeline --preset cpu     # 2-core machine: ~1.5-2 h teacher, ~30 min demos, ~1 h student
    blindgrasp-pipeline --preset paper   # GPU machine, the paper's Tables III-IV; see scripts/paper_recipe.sh
"""


class Stage:
    """Runs one CLI with its output in logs/<name>.log, and records command and wall time."""

    def __init__(self, out: Path, record: dict):
        self.out = out
        self.record = record
        (out / "logs").mkdir(parents=True, exist_ok=True)

    def run(self, name: str, cmd: list[str], env: dict | None = None) -> None:
        log_path = self.out / "logs" / f"{name}.log"
        print(f"[pipeline] {name}: {shlex.join(cmd)}", flush=True)
        t = time.time()
        with open(log_path, "w") as log:
            proc = subprocess.run(cmd, stdout=log, stderr=subprocess.STDOUT, env={**os.environ, **(env or {})})
        wall = time.time() - t
        self.record["stages"][name] = {"command": shlex.join(cmd), "wall_s": wall, "log": str(log_path)}
        self._save()
        if proc.returncode != 0:
            tail = log_path.read_text().splitlines()[-25:]
            raise SystemExit(f"[pipeline] {name} failed (exit {proc.returncode}); last lines of {log_path}:\n" + "\n".join(tail))
        print(f"[pipeline] {name} done in {wall:.0f} s", flush=True)

    def skip(self, name: str, why: str) -> None:
        print(f"[pipeline] {name}: skipped ({why})", flush=True)

    def _save(self) -> None:
        (self.out / "pipeline.json").write_text(json.dumps(self.record, indent=2))


def _bin(name: str) -> str:
    """The console script next to this interpreter (the venv's), so subprocesses use the same install."""
    cand = Path(sys.executable).parent / name
    return str(cand) if cand.exists() else name


def run_pipeline(preset: PipelinePreset, out: Path, seed: int) -> Path:
    out.mkdir(parents=True, exist_ok=True)
    record_path = out / "pipeline.json"
    record = json.loads(record_path.read_text()) if record_path.exists() else {"stages": {}}
    record["preset"] = asdict(preset)
    stage = Stage(out, record)
    # One torch thread per process: on 2 cores, intra-op threads of several processes fight (measured ~50x slower
    # lerobot-train steps at the quick size); MuJoCo's own threads are unaffected.
    env1 = {"OMP_NUM_THREADS": "1", "HF_HUB_OFFLINE": "1", "MUJOCO_GL": os.environ.get("MUJOCO_GL", "egl")}

    teacher_dir = out / "teacher"
    summary = teacher_dir / "train_summary.json"
    if summary.exists() and not json.loads(summary.read_text()).get("interrupted"):
        stage.skip("teacher", "trained")
    else:
        cmd = [_bin("blindgrasp-train-teacher"), "--preset", preset.teacher_preset, "--output-dir", str(teacher_dir),
               "--seed", str(seed)]
        if preset.teacher_iterations:
            cmd += ["--iterations", str(preset.teacher_iterations)]
        if preset.teacher_num_envs:
            cmd += ["--num-envs", str(preset.teacher_num_envs)]
        stage.run("teacher", cmd)
    teacher_eval = out / "teacher_eval"
    if (teacher_eval / "eval.json").exists():
        stage.skip("teacher_eval", "done")
    else:
        stage.run(
            "teacher_eval",
            [_bin("blindgrasp-eval-teacher"), str(teacher_dir), "--episodes", str(preset.teacher_eval_episodes),
             "--out", str(teacher_eval)],
        )

    repo = f"local/blindgrasp_{preset.name}"
    demos = _collect(stage, preset, teacher_dir, out / "demos", repo, seed, curate=True)
    kept = _kept(demos)
    train_set = demos
    record["student_dataset"] = "curated"
    if kept < preset.min_curated_episodes:
        print(f"[pipeline] only {kept} curated episodes (< {preset.min_curated_episodes}); also collecting the "
              "uncurated set and training the student on it", flush=True)
        repo = f"local/blindgrasp_{preset.name}_uncurated"
        train_set = _collect(stage, preset, teacher_dir, out / "demos_uncurated", repo, seed, curate=False)
        record["student_dataset"] = "uncurated (too few curated episodes)"

    student = out / "student"
    ckpt = student / "checkpoints" / "last" / "pretrained_model"
    if ckpt.exists():
        stage.skip("student", "trained")
    else:
        if student.exists():  # an interrupted lerobot-train: its output dir must not exist unless resuming
            os.replace(student, out / f"student_interrupted_{int(time.time())}")
        stage.run(
            "student",
            [_bin("lerobot-train"), "--policy.type=blindgrasp_transformer", f"--policy.size={preset.student_size}",
             f"--dataset.repo_id={repo}", f"--dataset.root={train_set}", f"--output_dir={student}",
             f"--steps={preset.student_steps}", f"--batch_size={preset.student_batch}",
             f"--save_freq={preset.student_steps}", f"--log_freq={max(1, preset.student_steps // 50)}",
             "--policy.push_to_hub=false", "--policy.device=cpu", "--num_workers=0", "--wandb.enable=false",
             f"--seed={seed}"],
            env=env1,
        )
    student_eval = out / "student_eval"
    if (student_eval / "eval_info.json").exists():
        stage.skip("student_eval", "done")
    else:
        stage.run(
            "student_eval",
            [_bin("lerobot-eval"), f"--policy.path={ckpt}", "--env.type=blindgrasp", f"--env.task={preset.eval_task}",
             f"--eval.n_episodes={preset.eval_episodes_per_object}",
             f"--eval.batch_size={preset.eval_episodes_per_object}", "--policy.device=cpu",
             f"--output_dir={student_eval}", f"--seed={seed + 1000}"],
            env=env1,
        )
    from lerobot_blindgrasp.report import write_report  # matplotlib, only now

    report = write_report(out, record, BIGGER)
    print(f"[pipeline] report: {report}", flush=True)
    return report


def _collect(stage: Stage, preset: PipelinePreset, teacher: Path, root: Path, repo_id: str, seed: int,
             curate: bool) -> Path:
    name = "demos" if curate else "demos_uncurated"
    if (root / "yield_report.json").exists() and (root / "meta" / "info.json").exists():
        stage.skip(name, "collected")
        return root
    cmd = [_bin("blindgrasp-collect-demos"), "--teacher", str(teacher), "--out", str(root), "--repo-id", repo_id,
           "--episodes-per-object", str(preset.demo_episodes_per_object),
           "--max-rollouts-per-object", str(preset.demo_max_rollouts_per_object),
           "--num-envs", str(preset.demo_num_envs), "--seed", str(seed + 500), "--no-progress"]
    if not curate:
        cmd.append("--no-curation")
    if root.exists():
        cmd.append("--resume")
    stage.run(name, cmd)
    return root


def _kept(root: Path) -> int:
    report = json.loads((root / "yield_report.json").read_text())
    return int(report["total"]["kept"])


def parse_step(s: str) -> float:
    m = re.fullmatch(r"([\d.]+)([KMB]?)", s)
    if not m:
        raise ValueError(s)
    return float(m.group(1)) * {"": 1, "K": 1e3, "M": 1e6, "B": 1e9}[m.group(2)]


def main(argv=None) -> None:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--preset", choices=sorted(PRESETS), default="quick")
    p.add_argument("--output-dir", type=Path, default=None, help="default: outputs/pipeline_<preset>")
    p.add_argument("--seed", type=int, default=1)
    args = p.parse_args(argv)
    out = args.output_dir or Path("outputs") / f"pipeline_{args.preset}"
    run_pipeline(PRESETS[args.preset], out, args.seed)


if __name__ == "__main__":
    main()
