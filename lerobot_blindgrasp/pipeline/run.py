"""`blindgrasp-pipeline --preset=NAME`: the whole method, end to end, ending in a report (the presets and their run
times: docs/getting-started.md). Sizes come from the preset registry (`presets/`), command lines from `recipe.py`.

Each stage is a real CLI run as a subprocess with its log in <out>/logs/: the teacher (shipped, `--teacher`, or
trained), curated demos, the student (`lerobot-train`) and any DAgger rounds, the student in sim (`lerobot-eval`)
and the teacher on the same start states, then `report.md`. A re-run skips each stage `pipeline.json` marks completed
(marked only after its command succeeded) and runs one cut short again, resuming where its command can. Each stage
draws env seeds from its own range (`spec.SEED_RANGES`), so no start state is used twice.
"""

from __future__ import annotations

import json
import os
import time
from dataclasses import asdict, dataclass
from pathlib import Path

from lerobot_blindgrasp import presets, spec
from lerobot_blindgrasp.cli import parse_config, sleeping_openmp_threads
from lerobot_blindgrasp.pipeline import recipe
from lerobot_blindgrasp.pipeline.stage import COMPLETED, Stage

BIGGER = """\
Go bigger (same command, another preset):

    blindgrasp-pipeline --preset=cpu     # the shipped teacher's recipe from scratch (~3 h on 2 cores), then demos, student
    blindgrasp-pipeline --preset=paper --device=cuda   # GPU machine, the paper's Tables III-IV
    bash scripts/paper_recipe.sh         # Table V: every ablation row at the paper preset's sizes
"""


@dataclass
class PipelineConfig:
    """The method end to end (teacher -> curated demos -> student -> paired sim eval -> report)."""

    preset: str = "quick_blind"  # a registry preset (`lerobot_blindgrasp/presets`, listed in docs/reference.md)
    output_dir: Path | None = None  # default outputs/pipeline_<preset>; re-running continues where it stopped
    seed: int = spec.TEACHER_TRAIN_SEED  # teacher-training env seed and torch seed; also picks the demo seed block
    teacher: Path | None = None  # this teacher folder instead of the preset's (shipped or trained from scratch)
    eval_seed: int = spec.EVAL_SEED  # lerobot-eval --seed, and the teacher eval's: both run the same start states
    device: str | None = None  # torch device for the student (default: the preset's)
    # A Table V stage (teachers, teacher_evals, demos, students, evals): print its commands that are not done yet
    # under output_dir, one shell line each, and exit. scripts/paper_recipe.sh runs them.
    print_commands: str | None = None

    def __post_init__(self):
        presets.get(self.preset)  # an unknown preset: one line before anything runs
        self.output_dir = Path(self.output_dir or Path("outputs") / f"pipeline_{self.preset}")
        self.teacher = None if self.teacher is None else Path(self.teacher)
        if self.print_commands is not None and self.print_commands not in recipe.STAGES:
            raise ValueError(f"--print_commands takes one of {', '.join(recipe.STAGES)}")


