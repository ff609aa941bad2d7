"""`blindgrasp-pipeline --preset={quick_blind,quick,cpu,paper,smoke}`: the whole method, end to end, ending in a report.

    blindgrasp-pipeline                    # README command 1 (quick_blind, beyond the paper): ~10 min on 2 cores
    blindgrasp-pipeline --preset=quick_blind_targeted   # the shipped student's recipe (beyond the paper), ~17 min
    blindgrasp-pipeline --preset=quick     # the paper's student recipe on the default shipped teacher, ~13 min
    blindgrasp-pipeline --preset=cpu       # trains its own teacher from scratch: hours on 2 cores
    blindgrasp-pipeline --preset=paper --device=cuda    # the paper's Tables III-IV: a GPU machine
    blindgrasp-pipeline --preset=quick --teacher=runs/teacher_cpu     # any teacher folder instead

Every size comes from the preset registry (`lerobot_blindgrasp/presets/`); the command lines from
`lerobot_blindgrasp/pipeline/recipe.py`, which `scripts/paper_recipe.sh` uses too (`--print_commands=STAGE`). A draccus
config like LeRobot's scripts (`--help`, `--config_path`).

Stages, each a real CLI run as a subprocess (its command and log are kept in <out>/logs/):
1. the teacher: a shipped teacher (`quick_blind`, `quick`), a given `--teacher`, or trained from scratch
   (`blindgrasp-train-teacher`, presets `cpu`, `paper`, `smoke`);
2. curated demos (`blindgrasp-collect-demos`) as a LeRobotDataset; a preset with `extra_episodes` (beyond the
   paper) collects more of the objects it names, each on its own start states, and merges them in with LeRobot's
   `aggregate_datasets`;
3. the student (`lerobot-train --policy.type=blindgrasp_transformer`; an epoch-sized preset such as `paper` gets
   its step count and LR schedule from the collected dataset's frames, `presets.student`);
   With a DAgger stage (beyond the paper), `blindgrasp-dagger` then relabels the student's own episodes with the
   teacher's mean action and `lerobot-train` fine-tunes it on the aggregate, for each round;
4. the student in sim (`lerobot-eval --env.type=blindgrasp`) and the teacher on the *same* start states
   (`blindgrasp-eval-teacher --seed` = lerobot-eval's `--seed`; see spec.eval_env_seed);
5. `report.md` with PNG plots: which teacher, teacher vs student success per object with 95 % Wilson intervals
   and paired counts, learning curves, demo yield, the preset's deviations from the paper, and the commands to
   go bigger.
Re-running the same command after an interruption or a kill continues where it stopped: a stage is skipped once
it is marked completed in `pipeline.json`, a mark written (atomically) only after the stage's command succeeded,
so a stage's partial output is never taken for a finished one. A stage cut short is run again, and resumes where
its command can: the teacher from its newest checkpoint, the demos with `--resume=true` (repaired to their last
checkpoint); the student and the evaluations start over.
Env seeds: teacher training from `--seed`, demos from the demo range, evaluation from the eval range
(`spec.SEED_RANGES`), so no start state is used twice.
"""

from __future__ import annotations

import json
import os
import shlex
import shutil
import signal
import subprocess
import sys
import time
from dataclasses import asdict, dataclass
from pathlib import Path

from lerobot_blindgrasp import durable, presets, spec
from lerobot_blindgrasp.cli import parse_config, sleeping_openmp_threads
from lerobot_blindgrasp.pipeline import recipe

PRESETS = presets.PRESETS  # the registry itself, not a copy
COMPLETED = "completed"  # pipeline.json: the stages that finished, in order
DEMO_SEED_BLOCK = recipe.DEMO_SEED_BLOCK

BIGGER = """\
Go bigger (same command, another preset):

    blindgrasp-pipeline --preset=cpu     # the shipped teacher's recipe from scratch (~3 h on 2 cores), then demos, student
    blindgrasp-pipeline --preset=paper --device=cuda   # GPU machine, the paper's Tables III-IV
    bash scripts/paper_recipe.sh         # Table V: every ablation row at the paper preset's sizes
"""


