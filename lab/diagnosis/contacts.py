"""How a teacher touches each object: the direction of its fingertip forces, next to its success.

    python -m lab.diagnosis.contacts --objects=capsule_small,sphere_small,sphere_medium --episodes=10

Success says *that* a teacher fails on an object; this says *how*. For every control step after the approach
(`--after_s`) and every fingertip touching the object (> 0.1 N, world-frame net force of the tip on the object),
it records -F_z/|F| (1: pressing the object straight down into the table, 0: squeezing sideways) and how high the
tip sits above the object's centre. A tip pressing from above can never lift the object; a lifting grasp squeezes
sideways. This is how the small capsule's failure mode was found: the `cpu` teacher pressed it into the table.

Start states are the evaluation ones (`--seed`, as `blindgrasp-eval-teacher`), deterministic actions.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from lerobot_blindgrasp import spec
from lerobot_blindgrasp.cli import parse_config
from lerobot_blindgrasp.rollout.envs import make_batched_env
from lerobot_blindgrasp.sim import objects
from lerobot_blindgrasp.sim.batched_env import BatchedGraspEnv

PRESSING_DOWN = 0.5  # -F_z/|F| above this: more than 30 degrees below horizontal


@dataclass
class ContactsConfig:
    """Fingertip force directions of a teacher per object (deterministic, evaluation start states)."""

    teacher: Path | None = None  # teacher folder, run directory or checkpoint; default: the shipped teacher
    objects: str = "all"  # "all", "medium", or a comma-separated list of catalogue names
    episodes: int = 10  # episodes per object
    seed: int = spec.EVAL_SEED  # first evaluation index
    after_s: float = 2.0  # ignore the first seconds (the approach) of each episode


def contact_directions(env: BatchedGraspEnv, obs: dict, act, steps: int, after_steps: int) -> dict[str, float]:
    """Drive a just-reset env (`obs`: what reset returned) with `act(obs) -> action` for `steps` control steps;
    summarize the tip-on-object contacts from step `after_steps` on. Returns success, the number of (step, tip)
    contacts, mean -F_z/|F|, the share pressing down (> PRESSING_DOWN) and the mean tip height above the object
    centre (mm)."""
    downward, height = [], []
    for t in range(steps):
        obs, _, _, _, info = env.step(act(obs))
        if t < after_steps:
            continue
        touching = info["tip_object_force"] > spec.FORCE_THRESHOLD_N
        tip_z = env.fingertip_positions()[..., 2]
        downward.append(info["tip_object_downward"][touching])
        height.append((tip_z - env.object_position()[:, None, 2])[touching])
    d, h = np.concatenate(downward), np.concatenate(height)
    return {
        "success_rate": float(env.success.double().mean()),
        "contacts": int(d.size),
        "mean_downward": float(d.mean()) if d.size else float("nan"),
        "share_pressing_down": float((d > PRESSING_DOWN).mean()) if d.size else float("nan"),
        "mean_tip_height_mm": float(h.mean() * 1000) if h.size else float("nan"),
    }


def teacher_contacts(cfg: ContactsConfig) -> dict[str, dict[str, float]]:
    from lerobot_blindgrasp.teacher.policy import TeacherPolicy, default_teacher

    teacher = TeacherPolicy(cfg.teacher or default_teacher())
    out = {}
    for name in objects.resolve_objects(cfg.objects):
        env = make_batched_env("eval", (name,), episodes=cfg.episodes, seed=cfg.seed)
        obs = env.reset()
        after = int(round(cfg.after_s * spec.CONTROL_HZ))
        act = lambda o: teacher(o, stochastic=False)  # noqa: E731
        out[name] = contact_directions(env, obs, act, env.max_episode_steps, after)
        env.close()
    return out


def markdown(rows: dict[str, dict[str, float]]) -> str:
    lines = [
        "| object | success | tip contacts | mean -F_z/abs(F) | share pressing down (> 0.5) "
        "| tip above object centre (mm) |",
        "|---|---:|---:|---:|---:|---:|",
    ]
    for name, r in rows.items():
        lines.append(
            f"| {name} | {r['success_rate']:.0%} | {r['contacts']} | {r['mean_downward']:+.2f} | "
            f"{r['share_pressing_down']:.0%} | {r['mean_tip_height_mm']:+.1f} |"
        )
    return "\n".join(lines) + "\n"


def main(argv=None) -> None:
    cfg = parse_config(ContactsConfig, argv)
    print(markdown(teacher_contacts(cfg)))


if __name__ == "__main__":
    main()