def run_pipeline(cfg: PipelineConfig) -> Path:
    preset = presets.get(cfg.preset)
    out, seed, eval_seed = cfg.output_dir, cfg.seed, cfg.eval_seed
    device = cfg.device or preset.student.device
    demo_seed = recipe.demo_seed(seed)
    spec.check_seeds("demos", demo_seed, recipe.DEMO_SEED_BLOCK)  # one-line errors before any stage runs
    spec.eval_env_seed(eval_seed + preset.evaluation.episodes_per_object - 1, 0)
    out.mkdir(parents=True, exist_ok=True)
    record_path = out / "pipeline.json"
    record = json.loads(record_path.read_text()) if record_path.exists() else {"stages": {}, COMPLETED: []}
    record["preset"] = asdict(preset)
    record["deviations"] = list(preset.all_deviations)
    record["seeds"] = {"pipeline": seed, "demos_first_env_seed": demo_seed, "eval_index": eval_seed}
    record["device"] = device
    stage = Stage(out, record)
    # One torch thread per process: on few cores, intra-op threads of several processes fight (MuJoCo's are apart).
    env1 = {"OMP_NUM_THREADS": "1", "HF_HUB_OFFLINE": "1", "MUJOCO_GL": os.environ.get("MUJOCO_GL", "egl")}
    student_env = {**env1, "OMP_NUM_THREADS": str(preset.student.threads)}

    teacher_dir, record["teacher"] = teacher_for_run(stage, preset, out, seed, cfg.teacher)
    # The teacher on the student's evaluation start states, in this run: paired on this machine's floats.
    stage.once("teacher_eval", "done", recipe.teacher_eval(preset, teacher_dir, out / "teacher_eval", eval_seed))
    train_set, repo = _demos(stage, preset, teacher_dir, out, seed, demo_seed)
    cmd, sched = recipe.lerobot_train(preset.student, train_set, repo, out / "student", seed, device)
    record["student_schedule"] = asdict(sched)
    ckpt = _train(stage, "student", out / "student", cmd, student_env)
    record["student_recipe"] = preset.student_recipe
    # DAgger rounds (beyond the paper): the latest student drives, the teacher labels, the student is fine-tuned.
    for r in range(1, (preset.dagger.rounds if preset.dagger else 0) + 1):
        relabelled, name = out / f"dagger_{r}", f"student_dagger_{r}"
        dagger_seed = recipe.dagger_seed(seed, r)
        stage.once(
            f"dagger_{r}",
            "relabelled",
            recipe.dagger(preset, ckpt, teacher_dir, train_set, relabelled, dagger_seed, device),
            env=student_env,
        )
        train_set, repo = relabelled / "aggregate", f"local/blindgrasp_{preset.name}_dagger_{r}"
        cmd = recipe.student_finetune(preset, ckpt, train_set, repo, out / name, seed, device)
        ckpt = _train(stage, name, out / name, cmd, student_env)
    record["student_checkpoint"] = str(ckpt)
    stage.once(
        "student_eval",
        "done",
        recipe.student_eval(preset, ckpt, out / "student_eval", eval_seed, device),
        env=env1,
    )
    from lerobot_blindgrasp.pipeline.job_report import write_job_report  # matplotlib, only now

    report = write_job_report(out, record, BIGGER)
    print(f"[pipeline] report: {report}", flush=True)
    return report


def _train(stage: Stage, name: str, student: Path, cmd: list[str], env: dict) -> Path:
    """lerobot-train into `student` unless done; returns its checkpoint. An interrupted run's folder is moved aside:
    lerobot-train refuses an existing output dir unless resuming."""
    if stage.done(name):
        stage.skip(name, "trained")
    else:
        if student.exists():
            os.replace(student, student.with_name(f"{student.name}_interrupted_{int(time.time())}"))
        stage.run(name, cmd, env=env)
    return recipe.checkpoint(student)


def teacher_for_run(
    stage: Stage, preset: presets.Preset, out: Path, seed: int, given: Path | None
) -> tuple[Path, dict]:
    """The teacher folder for this run and what the report says about it."""
    from lerobot_blindgrasp.teacher.policy import TeacherError, TeacherPolicy, default_teacher

    if given is not None or preset.teacher.shipped:
        try:
            path = Path(given) if given is not None else default_teacher(preset.teacher.shipped_folder)
            t = TeacherPolicy(path)
        except TeacherError as e:
            raise SystemExit(f"[pipeline] error: {e}") from None
        shipped = "shipped" if preset.teacher.shipped_folder else "shipped default"
        stage.skip("teacher", f"using {'the given' if given is not None else 'the ' + shipped} teacher {path}")
        source = "given (--teacher)" if given is not None else shipped
        preset_name = t.config.get("preset")
    else:
        path, preset_name = out / "teacher", preset.teacher.settings.name
        source = f"trained from scratch in this run (teacher preset `{preset_name}`)"
        if stage.done("teacher"):
            stage.skip("teacher", "trained")
        else:
            spec.check_seeds("teacher_train", seed, preset.teacher.num_envs or preset.teacher.settings.num_envs)
            stage.run("teacher", recipe.teacher_train(preset, path, seed))
        t = TeacherPolicy(path)
    return path, {
        "source": source,
        "path": str(path),
        "file": t.name,
        "sha256": t.sha256,
        "iteration": t.iteration,
        "preset": preset_name,
    }


