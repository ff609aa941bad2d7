"""Training success against env steps and against training wall clock, from a run's TensorBoard scalars.

    python -m lab.diagnosis.progress --output=OUT.png --runs=[[LABEL=]RUN_DIR[+RUN_DIR...],...]
        [--until=ITER] [--metrics=[TAG,TAG]] [--held_out=[EVAL_DIR,EVAL_DIR]]

`RUN_A+RUN_B` is one training history kept in two directories: RUN_B was started from a checkpoint of RUN_A (for
example the shipped teacher, whose cloning stage resumed the `cpu` run's iteration 1397 under another preset). Its
curve is RUN_A up to RUN_B's first iteration, then RUN_B, with RUN_B's wall clock added to RUN_A's.

`--until=ITER` cuts every curve after iteration ITER, to compare runs at one budget (a side-by-side run that was
stopped earlier than the one it is compared with). `--metrics=[TAG,TAG]` adds a second figure, OUT_metrics.png, with
those TensorBoard scalars of every run against env steps (e.g. `Metrics/mean_contacts,Metrics/mean_lift_cm`: what
a policy does, where success alone only says that it fails).

`--held_out=[EVAL_DIR,...]` marks `blindgrasp-eval-teacher` results on the curves: each eval sits on the run whose
directories hold the checkpoint it evaluated (matched by the checkpoint's SHA-256, which the eval records), at that
iteration's env steps and training hours; filled: deterministic, open: stochastic, all 18 objects.

Success here is the training-time rate rsl-rl logs per object (`Success/<object>`: episodes that ended in an
iteration, stochastic actions, training seeds), averaged with equal weight over the 18 objects and over the 6
medium ones, so a run that gives hard objects more envs is not flattered by its own allocation. Held-out numbers
come from `blindgrasp-eval-teacher`; these curves show the trend.

Wall clock is the sum of rsl-rl's per-iteration collection and update times, so a run stopped and resumed across
sessions reports its training time without the gaps (process start-up, about 10 s per resume, is not counted).
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from lerobot_blindgrasp import durable
from lerobot_blindgrasp.cli import parse_config
from lerobot_blindgrasp.sim import objects
from lerobot_blindgrasp.teacher.policy import CONFIG_NAME

SMOOTHING = 25  # iterations in the trailing mean of every curve


def _scalars(run_dir: Path) -> dict[str, dict[int, float]]:
    from tensorboard.backend.event_processing.event_accumulator import EventAccumulator

    out: dict[str, dict[int, float]] = {}
    # A resumed run writes a new events file per session; later files win for a repeated iteration.
    for events in sorted(run_dir.glob("events.out.tfevents.*"), key=lambda p: (p.stat().st_mtime, p.name)):
        ea = EventAccumulator(str(events), size_guidance={"scalars": 0})
        ea.Reload()
        for tag in ea.Tags().get("scalars", []):
            out.setdefault(tag, {}).update({e.step: e.value for e in ea.Scalars(tag)})
    return out


def _smooth(y: np.ndarray, window: int) -> np.ndarray:
    """Trailing mean over `window` iterations (NaN-aware: iterations where an object ended no episode)."""
    out = np.full_like(y, np.nan)
    for i in range(len(y)):
        w = y[max(0, i - window + 1) : i + 1]
        if np.isfinite(w).any():
            out[i] = np.nanmean(w)
    return out


def progress(
    run_dir: Path | tuple[Path, ...], window: int = SMOOTHING, until: int | None = None
) -> dict[str, list[float]]:
    """Per iteration (up to `until`, if given): env steps, training hours, and smoothed success (all 18 objects,
    6 medium). A tuple of run directories is one history continued from one directory into the next: each
    directory up to the next one's first iteration, wall clock accumulated, smoothed across the seams."""
    parts = [p for p in (_raw(d, until) for d in (run_dir if isinstance(run_dir, tuple) else (run_dir,))) if p]
    if not parts:
        return {}
    its, steps, secs, per_obj = [], [], [], []
    for k, (i, st, sec, obj) in enumerate(parts):
        n = sum(1 for x in i if k + 1 == len(parts) or x < parts[k + 1][0][0])
        its += i[:n]
        steps += st[:n]
        secs.append(sec[:n])
        per_obj.append(obj[:, :n])
    per_obj = np.array([_smooth(row, window) for row in np.concatenate(per_obj, axis=1)])
    medium = [objects.PAPER_OBJECTS.index(n) for n in objects.MEDIUM_OBJECTS]
    with np.errstate(invalid="ignore"):
        return {
            "iteration": [float(i) for i in its],
            "env_steps": [float(x) for x in steps],
            "wall_h": list(np.cumsum(np.concatenate(secs)) / 3600.0),
            "success_all18": list(np.nan_to_num(per_obj.mean(axis=0))),
            "success_medium": list(np.nan_to_num(per_obj[medium].mean(axis=0))),
        }