@dataclass
class PipelineConfig:
    """The method end to end (teacher -> curated demos -> student -> paired sim eval -> report)."""

    # registry preset (lerobot_blindgrasp/presets): quick_blind (README command 1, beyond the paper), quick (the
    # paper's student recipe on the default shipped teacher), cpu, paper, smoke, ...
    preset: str = "quick_blind"
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


class Stage:
    """Runs one CLI with its output in logs/<name>.log, and records command and wall time."""

    def __init__(self, out: Path, record: dict):
        self.out = out
        self.record = record
        (out / "logs").mkdir(parents=True, exist_ok=True)

    def run(self, name: str, cmd: list[str], env: dict | None = None, ok: tuple[int, ...] = (0,)) -> int:
        cmd = [_bin(cmd[0]), *cmd[1:]]
        log_path = self.out / "logs" / f"{name}.log"
        print(f"[pipeline] {name}: {shlex.join(cmd)}", flush=True)
        t = time.time()
        with open(log_path, "w") as log:
            proc = subprocess.run(
                cmd,
                stdout=log,
                stderr=subprocess.STDOUT,
                env={**os.environ, **(env or {})},
                preexec_fn=_die_with_parent,
            )
        wall = time.time() - t
        self.record["stages"][name] = {
            "command": shlex.join(cmd),
            "wall_s": wall,
            "log": str(log_path),
            "returncode": proc.returncode,
        }
        if proc.returncode not in ok:
            self._save()
            tail = log_path.read_text().splitlines()[-25:]
            raise SystemExit(
                f"[pipeline] {name} failed (exit {proc.returncode}); last lines of {log_path}:\n" + "\n".join(tail)
            )
        self.complete(name)
        print(f"[pipeline] {name} done in {wall:.0f} s", flush=True)
        return proc.returncode

    def skip(self, name: str, why: str) -> None:
        print(f"[pipeline] {name}: skipped ({why})", flush=True)

    def complete(self, name: str) -> None:
        """Mark a stage finished: the last thing written for it, after all of its output."""
        done = self.record.setdefault(COMPLETED, [])
        if name not in done:
            done.append(name)
        self._save()

    def done(self, name: str, legacy: bool = False) -> bool:
        """Whether a stage finished. `legacy`: the output check of pipeline.json files written before completion
        marks existed (they have no COMPLETED list); ignored otherwise."""
        return name in self.record[COMPLETED] if COMPLETED in self.record else legacy

    def _save(self) -> None:
        durable.atomic_write_json(self.out / "pipeline.json", self.record, indent=2)


def _die_with_parent() -> None:
    """In the stage's process, before exec: on Linux, be killed when the pipeline dies, even by SIGKILL. Otherwise
    an orphaned stage would go on writing while the re-run pipeline starts the same stage in the same folder."""
    if sys.platform.startswith("linux"):
        import ctypes

        ctypes.CDLL(None).prctl(1, signal.SIGKILL)  # PR_SET_PDEATHSIG


def _bin(name: str) -> str:
    """The console script next to this interpreter (the venv's), so subprocesses use the same install."""
    cand = Path(sys.executable).parent / name
    return str(cand) if cand.exists() else name


