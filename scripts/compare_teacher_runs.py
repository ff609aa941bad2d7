"""Overlay the TensorBoard curves of several teacher runs (for docs/research/teacher_cpu.md).

    .venv/bin/python scripts/compare_teacher_runs.py --output=OUT.png --runs=[LABEL=RUN_DIR,...]

x axis: env steps (iteration x num_envs x steps per env, from each run's teacher_config.json).
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402

from lerobot_blindgrasp import durable  # noqa: E402
from lerobot_blindgrasp.cli import parse_config  # noqa: E402
from lerobot_blindgrasp.results.plots import teacher_curves  # noqa: E402

TAGS = (
    "Metrics/mean_contacts",
    "Metrics/mean_lift_cm",
    "Episode_Reward/task",
    "Episode_Reward/incentive",
    "Episode_Termination/object_out_of_reach",
    "Metrics/success",
)


@dataclass
class CompareRunsConfig:
    output: Path  # the figure (png)
    runs: list[str] = field(default_factory=list)  # LABEL=RUN_DIR, one curve each


def main(argv: list[str] | None = None) -> None:
    cfg = parse_config(CompareRunsConfig, argv)
    out = cfg.output
    runs = [a.split("=", 1) for a in cfg.runs]
    fig, axes = plt.subplots(2, 3, figsize=(14, 7))
    for label, run in runs:
        cfg = json.loads((Path(run) / "teacher_config.json").read_text())
        per_it = cfg["num_envs"] * cfg["runner"]["num_steps_per_env"]
        curves = teacher_curves(Path(run), TAGS)
        for ax, tag in zip(axes.flat, TAGS):
            if tag in curves:
                xs, ys = curves[tag]
                ax.plot([x * per_it / 1e6 for x in xs], ys, label=label, lw=1)
    for ax, tag in zip(axes.flat, TAGS):
        ax.set_title(tag, fontsize=9)
        ax.set_xlabel("env steps (M)")
        ax.grid(alpha=0.3)
    axes.flat[0].legend(fontsize=8)
    fig.tight_layout()
    with durable.atomic_path(out) as tmp:
        fig.savefig(tmp, dpi=110)


if __name__ == "__main__":
    main()
