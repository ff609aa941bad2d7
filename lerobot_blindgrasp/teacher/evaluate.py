"""`blindgrasp-eval-teacher`: per-object success table of a trained teacher, deterministic and stochastic, on the
evaluation start states: `--seed=S --episodes=N` runs the episodes `lerobot-eval --seed=S --eval.n_episodes=N`
runs. Writes `eval.json`, `eval.md` (95 % Wilson intervals) and `eval.png`.

    blindgrasp-eval-teacher --teacher=runs/teacher_cpu --episodes=20   # default: the shipped teacher
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np
import torch
from tqdm import tqdm

from lerobot_blindgrasp import durable, spec
from lerobot_blindgrasp.cli import parse_config
from lerobot_blindgrasp.results import rates
from lerobot_blindgrasp.rollout.actors import TeacherActor
from lerobot_blindgrasp.rollout.envs import make_batched_env
from lerobot_blindgrasp.rollout.loop import run_batch
from lerobot_blindgrasp.sim import backends, objects, rewards
from lerobot_blindgrasp.sim.gym_env import start_seed
from lerobot_blindgrasp.teacher.policy import TeacherError, TeacherPolicy, default_teacher

MODES = ("deterministic", "stochastic")


@dataclass
class EvalTeacherConfig:
    """Per-object success of a PPO teacher on the evaluation start states, deterministic and stochastic."""

    # a teacher folder (shipped, or a run: its latest model_<it>.pt) or checkpoint; default: the shipped one
    teacher: Path | None = None
    episodes: int = 20  # episodes per object and mode
    objects: str = "all"  # "all", "medium", or a comma-separated list of catalogue names
    modes: str = ",".join(MODES)  # comma-separated: deterministic (mean action), stochastic (sampled)
    seed: int = spec.EVAL_SEED  # first evaluation index (lerobot-eval's --seed)
    # output folder (default: <run dir>/eval, or outputs/teacher_eval for the shipped teacher)
    output_dir: Path | None = None
    progress: bool = True  # progress bar
    # physics: "batch" (mujoco.batch, CPU) or "warp" (MuJoCo Warp on this process's GPU, else Warp's CPU device)
    backend: str = "batch"

    def __post_init__(self):
        backends.check_backend(self.backend)
        bad = set(self.mode_names) - set(MODES)
        if bad:
            raise ValueError(f"unknown mode(s) {sorted(bad)}; choose from {MODES}")
        spec.eval_env_seed(self.seed + self.episodes - 1, 0)  # raises if the indices leave the eval block

    @property
    def mode_names(self) -> tuple[str, ...]:
        return tuple(m.strip() for m in self.modes.split(",") if m.strip())


def _run_object(
    teacher: TeacherPolicy, name: str, episodes: int, seed: int, mode: str, reward_cfg, backend
) -> tuple:
    """One object's episodes in one batch, on evaluation indices seed .. seed + episodes - 1, as the gym env."""
    env = make_batched_env("eval", (name,), episodes=episodes, seed=seed, reward=reward_cfg, backend=backend)
    done = run_batch(env, TeacherActor(teacher, stochastic=mode == "stochastic"))
    return np.array([e.success for e in done]), np.array([e.max_lift for e in done])


def evaluate_teacher(
    teacher: TeacherPolicy,
    object_names: tuple[str, ...] = objects.PAPER_OBJECTS,
    episodes_per_object: int = 20,
    seed: int = spec.EVAL_SEED,
    modes: tuple[str, ...] = MODES,
    progress: bool = True,
    backend: str = "batch",
) -> dict:
    """Success (with per-episode flags) and mean lift per object and mode, on the paired start states."""
    reward_cfg = rewards.RewardConfig.from_record(teacher.config["reward"])
    results: dict = {
        "objects": list(object_names),
        "episodes_per_object": episodes_per_object,
        "seed": seed,
        "backend": backend,
        "seeds": f"evaluation indices {seed}..{seed + episodes_per_object - 1} per object (spec.eval_env_seed)",
        "modes": {},
    }
    for mode in modes:
        torch.manual_seed(seed)
        per_object = {}
        for name in tqdm(object_names, desc=f"eval {mode}", disable=not progress, leave=False):
            success, max_lift = _run_object(teacher, name, episodes_per_object, seed, mode, reward_cfg, backend)
            per_object[name] = {
                "success_rate": float(success.mean()),
                "successes": [bool(x) for x in success],
                "mean_max_lift_cm": float(max_lift.mean() * 100),
                "first_env_seed": start_seed(seed, name),
            }
        medium = [o for o in object_names if o.endswith("_medium")]
        results["modes"][mode] = {
            "per_object": per_object,
            "overall": _pooled(per_object, object_names),
            "medium_objects": _pooled(per_object, medium) if medium else None,
            "counts": {
                "overall": _counts(per_object, object_names),
                "medium_objects": _counts(per_object, medium),
            },
        }
    results["checkpoint"] = str(teacher.checkpoint)
    results["checkpoint_sha256"] = teacher.sha256
    results["iteration"] = teacher.iteration
    return results