def run_pipeline(cfg: PipelineConfig) -> Path:
    preset = presets.get(cfg.preset)
    out, seed, eval_seed = cfg.output_dir, cfg.seed, cfg.eval_seed
    device = cfg.device or preset.student.device
    demo_seed = recipe.demo_seed(seed)
    spec.check_seeds("demos", demo_seed, DEMO_SEED_BLOCK)  # one-line errors before any stage runs
    spec.eval_env_seed(eval_seed + preset.evaluation.episodes_per_object - 1, 0)
    out.mkdir(parents=True, exist_ok=True)
    record_path = out / "pipeline.json"
    record = json.loads(record_path.read_text()) if record_path.exists() else {"stages": {}, COMPLETED: []}
    record["preset"] = asdict(preset)
    record["deviations"] = list(preset.all_deviations)
    record["seeds"] = {"pipeline": seed, "demos_first_env_seed": demo_seed, "eval_index": eval_seed}
    record["device"] = device
    stage = Stage(out, record)
    # One torch thread per process: on 2 cores, intra-op threads of several processes fight (measured ~50x slower
    # lerobot-train steps at the quick size); MuJoCo's own threads are unaffected.
    env1 = {"OMP_NUM_THREADS": "1", "HF_HUB_OFFLINE": "1", "MUJOCO_GL": os.environ.get("MUJOCO_GL", "egl")}

    teacher_dir, record["teacher"] = _teacher(stage, preset, out, seed, cfg.teacher)
    eval_objects = recipe.objects_of(preset.evaluation.task)
    teacher_eval = out / "teacher_eval"
    if stage.done("teacher_eval", legacy=(teacher_eval / "eval.json").exists()):
        stage.skip("teacher_eval", "done")
    elif _reuse_teacher_eval(teacher_dir, teacher_eval, preset, eval_seed, eval_objects, note=record["teacher"]):
        stage.skip(
            "teacher_eval", f"the same start states were evaluated for this teacher in {teacher_dir / 'eval'}"
        )
        record["teacher"]["eval_reused_from"] = str(teacher_dir / "eval")
        stage.complete("teacher_eval")
    else:
        stage.run("teacher_eval", recipe.teacher_eval(preset, teacher_dir, teacher_eval, eval_seed))

    repo = f"local/blindgrasp_{preset.name}"
    demos = _collect(stage, preset, teacher_dir, out / "demos", repo, demo_seed, curate=True)
    kept = _kept(demos)
    train_set = demos
    record["student_dataset"] = "curated"
    if kept < preset.demos.min_curated_episodes:
        print(
            f"[pipeline] only {kept} curated episodes (< {preset.demos.min_curated_episodes}); also collecting the "
            "uncurated set and training the student on it",
            flush=True,
        )
        repo = f"local/blindgrasp_{preset.name}_uncurated"
        train_set = _collect(
            stage,
            preset,
            teacher_dir,
            out / "demos_uncurated",
            repo,
            demo_seed + DEMO_SEED_BLOCK // 2,
            curate=False,
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

    student = out / "student"
    ckpt = recipe.checkpoint(student)
    cmd, sched = recipe.student_train(preset, train_set, repo, student, seed, device)
    record["student_schedule"] = asdict(sched)
    if stage.done("student", legacy=ckpt.exists()):
        stage.skip("student", "trained")
    else:
        if student.exists():  # an interrupted lerobot-train: its output dir must not exist unless resuming
            os.replace(student, out / f"student_interrupted_{int(time.time())}")
        stage.run("student", cmd, env={**env1, "OMP_NUM_THREADS": str(preset.student.threads)})
    record["student_recipe"] = preset.student_recipe
    if preset.dagger is not None:
        ckpt = _dagger_rounds(
            stage,
            preset,
            out,
            teacher_dir,
            train_set,
            ckpt,
            seed,
            device,
            {**env1, "OMP_NUM_THREADS": str(preset.student.threads)},
        )
    record["student_checkpoint"] = str(ckpt)
    student_eval = out / "student_eval"
    if stage.done("student_eval", legacy=(student_eval / "eval_info.json").exists()):
        stage.skip("student_eval", "done")
    else:
        stage.run("student_eval", recipe.student_eval(preset, ckpt, student_eval, eval_seed, device), env=env1)
    from lerobot_blindgrasp.pipeline.report import write_report  # matplotlib, only now

    report = write_report(out, record, BIGGER)
    print(f"[pipeline] report: {report}", flush=True)
    return report


def _dagger_rounds(
    stage: Stage,
    preset: presets.Preset,
    out: Path,
    teacher: Path,
    demos: Path,
    ckpt: Path,
    seed: int,
    device: str,
    env: dict,
) -> Path:
    """DAgger rounds (beyond the paper): the latest student drives, the teacher labels, the student is fine-tuned on
    the aggregate. Returns the final student's checkpoint."""
    from lerobot_blindgrasp.demos.dagger import DONE

    for r in range(1, preset.dagger.rounds + 1):
        name, relabelled, student = f"dagger_{r}", out / f"dagger_{r}", out / f"student_dagger_{r}"
        if stage.done(name, legacy=(relabelled / DONE).is_file()):
            stage.skip(name, "relabelled")
        else:
            stage.run(
                name,
                recipe.dagger(preset, ckpt, teacher, demos, relabelled, recipe.dagger_seed(seed, r), device),
                env=env,
            )
        demos, repo = relabelled / "aggregate", f"local/blindgrasp_{preset.name}_dagger_{r}"
        if stage.done(f"student_dagger_{r}", legacy=recipe.checkpoint(student).exists()):
            stage.skip(f"student_dagger_{r}", "trained")
        else:
            if student.exists():  # an interrupted lerobot-train: its output dir must not exist unless resuming
                os.replace(student, out / f"student_dagger_{r}_interrupted_{int(time.time())}")
            stage.run(
                f"student_dagger_{r}",
                recipe.student_finetune(preset, ckpt, demos, repo, student, seed, device),
                env=env,
            )
        ckpt = recipe.checkpoint(student)
    return ckpt


def _teacher(stage: Stage, preset: presets.Preset, out: Path, seed: int, given: Path | None) -> tuple[Path, dict]:
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
        return path, {
            "source": source,
            "path": str(path),
            "file": t.name,
            "sha256": t.sha256,
            "iteration": t.iteration,
            "preset": t.config.get("preset"),
        }
    teacher_dir = out / "teacher"
    if stage.done("teacher", legacy=recipe.teacher_trained(teacher_dir)):
        stage.skip("teacher", "trained")
    else:
        spec.check_seeds("teacher_train", seed, preset.teacher.num_envs or preset.teacher.settings.num_envs)
        stage.run("teacher", recipe.teacher_train(preset, teacher_dir, seed))
    t = TeacherPolicy(teacher_dir)
    name = preset.teacher.settings.name
    return teacher_dir, {
        "source": f"trained from scratch in this run (teacher preset `{name}`)",
        "path": str(teacher_dir),
        "file": t.name,
        "sha256": t.sha256,
        "iteration": t.iteration,
        "preset": name,
    }


def _reuse_teacher_eval(
    teacher_dir: Path,
    dest: Path,
    preset: presets.Preset,
    eval_seed: int,
    eval_objects: tuple[str, ...],
    note: dict | None = None,
) -> bool:
    """A shipped teacher may carry its eval (`<folder>/eval/eval.json`). Rollouts are functions of (teacher, start
    states, torch seed, sim code, float platform), so an eval of the same weights on the same start states under
    the same sim sources, made on this CPU family, is the paired eval; reuse it rather than spend minutes
    recomputing it. One from another family (its floats drift, and a contact-rich episode can end otherwise) is
    re-run here: `note["eval_rerun_because"]` then says why, for the report."""
    from lerobot_blindgrasp import platform_id
    from lerobot_blindgrasp.teacher.evaluate import sim_fingerprint
    from lerobot_blindgrasp.teacher.policy import TeacherPolicy

    src = teacher_dir / "eval" / "eval.json"
    if not src.is_file():
        return False
    prev = json.loads(src.read_text())
    same = (
        prev.get("checkpoint_sha256") == TeacherPolicy(teacher_dir).sha256
        and prev.get("sim_fingerprint") == sim_fingerprint()
        and prev.get("seed") == eval_seed
        and prev.get("episodes_per_object") == preset.evaluation.episodes_per_object
        and prev.get("objects") == list(eval_objects)
        and set(preset.evaluation.teacher_modes) <= set(prev.get("modes", {}))
    )
    here = platform_id.platform()
    if same and not platform_id.same(prev.get("platform"), here):
        why = (
            f"the carried eval {src} was recorded on {platform_id.describe(prev.get('platform'))}, and this "
            f"machine is {platform_id.describe(here)}"
        )
        print(
            f"[pipeline] {why}: re-running the teacher's eval here, so that teacher and student are paired on "
            "one machine's floats",
            flush=True,
        )
        if note is not None:
            note["eval_rerun_because"] = why
        return False
    if same:  # copied beside dest, then renamed: a kill mid-copy leaves no eval.json that looks finished
        tmp = dest.with_name(f".{dest.name}{durable.TEMP_MARK}copy")
        shutil.rmtree(tmp, ignore_errors=True)
        shutil.copytree(src.parent, tmp)
        shutil.rmtree(dest, ignore_errors=True)
        os.replace(tmp, dest)
    return same


def _collect(
    stage: Stage,
    preset: presets.Preset,
    teacher: Path,
    root: Path,
    repo_id: str,
    first_seed: int,
    curate: bool,
    extra: tuple[str, int] | None = None,
) -> Path:
    name = root.name if extra else "demos" if curate else "demos_uncurated"
    if stage.done(name, legacy=recipe.demos_collected(root)):
        stage.skip(name, "collected")
        return root
    from lerobot_blindgrasp.demos.collect import EXIT_EMPTY

    # An empty curated set is handled by the caller (uncurated fallback). A collection cut short is resumed
    # (recipe.collect adds --resume=true; the collector repairs a crashed folder first).
    stage.run(
        name,
        recipe.collect(preset, teacher, root, repo_id, first_seed, curate=curate, extra=extra),
        ok=(0, EXIT_EMPTY),
    )
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
    """Beyond the paper: the preset's extra episodes of the objects it names (one collection each, curated or not
    as the set the student trains on), merged with that set by LeRobot's `aggregate_datasets`. Returns the merged
    dataset and its repo id."""
    roots, repos = [demos], [repo]
    for k, (name, n) in enumerate(preset.demos.extra_episodes):
        root, extra_repo = out / f"{demos.name}_{name}", f"{repo}_{name}"
        _collect(
            stage,
            preset,
            teacher,
            root,
            extra_repo,
            recipe.extra_demo_seed(seed, k, curated),
            curate=curated,
            extra=(name, n),
        )
        if _kept(root):  # an object the teacher never solved adds nothing (its yield report says so)
            roots.append(root)
            repos.append(extra_repo)
    name = f"{demos.name}_targeted"
    merged, merged_repo = out / name, f"{repo}_merged"
    if stage.done(name, legacy=False):
        stage.skip(name, "merged")
        return merged, merged_repo
    from lerobot_blindgrasp.demos.dataset import aggregate

    # Merged beside the destination, then renamed: a kill mid-merge leaves no folder that looks finished.
    tmp = out / f".{name}{durable.TEMP_MARK}merge"
    shutil.rmtree(tmp, ignore_errors=True)
    t = time.time()
    aggregate(repos, roots, merged_repo, tmp)
    durable.fsync_tree(tmp)
    shutil.rmtree(merged, ignore_errors=True)
    os.replace(tmp, merged)
    durable.fsync_dir(out)
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
            print(
                recipe.shell_lines(
                    recipe.table_v(
                        presets.get(cfg.preset),
                        cfg.output_dir,
                        cfg.print_commands,
                        cfg.seed,
                        cfg.eval_seed,
                        cfg.device,
                    )
                )
            )
            return
        run_pipeline(cfg)
    except ValueError as e:  # seeds outside their ranges, a stage printed before its inputs exist
        raise SystemExit(f"[pipeline] error: {e}") from None


if __name__ == "__main__":
    main()
