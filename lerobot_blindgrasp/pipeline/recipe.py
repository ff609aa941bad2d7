"""The command line of every stage, built from a registry preset: one definition for `blindgrasp-pipeline` and for
`scripts/paper_recipe.sh`, which runs Table V stage by stage (`--print_commands=STAGE` prints the commands of that
stage not done yet). Student steps come from the collected dataset (`presets.student`), so `students` can only be
printed once the demos exist.
"""

from __future__ import annotations

import json
import shlex
import time
from pathlib import Path

from lerobot_blindgrasp import presets, spec
from lerobot_blindgrasp.sim import objects

STAGES = ("teachers", "teacher_evals", "demos", "students", "evals")
# Each pipeline --seed gets its own block of demo env seeds, so reruns with another seed are new draws.
DEMO_SEED_BLOCK = 1 << 24


def demo_seed(seed: int) -> int:
    return spec.DEMO_SEED + seed * DEMO_SEED_BLOCK


def extra_demo_seed(seed: int, k: int, curated: bool = True) -> int:
    """First env seed of the k-th (0-based) extra collection of `DemoStage.extra_episodes`, 2^20 env seeds each: the
    second quarter of the pipeline seed's demo block, or its fourth for the uncurated fallback's extras (the
    fallback itself starts at the block's half)."""
    if not 0 <= k < 4:
        raise ValueError(f"at most 4 objects get extra episodes, not {k + 1}")
    return demo_seed(seed) + (1 if curated else 3) * DEMO_SEED_BLOCK // 4 + k * (DEMO_SEED_BLOCK // 16)


def teacher_train(
    p: presets.Preset, out: Path, seed: int, variant: presets.Variant = presets.Variant()
) -> list[str]:
    """blindgrasp-train-teacher of the preset's teacher, or of a Table V teacher ablation (`variant`) on the preset's
    ablation teacher."""
    t = p.teacher_stage(variant)
    cmd = ["blindgrasp-train-teacher", f"--preset={t.settings.name}", f"--output_dir={out}", f"--seed={seed}"]
    if t.iterations:
        cmd.append(f"--iterations={t.iterations}")
    if t.num_envs:
        cmd.append(f"--num_envs={t.num_envs}")
    if variant.no_incentive:
        cmd.append("--no_incentive=true")
    if variant.student_obs:
        cmd.append("--student_obs=true")
    return cmd


def teacher_eval(p: presets.Preset, teacher_dir: Path, dest: Path, eval_seed: int) -> list[str]:
    e = p.evaluation
    return [
        "blindgrasp-eval-teacher",
        f"--teacher={teacher_dir}",
        f"--episodes={e.episodes_per_object}",
        f"--objects={','.join(objects.resolve_objects(e.task))}",
        f"--seed={eval_seed}",
        f"--modes={','.join(e.teacher_modes)}",
        f"--output_dir={dest}",
    ]


def demos_collect(
    p: presets.Preset,
    teacher: Path,
    root: Path,
    repo_id: str,
    first_seed: int,
    *,
    curate: bool = True,
    stochastic: bool = True,
    extra: tuple[str, int] | None = None,
) -> list[str]:
    """blindgrasp-collect-demos of the preset's demos, or (`extra` = (object, episodes)) of one of its
    `extra_episodes` collections, with the collector's default rollout budget (20 x the episodes)."""
    from lerobot_blindgrasp.demos.config import DEFAULT_ROLLOUT_BUDGET_FACTOR

    d = p.demos
    episodes, budget = d.episodes_per_object, d.max_rollouts_per_object
    if extra is not None:
        episodes, budget = extra[1], DEFAULT_ROLLOUT_BUDGET_FACTOR * extra[1]
    cmd = [
        "blindgrasp-collect-demos",
        f"--teacher={teacher}",
        f"--output_dir={root}",
        f"--repo_id={repo_id}",
        f"--episodes_per_object={episodes}",
        f"--max_rollouts_per_object={budget}",
        f"--num_envs={d.num_envs}",
        f"--seed={first_seed}",
        "--progress=false",
    ]
    if extra is not None:
        cmd.append(f"--objects={extra[0]}")
    if d.joint_calibration_rad:
        cmd.append(f"--joint_calibration_rad={d.joint_calibration_rad}")
    if not stochastic:
        cmd.append("--stochastic=false")
    if not curate:
        cmd.append("--curation.enabled=false")
    if root.exists():
        cmd.append("--resume=true")
    return cmd


