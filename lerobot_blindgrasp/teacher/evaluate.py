"""`blindgrasp-eval-teacher CKPT`: per-object success table of a trained teacher.

    blindgrasp-eval-teacher runs/teacher_cpu --episodes 20 --out docs/results/teacher_cpu_eval

Runs N episodes per object (10 s each, the paper's randomization and observation noise, external forces off as in
evaluation and demo collection), deterministic (mean action) and stochastic (sampled), and writes
`eval.json`, `eval.md` (markdown table) and `eval.png` (bar chart) to --out.
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np
import torch
from tqdm import tqdm

from lerobot_blindgrasp import spec
from lerobot_blindgrasp.sim import objects, randomization, rewards
from lerobot_blindgrasp.sim.env import BatchedGraspEnv, GraspEnvConfig
from lerobot_blindgrasp.teacher.policy import TeacherPolicy

MODES = ("deterministic", "stochastic")


def evaluate(
    teacher: TeacherPolicy,
    object_names: tuple[str, ...] = objects.PAPER_OBJECTS,
    episodes_per_object: int = 10,
    seed: int = 10_000,
    modes: tuple[str, ...] = MODES,
    progress: bool = True,
) -> dict:
    """Success rate and mean lift per object and mode. One batched env runs every episode of a mode at once."""
    reward_cfg = rewards.RewardConfig(**teacher.config["reward"])
    n = len(object_names) * episodes_per_object
    results: dict = {"objects": list(object_names), "episodes_per_object": episodes_per_object, "modes": {}}
    for mode in modes:
        torch.manual_seed(seed)
        env = BatchedGraspEnv(
            GraspEnvConfig(
                num_envs=n,
                objects=object_names,
                seed=seed,
                dr=randomization.PAPER_DR.without_external_force(),
                reward=reward_cfg,
                autoreset=False,
            )
        )
        obs = env.reset()
        alive = np.ones(n, dtype=bool)
        success = np.zeros(n, dtype=bool)
        max_lift = np.zeros(n)
        for _ in tqdm(range(env.max_episode_steps), desc=f"eval {mode}", disable=not progress, leave=False):
            obs, _, term, trunc, info = env.step(teacher(obs, stochastic=mode == "stochastic"))
            success |= info["success"] & alive
            max_lift = np.where(alive, np.maximum(max_lift, info["lift"]), max_lift)
            alive &= ~(term | trunc)
            if not alive.any():
                break
        per_object = {}
        for k, name in enumerate(object_names):
            mask = env.object_index == k
            per_object[name] = {
                "success_rate": float(success[mask].mean()),
                "mean_max_lift_cm": float(max_lift[mask].mean() * 100),
            }
        medium = [per_object[o]["success_rate"] for o in object_names if o.endswith("_medium")]
        results["modes"][mode] = {
            "per_object": per_object,
            "overall": float(success.mean()),
            "medium_objects": float(np.mean(medium)) if medium else None,
        }
    results["checkpoint"] = str(teacher.checkpoint)
    results["checkpoint_sha256"] = teacher.sha256
    results["iteration"] = teacher.iteration
    return results


def markdown_table(results: dict) -> str:
    modes = list(results["modes"])
    head = "| object | " + " | ".join(f"{m} success" for m in modes) + " | " + " | ".join(
        f"{m} max lift (cm)" for m in modes
    ) + " |"
    lines = [head, "|---|" + "---:|" * (2 * len(modes))]
    for o in results["objects"]:
        s = [f"{results['modes'][m]['per_object'][o]['success_rate'] * 100:.0f} %" for m in modes]
        lift = [f"{results['modes'][m]['per_object'][o]['mean_max_lift_cm']:.1f}" for m in modes]
        lines.append(f"| {o} | " + " | ".join(s + lift) + " |")
    n_medium = sum(o.endswith("_medium") for o in results["objects"])
    for key, label in (("medium_objects", f"{n_medium} medium objects"), ("overall", f"all {len(results['objects'])}")):
        vals = [results["modes"][m][key] for m in modes]
        if all(v is not None for v in vals):
            lines.append(f"| **{label}** | " + " | ".join(f"**{v * 100:.1f} %**" for v in vals) + " |" + " |" * len(modes))
    return "\n".join(lines) + "\n"


def bar_chart(results: dict, path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    names = results["objects"]
    x = np.arange(len(names))
    modes = list(results["modes"])
    width = 0.8 / len(modes)
    fig, ax = plt.subplots(figsize=(max(6, 0.55 * len(names) + 2), 4))
    for i, m in enumerate(modes):
        vals = [results["modes"][m]["per_object"][o]["success_rate"] * 100 for o in names]
        ax.bar(x + (i - (len(modes) - 1) / 2) * width, vals, width, label=m)
    ax.set_xticks(x, [n.replace("_", " ") for n in names], rotation=60, ha="right", fontsize=8)
    ax.set_ylabel("success (%)")
    ax.set_ylim(0, 100)
    ax.set_title(f"Teacher success, {results['episodes_per_object']} episodes per object (iteration {results['iteration']})")
    ax.legend()
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)


def write_outputs(results: dict, out: Path) -> None:
    out.mkdir(parents=True, exist_ok=True)
    (out / "eval.json").write_text(json.dumps(results, indent=2))
    (out / "eval.md").write_text(markdown_table(results))
    bar_chart(results, out / "eval.png")


def main(argv=None) -> None:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("checkpoint", help="model_<it>.pt, or a run directory (its latest checkpoint)")
    p.add_argument("--episodes", type=int, default=10, help="episodes per object and mode")
    p.add_argument("--objects", default="all", help='"all", "medium", or a comma-separated list')
    p.add_argument("--modes", default="deterministic,stochastic")
    p.add_argument("--seed", type=int, default=10_000)
    p.add_argument("--out", type=Path, default=None, help="output folder (default: <run dir>/eval)")
    args = p.parse_args(argv)
    teacher = TeacherPolicy(args.checkpoint)
    modes = tuple(m.strip() for m in args.modes.split(","))
    bad = set(modes) - set(MODES)
    if bad:
        raise SystemExit(f"unknown mode(s) {sorted(bad)}; choose from {MODES}")
    results = evaluate(teacher, objects.resolve_objects(args.objects), args.episodes, args.seed, modes)
    out = args.out or teacher.checkpoint.parent / "eval"
    write_outputs(results, out)
    print(markdown_table(results))
    print(f"wrote {out}/eval.json, eval.md, eval.png")


if __name__ == "__main__":
    main()
