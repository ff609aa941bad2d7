"""Learning-curve plots shared by the teacher training CLI and the pipeline report."""

from __future__ import annotations

from pathlib import Path

import matplotlib
import numpy as np

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402

from lerobot_blindgrasp import durable  # noqa: E402

TEACHER_TAGS = (
    "Train/mean_reward",
    "Metrics/success",
    "Metrics/mean_lift_cm",
    "Metrics/mean_contacts",
    "Episode_Reward/task",
    "Episode_Reward/incentive",
    "Episode_Reward/touch",
    "Episode_Termination/object_out_of_reach",
)


def teacher_curves(run_dir: Path, tags=TEACHER_TAGS) -> dict:
    from tensorboard.backend.event_processing.event_accumulator import EventAccumulator

    ea = EventAccumulator(str(run_dir), size_guidance={"scalars": 0})
    ea.Reload()
    have = set(ea.Tags().get("scalars", []))
    return {t: ([e.step for e in ea.Scalars(t)], [e.value for e in ea.Scalars(t)]) for t in tags if t in have}


def plot_curves(path: Path, curves: dict, title: str) -> None:
    cols = min(4, len(curves))
    rows = -(-len(curves) // cols)
    fig, axes = plt.subplots(rows, cols, figsize=(4.2 * cols, 3.0 * rows), squeeze=False)
    for ax in axes.flat[len(curves) :]:
        ax.set_visible(False)
    for ax, (tag, (xs, ys)) in zip(axes.flat, curves.items()):
        ax.plot(xs, ys)
        ax.set_title(tag, fontsize=9)
        ax.set_xlabel("iteration" if "/" in tag else "step")
        ax.grid(alpha=0.3)
    fig.suptitle(title)
    fig.tight_layout()
    with durable.atomic_path(path) as tmp:
        fig.savefig(tmp, dpi=110)
    plt.close(fig)


def bar_chart(path: Path, names: list[str], series: dict[str, list[float]], title: str, ylabel: str) -> None:
    x = np.arange(len(names))
    w = 0.8 / max(1, len(series))
    fig, ax = plt.subplots(figsize=(max(7, 0.55 * len(names) + 2), 4))
    for i, (label, vals) in enumerate(series.items()):
        ax.bar(x + (i - (len(series) - 1) / 2) * w, vals, w, label=label)
    ax.set_xticks(x, [n.replace("_", " ") for n in names], rotation=60, ha="right", fontsize=8)
    ax.set_ylabel(ylabel)
    ax.set_ylim(0, 100)  # every chart here is a percentage; a fixed axis keeps all-zero charts readable
    # The legend goes between the title and the axes, never over a bar: as many columns as the width holds
    # (about 4 pt a character at font size 8, plus the colour patch and the gap).
    longest = max((len(label) for label in series), default=0)
    ncol = max(1, min(len(series), int(fig.get_figwidth() * 72 / (4 * longest + 35))))
    ax.legend(fontsize=8, loc="lower center", bbox_to_anchor=(0.5, 1.01), ncol=ncol, frameon=False)
    fig.suptitle(title)
    fig.tight_layout()
    with durable.atomic_path(path) as tmp:
        fig.savefig(tmp, dpi=110)
    plt.close(fig)