def lerobot_train(
    s: presets.StudentStage, dataset: Path, repo_id: str, out: Path, seed: int, device: str | None = None
) -> tuple[list[str], presets.Schedule]:
    """lerobot-train of a student stage on a dataset (a sim demo set or glove recordings); the step count (and LR
    schedule) follows from the dataset's frames once it is complete."""
    frames = presets.dataset_frames(dataset) if (dataset / "meta" / "info.json").exists() else None
    sched = presets.schedule(s, frames)
    extra = []
    if sched.constant_lr_steps is not None:
        extra.append(f"--policy.scheduler_constant_steps={sched.constant_lr_steps}")
    if s.lr is not None:
        extra.append(f"--policy.optimizer_lr={s.lr}")
    policy = ["--policy.type=blindgrasp_transformer", f"--policy.size={s.size}"]
    cmd = _lerobot_train(s, policy, dataset, repo_id, out, sched.steps, seed, device, [*extra, *s.policy_flags])
    return cmd, sched


def _lerobot_train(
    s: presets.StudentStage,
    policy: list[str],
    dataset: Path,
    repo_id: str,
    out: Path,
    steps: int,
    seed: int,
    device: str | None,
    extra: list[str],
) -> list[str]:
    """The lerobot-train command both trainings share: `policy` says where the policy starts, `extra` follows the
    batch size."""
    return [
        "lerobot-train",
        *policy,
        f"--dataset.repo_id={repo_id}",
        f"--dataset.root={dataset}",
        f"--output_dir={out}",
        f"--steps={steps}",
        f"--batch_size={s.batch_size}",
        *extra,
        f"--save_freq={steps}",
        f"--log_freq={max(1, steps // 50)}",
        "--policy.push_to_hub=false",
        f"--policy.device={device or s.device}",
        f"--num_workers={s.num_workers}",
        "--wandb.enable=false",
        f"--seed={seed}",
    ]


def dagger_seed(seed: int, round_: int) -> int:
    """First env seed of DAgger round `round_` (1-based) of pipeline seed `seed`: its own demo-range block."""
    from lerobot_blindgrasp.demos.dagger import DAGGER_SEED

    return DAGGER_SEED + (8 * seed + round_) * DEMO_SEED_BLOCK


def dagger(
    p: presets.Preset,
    student_ckpt: Path,
    teacher: Path,
    demos: Path,
    out: Path,
    first_seed: int,
    device: str | None = None,
) -> list[str]:
    d = p.dagger
    return [
        "blindgrasp-dagger",
        f"--student={student_ckpt}",
        f"--teacher={teacher}",
        f"--demos={demos}",
        f"--output_dir={out}",
        f"--episodes_per_object={d.episodes_per_object}",
        f"--objects={d.objects}",
        f"--num_envs={d.num_envs}",
        f"--seed={first_seed}",
        f"--device={device or p.student.device}",
        "--progress=false",
    ]


def student_finetune(
    p: presets.Preset, init: Path, dataset: Path, repo_id: str, out: Path, seed: int, device: str | None = None
) -> list[str]:
    """lerobot-train from a student's weights (DAgger's retraining on the aggregate), `p.dagger.steps` steps."""
    steps = p.dagger.steps
    return _lerobot_train(p.student, [f"--policy.path={init}"], dataset, repo_id, out, steps, seed, device, [])