def _raw(run_dir: Path, until: int | None):
    """(iterations, env steps, seconds per iteration, per-object success (18, n) with NaN where none ended)."""
    cfg = json.loads((run_dir / CONFIG_NAME).read_text())
    steps_per_it = cfg["runner"]["num_steps_per_env"] * cfg["num_envs"]
    s = _scalars(run_dir)
    its = sorted(i for i in s.get("Perf/collection_time", {}) if until is None or i <= until)
    if not its:
        return None
    secs = np.array([s["Perf/collection_time"][i] + s["Perf/learning_time"].get(i, 0.0) for i in its])
    per_obj = np.array(
        [[s.get(f"Success/{n}", {}).get(i, np.nan) for i in its] for n in objects.PAPER_OBJECTS], dtype=float
    )
    return its, [(i + 1) * steps_per_it for i in its], secs, per_obj


def held_out_points(runs: dict[str, Path | tuple[Path, ...]], eval_dirs: list[Path]) -> dict[str, list[dict]]:
    """Run label -> the held-out evals of its checkpoints: iteration and success over all 18 objects per mode
    (objects weighted equally). An eval of a checkpoint that none of the runs holds is an error: a marker on the
    wrong curve would be worse than none."""
    from lerobot_blindgrasp.teacher.policy import file_sha256

    owner = {}  # checkpoint SHA-256 -> run label
    for label, run_dirs in runs.items():
        for run_dir in run_dirs if isinstance(run_dirs, tuple) else (run_dirs,):
            owner.update({file_sha256(ckpt): label for ckpt in run_dir.glob("model_*.pt")})
    points: dict[str, list[dict]] = {}
    for eval_dir in eval_dirs:
        path = eval_dir / "eval.json" if eval_dir.is_dir() else eval_dir
        if not path.is_file():
            raise SystemExit(f"{eval_dir}: no eval.json (a blindgrasp-eval-teacher output)")
        data = json.loads(path.read_text())
        label = owner.get(data.get("checkpoint_sha256"))
        if label is None:
            raise SystemExit(f"{eval_dir} evaluated {data.get('checkpoint')}, which none of the runs holds")
        rates = {
            mode: float(np.mean([r["success_rate"] for r in m["per_object"].values()]))
            for mode, m in data["modes"].items()
        }
        points.setdefault(label, []).append({"iteration": int(data["iteration"]), "success_all18": rates})
    return points


def _at_iteration(curve: dict[str, list[float]], iteration: int) -> tuple[float, float] | None:
    """(env steps, training hours) of `iteration` on a curve, None if the curve was cut before it."""
    its = np.array(curve["iteration"])
    k = int(np.searchsorted(its, iteration))
    if k == len(its) or its[k] != iteration:
        return None
    return curve["env_steps"][k], curve["wall_h"][k]