def _counts(per_object: dict, names) -> list[int]:
    flags = [f for n in names for f in per_object[n]["successes"]]
    return list(rates.count(flags))


def _pooled(per_object: dict, names) -> float:
    k, n = _counts(per_object, names)
    return k / n if n else 0.0


def markdown_table(results: dict) -> str:
    modes = list(results["modes"])
    columns = [f"{m} success [95 % CI]" for m in modes] + [f"{m} max lift (cm)" for m in modes]
    lines = ["| object | " + " | ".join(columns) + " |", "|---|" + "---:|" * len(columns)]
    for o in results["objects"]:
        s = [rates.format_rate(*rates.count(results["modes"][m]["per_object"][o]["successes"])) for m in modes]
        lift = [f"{results['modes'][m]['per_object'][o]['mean_max_lift_cm']:.1f}" for m in modes]
        lines.append(f"| {o} | " + " | ".join(s + lift) + " |")
    n_medium = sum(o.endswith("_medium") for o in results["objects"])
    for key, label in (
        ("medium_objects", f"{n_medium} medium objects"),
        ("overall", f"all {len(results['objects'])}"),
    ):
        counts = [results["modes"][m]["counts"][key] for m in modes]
        if all(c[1] for c in counts):
            cells = " | ".join(f"**{rates.format_rate(*c, digits=1)}**" for c in counts)
            lines.append(f"| **{label}** | " + cells + " |" + " |" * len(modes))
    lines += [
        "",
        f"Teacher `{results['checkpoint']}` (iteration {results['iteration']}); start states: "
        f"{results['seeds']}; 95 % Wilson intervals.",
    ]
    return "\n".join(lines) + "\n"


def write_outputs(results: dict, out: Path) -> None:
    out.mkdir(parents=True, exist_ok=True)
    # eval.json last: it is what marks the evaluation as done (the pipeline skips a stage that has it).
    durable.atomic_write_text(out / "eval.md", markdown_table(results))
    from lerobot_blindgrasp.results.plots import bar_chart  # matplotlib only when a chart is drawn

    names, modes = results["objects"], results["modes"]
    series = {m: [modes[m]["per_object"][o]["success_rate"] * 100 for o in names] for m in modes}
    title = (
        f"Teacher success, {results['episodes_per_object']} episodes per object (iteration {results['iteration']})"
    )
    bar_chart(out / "eval.png", names, series, title, "success (%)")
    durable.atomic_write_json(out / "eval.json", results, indent=2)


def main(argv=None) -> None:
    cfg = parse_config(EvalTeacherConfig, argv)
    try:
        teacher = TeacherPolicy(cfg.teacher or default_teacher())
        names = objects.resolve_objects(cfg.objects)
        results = evaluate_teacher(
            teacher, names, cfg.episodes, cfg.seed, cfg.mode_names, cfg.progress, cfg.backend
        )
        # The shipped teacher's folder is part of the repository: never write into it unasked.
        out = cfg.output_dir or (
            teacher.checkpoint.parent / "eval" if cfg.teacher else Path("outputs/teacher_eval")
        )
        write_outputs(results, out)
    except (TeacherError, ValueError) as e:
        raise SystemExit(f"error: {e}") from None
    print(markdown_table(results))
    print(f"wrote {out}/eval.json, eval.md, eval.png")


if __name__ == "__main__":
    main()