def _demos(
    stage: Stage, preset: presets.Preset, teacher_dir: Path, out: Path, seed: int, demo_seed: int
) -> tuple[Path, str]:
    """The set the student trains on: the curated demos (the uncurated ones when too few pass curation), with the
    preset's extra episodes merged in. Returns the dataset and its repo id."""
    record = stage.record
    repo = f"local/blindgrasp_{preset.name}"
    demos = _collect_stage(stage, preset, teacher_dir, out / "demos", repo, demo_seed, curate=True)
    train_set = demos
    record["student_dataset"] = "curated"
    if (k := _kept(demos)) < preset.demos.min_curated_episodes:
        print(
            f"[pipeline] only {k} curated episodes (< {preset.demos.min_curated_episodes}); also collecting the "
            "uncurated set and training the student on it",
            flush=True,
        )
        repo = f"local/blindgrasp_{preset.name}_uncurated"
        uncurated_seed = demo_seed + recipe.DEMO_SEED_BLOCK // 2
        train_set = _collect_stage(
            stage, preset, teacher_dir, out / "demos_uncurated", repo, uncurated_seed, curate=False
        )
        record["student_dataset"] = "uncurated (too few curated episodes)"
    if _kept(train_set) == 0:
        raise SystemExit(
            f"[pipeline] error: the demo dataset {train_set} has no episodes, so there is nothing to "
            "train the student on; use a better teacher (--teacher) or more rollouts"
        )
    if preset.demos.extra_episodes:
        curated = train_set == demos
        train_set, repo = _targeted_demos(stage, preset, teacher_dir, out, train_set, repo, seed, curated)
        record["student_dataset"] += ", with " + ", ".join(
            f"{n} more episodes of {name}" for name, n in preset.demos.extra_episodes
        )
    return train_set, repo


def _collect_stage(
    stage: Stage,
    preset: presets.Preset,
    teacher: Path,
    root: Path,
    repo_id: str,
    first_seed: int,
    curate: bool,
    extra: tuple[str, int] | None = None,
) -> Path:
    from lerobot_blindgrasp.demos.collect_cli import EXIT_EMPTY

    name = root.name if extra else "demos" if curate else "demos_uncurated"
    # An empty curated set is the caller's (the uncurated fallback). A collection cut short is resumed
    # (recipe.demos_collect adds --resume=true; the collector repairs a crashed folder first).
    cmd = recipe.demos_collect(preset, teacher, root, repo_id, first_seed, curate=curate, extra=extra)
    stage.once(name, "collected", cmd, ok=(0, EXIT_EMPTY))
    return root


def _targeted_demos(
    stage: Stage,
    preset: presets.Preset,
    teacher: Path,
    out: Path,
    demos: Path,
    repo: str,
    seed: int,
    curated: bool,
) -> tuple[Path, str]:
    """Beyond the paper: (merged dataset, repo id) of the set the student trains on and the preset's extra episodes
    of the objects it names, one collection each, curated or not as that set (LeRobot's `aggregate_datasets`)."""
    roots, repos = [demos], [repo]
    for k, (name, n) in enumerate(preset.demos.extra_episodes):
        root, extra_repo = out / f"{demos.name}_{name}", f"{repo}_{name}"
        first_seed = recipe.extra_demo_seed(seed, k, curated)
        _collect_stage(stage, preset, teacher, root, extra_repo, first_seed, curate=curated, extra=(name, n))
        if _kept(root):  # an object the teacher never solved adds nothing (its yield report says so)
            roots.append(root)
            repos.append(extra_repo)
    name = f"{demos.name}_targeted"
    merged, merged_repo = out / name, f"{repo}_merged"
    if stage.done(name):
        stage.skip(name, "merged")
        return merged, merged_repo
    from lerobot_blindgrasp.demos.dataset import aggregate

    t = time.time()
    aggregate(repos, roots, merged_repo, merged)  # built beside `merged`: a kill leaves no finished-looking folder
    stage.record["stages"][name] = {
        "command": f"aggregate_datasets({repos})",
        "wall_s": time.time() - t,
        "roots": [str(r) for r in roots],
    }
    stage.complete(name)
    print(f"[pipeline] {name}: merged {len(roots)} datasets into {merged}", flush=True)
    return merged, merged_repo


def _kept(root: Path) -> int:
    report = json.loads((root / "yield_report.json").read_text())
    return int(report["total"]["kept"])


def main(argv=None) -> None:
    sleeping_openmp_threads(restart=False)  # for the stages it starts; the pipeline itself computes little
    cfg = parse_config(PipelineConfig, argv)
    try:
        if cfg.print_commands:
            preset = presets.get(cfg.preset)
            cmds = recipe.table_v(preset, cfg.output_dir, cfg.print_commands, cfg.seed, cfg.eval_seed, cfg.device)
            print(recipe.shell_lines(cmds))
            return
        run_pipeline(cfg)
    except ValueError as e:  # seeds outside their ranges, a stage printed before its inputs exist
        raise SystemExit(f"[pipeline] error: {e}") from None


if __name__ == "__main__":
    main()