def plot_progress(
    runs: dict[str, Path | tuple[Path, ...]],
    path: Path,
    title: str = "Teacher training progress",
    until: int | None = None,
    held_out: dict[str, list[dict]] | None = None,
) -> dict:
    """One figure, success against env steps (left) and training wall clock (right), one colour per run;
    solid: all 18 objects, dashed: the 6 medium ones; `held_out` (from `held_out_points`) as markers."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    curves = {label: progress(run_dir, until=until) for label, run_dir in runs.items()}
    fig, axes = plt.subplots(1, 2, figsize=(10, 5.2), sharey=True)
    for k, (label, p) in enumerate(curves.items()):
        if not p:
            continue
        colour = f"C{k}"
        for ax, x in ((axes[0], np.array(p["env_steps"]) / 1e6), (axes[1], np.array(p["wall_h"]))):
            ax.plot(x, 100 * np.array(p["success_all18"]), colour, label=f"{label}: all 18")
            ax.plot(x, 100 * np.array(p["success_medium"]), colour, ls="--", label=f"{label}: 6 medium")
        for point in (held_out or {}).get(label, []):
            _held_out_marker(axes, p, point, colour)
    for ax, xlabel in zip(axes, ("env steps (M)", "training wall clock (h)")):
        ax.set_xlabel(xlabel)
        ax.set_ylim(0, 100)
        ax.grid(alpha=0.3)
    axes[0].set_ylabel("success (%)")
    handles, labels = axes[0].get_legend_handles_labels()
    if held_out:
        from matplotlib.lines import Line2D

        for fill, text in (("k", "held out, deterministic (all 18)"), ("none", "held out, stochastic (all 18)")):
            handles.append(Line2D([], [], ls="", marker="o", mec="k", mfc=fill))
            labels.append(text)
    # Below the axes: the curves rise into every corner of the plot.
    fig.legend(handles, labels, loc="lower center", ncol=2, fontsize=8, frameon=False)
    fig.suptitle(
        f"{title}\n(lines: training success, stochastic, trailing mean over {SMOOTHING} iterations)", fontsize=10
    )
    fig.tight_layout(rect=(0, 0.045 * ((len(labels) + 1) // 2), 1, 1))
    with durable.atomic_path(path) as tmp:
        fig.savefig(tmp, dpi=110)
    plt.close(fig)
    return curves


def _held_out_marker(axes, p: dict, point: dict, colour: str) -> None:
    """One held-out evaluation on both panels, at its iteration's env steps and wall clock: filled for the
    deterministic teacher (labelled with its rate), hollow for the stochastic one."""
    at = _at_iteration(p, point["iteration"])
    if at is None:
        return
    for mode, fill in (("deterministic", colour), ("stochastic", "none")):
        if mode not in point["success_all18"]:
            continue
        y = 100 * point["success_all18"][mode]
        for ax, x in ((axes[0], at[0] / 1e6), (axes[1], at[1])):
            ax.plot([x], [y], "o", mec=colour, mfc=fill, ms=6, zorder=3)
            if mode == "deterministic":
                ax.annotate(
                    f"{y:.1f}",
                    (x, y),
                    textcoords="offset points",
                    xytext=(-4, 6),
                    ha="right",
                    fontsize=7,
                    color=colour,
                )


def plot_metrics(
    runs: dict[str, Path | tuple[Path, ...]],
    tags: list[str],
    path: Path,
    until: int | None = None,
    window: int = SMOOTHING,
) -> None:
    """One panel per TensorBoard scalar, every run against env steps (trailing mean over `window` iterations); a
    chained run's later directories win where iterations repeat."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, len(tags), figsize=(4.2 * len(tags), 3.4), squeeze=False)
    for k, (label, run_dirs) in enumerate(runs.items()):
        run_dirs = run_dirs if isinstance(run_dirs, tuple) else (run_dirs,)
        cfg = json.loads((run_dirs[-1] / CONFIG_NAME).read_text())
        steps_per_it = cfg["runner"]["num_steps_per_env"] * cfg["num_envs"]
        s: dict[str, dict[int, float]] = {}
        for run_dir in run_dirs:
            for tag, values in _scalars(run_dir).items():
                s.setdefault(tag, {}).update(values)
        for ax, tag in zip(axes[0], tags):
            its = sorted(i for i in s.get(tag, {}) if until is None or i <= until)
            if not its:
                continue
            y = _smooth(np.array([s[tag][i] for i in its], dtype=float), window)
            ax.plot(np.array([(i + 1) * steps_per_it for i in its]) / 1e6, y, f"C{k}", label=label)
    for ax, tag in zip(axes[0], tags):
        ax.set_title(tag, fontsize=9)
        ax.set_xlabel("env steps (M)")
        ax.grid(alpha=0.3)
    axes[0][0].legend(fontsize=8)
    fig.tight_layout()
    with durable.atomic_path(path) as tmp:
        fig.savefig(tmp, dpi=110)
    plt.close(fig)


@dataclass
class ProgressConfig:
    output: Path  # the figure (png); `--metrics` adds OUT_metrics.png next to it
    # The runs, each `[LABEL=]RUN_DIR[+RUN_DIR...]` (label: the last folder's name when not given)
    runs: list[str] = field(default_factory=list)
    until: int | None = None  # cut every curve after this iteration, to compare runs at one budget
    # TensorBoard scalar tags (Metrics/mean_contacts, Metrics/mean_lift_cm): a second figure with them against env steps
    metrics: list[str] = field(default_factory=list)
    # blindgrasp-eval-teacher output folders, marked on the run that holds each one's checkpoint
    held_out: list[Path] = field(default_factory=list)


def main(argv=None) -> None:
    cfg = parse_config(ProgressConfig, argv)
    if not cfg.runs:
        raise SystemExit("error: give the runs to plot: --runs=[[LABEL=]RUN_DIR[+RUN_DIR...],...]")
    runs = {}
    for arg in cfg.runs:
        label, _, paths = arg.rpartition("=")
        run_dirs = tuple(Path(p) for p in paths.split("+"))
        for run_dir in run_dirs:
            if not (run_dir / CONFIG_NAME).is_file():
                raise SystemExit(f"{run_dir} is not a teacher run directory (no {CONFIG_NAME})")
        runs[label or run_dirs[-1].name] = run_dirs if len(run_dirs) > 1 else run_dirs[0]
    out = cfg.output
    held_out = held_out_points(runs, cfg.held_out) if cfg.held_out else None
    curves = plot_progress(runs, out, until=cfg.until, held_out=held_out)
    if cfg.metrics:
        plot_metrics(runs, cfg.metrics, out.with_name(f"{out.stem}_metrics.png"), until=cfg.until)
    last = {label: {k: v[-1] for k, v in p.items()} for label, p in curves.items() if p}
    print(json.dumps({"plot": str(out), "last": last, "held_out": held_out or {}}, indent=2))


if __name__ == "__main__":
    main()