def student_eval(
    p: presets.Preset, ckpt: Path, dest: Path, eval_seed: int, device: str | None = None
) -> list[str]:
    e = p.evaluation
    return [
        "lerobot-eval",
        f"--policy.path={ckpt}",
        "--env.type=blindgrasp",
        f"--env.task={e.task}",
        f"--eval.n_episodes={e.episodes_per_object}",
        f"--eval.batch_size={e.episodes_per_object}",
        f"--policy.device={device or p.student.device}",
        # In-process envs: on a few cores, one worker process per env only adds start-up and contention.
        f"--eval.use_async_envs={'true' if e.async_envs else 'false'}",
        f"--env.render_stride={e.render_stride}",
        f"--env.render_episodes={e.render_episodes}",
        f"--output_dir={dest}",
        f"--seed={eval_seed}",
    ]


def teacher_trained(run: Path) -> bool:
    summary = run / "train_summary.json"
    return summary.exists() and not json.loads(summary.read_text()).get("interrupted")


def demos_collected(root: Path) -> bool:
    return (root / "yield_report.json").exists() and (root / "meta" / "info.json").exists()


def demos_empty(root: Path) -> bool:
    """A finished collection that kept no episode (the collector exits with EXIT_EMPTY): nothing to train on."""
    return demos_collected(root) and presets.dataset_frames(root) == 0


def checkpoint(student: Path) -> Path:
    return student / "checkpoints" / "last" / "pretrained_model"


def table_v(
    p: presets.Preset,
    out: Path,
    stage: str,
    seed: int = spec.TEACHER_TRAIN_SEED,
    eval_seed: int = spec.EVAL_SEED,
    device: str | None = None,
) -> list[list[str]]:
    """The commands of one Table V stage not done yet under `out`. Every student row uses the same demo start
    states (one demo seed), so rows differ only in what the paper varies."""
    if stage not in STAGES:
        raise ValueError(f"unknown stage {stage!r}; choose from {', '.join(STAGES)}")
    rows = presets.TABLE_V.values()
    cmds: list[list[str]] = []

    def teacher_dir(name: str) -> Path:
        if name == "teacher" and p.teacher.shipped:
            from lerobot_blindgrasp.teacher.policy import default_teacher

            return default_teacher()
        return out / name

    for name, variant in presets.TEACHERS.items():
        shipped = name == "teacher" and p.teacher.shipped
        if stage == "teachers" and not shipped and not teacher_trained(out / name):
            cmds.append(teacher_train(p, out / name, seed, variant))
        if stage == "teacher_evals" and not (out / f"{name}_eval" / "eval.json").exists():
            cmds.append(teacher_eval(p, teacher_dir(name), out / f"{name}_eval", eval_seed))
    for row in (r for r in rows if r.student):
        root, student = out / f"demos_{row.name}", out / f"student_{row.name}"
        repo = f"local/blindgrasp_{p.name}_{row.name}"
        if stage == "demos" and not demos_collected(root):
            cmds.append(
                demos_collect(
                    p,
                    teacher_dir(row.teacher),
                    root,
                    repo,
                    demo_seed(seed),
                    curate=row.curated_demos,
                    stochastic=row.stochastic_demos,
                )
            )
        if stage in ("students", "evals") and demos_empty(root):
            # A row without demos has no student; the script goes on with the other rows and says so.
            cmds.append(["#", f"{row.name}: skipped, {root} kept no episode"])
            continue
        if stage == "students" and not checkpoint(student).exists():
            if not demos_collected(root):
                raise ValueError(f"{root} is not collected yet: run the demos stage first")
            if student.exists():  # an interrupted lerobot-train: its output dir must not exist unless resuming
                cmds.append(["mv", str(student), str(out / f"student_{row.name}_interrupted_{int(time.time())}")])
            cmds.append(lerobot_train(p.student, root, repo, student, seed, device)[0])
        if stage == "evals" and not (out / f"eval_{row.name}" / "eval_info.json").exists():
            cmds.append(student_eval(p, checkpoint(student), out / f"eval_{row.name}", eval_seed, device))
    return cmds


def shell_lines(cmds: list[list[str]]) -> str:
    """One shell line per command; a ["#", text] entry is a comment line."""
    return "\n".join(f"# {c[1]}" if c[0] == "#" else shlex.join(c) for c in cmds)
