"""The pipeline report: markdown plus PNG plots, from what each stage left in the output folder.

Sources: teacher `eval.json` (blindgrasp-eval-teacher), its TensorBoard scalars, the demos' `yield_report.json`,
the student's `lerobot-train` log (loss lines) and lerobot-eval's `eval_info.json` (per task = per object).
"""

from __future__ import annotations

import json
import re
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from lerobot_blindgrasp.envs.sim_env import object_for_task_id  # noqa: E402
from lerobot_blindgrasp.plots import plot_curves, teacher_curves  # noqa: E402
from lerobot_blindgrasp.sim import objects  # noqa: E402

_LOSS_LINE = re.compile(r"step:\s*([\d.]+[KMB]?)\b.*?\bloss:\s*([\d.eE+-]+)")


def student_success(eval_info: dict) -> dict[str, float]:
    """Per-object success rate from lerobot-eval's per_task entries."""
    out = {}
    for entry in eval_info.get("per_task", []):
        succ = entry["metrics"].get("successes", [])
        out[object_for_task_id(int(entry["task_id"]))] = float(np.mean(succ)) if succ else 0.0
    return out


def student_loss_curve(log_text: str) -> tuple[list[float], list[float]]:
    from lerobot_blindgrasp.pipeline import parse_step

    steps, losses = [], []
    for m in _LOSS_LINE.finditer(log_text):
        steps.append(parse_step(m.group(1)))
        losses.append(float(m.group(2)))
    return steps, losses


def _bar_chart(path: Path, names: list[str], series: dict[str, list[float]], title: str, ylabel: str) -> None:
    x = np.arange(len(names))
    w = 0.8 / max(1, len(series))
    fig, ax = plt.subplots(figsize=(max(7, 0.55 * len(names) + 2), 4))
    for i, (label, vals) in enumerate(series.items()):
        ax.bar(x + (i - (len(series) - 1) / 2) * w, vals, w, label=label)
    ax.set_xticks(x, [n.replace("_", " ") for n in names], rotation=60, ha="right", fontsize=8)
    ax.set_ylabel(ylabel)
    ax.set_ylim(0, 100)  # every chart here is a percentage; a fixed axis keeps all-zero charts readable
    ax.set_title(title)
    ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def write_report(out: Path, record: dict, bigger: str) -> Path:
    figs = out / "figures"
    figs.mkdir(exist_ok=True)
    preset = record["preset"]["name"]
    names = list(objects.PAPER_OBJECTS)
    lines = [f"# Blind-grasp pipeline report: preset `{preset}`", ""]

    # --- stages
    lines += ["## Stages", "", "| stage | wall time | command |", "|---|---:|---|"]
    for name, st in record["stages"].items():
        lines.append(f"| {name} | {st['wall_s']:.0f} s | `{st['command']}` |")
    lines.append("")

    # --- success per object
    teacher = json.loads((out / "teacher_eval" / "eval.json").read_text())
    t_det = teacher["modes"]["deterministic"]["per_object"]
    t_sto = teacher["modes"].get("stochastic", {}).get("per_object", {})
    eval_info = json.loads((out / "student_eval" / "eval_info.json").read_text())
    stu = student_success(eval_info)
    n_stu = eval_info.get("overall", {}).get("n_episodes")
    series = {
        "teacher (deterministic)": [t_det[n]["success_rate"] * 100 for n in names],
        "teacher (stochastic)": [t_sto.get(n, {}).get("success_rate", 0) * 100 for n in names],
        "student (lerobot-eval)": [stu.get(n, 0.0) * 100 for n in names],
    }
    _bar_chart(figs / "success_per_object.png", names, series, "Sim success per object", "success (%)")
    lines += [
        "## Success per object (sim)",
        "",
        f"Teacher: `blindgrasp-eval-teacher`, {teacher['episodes_per_object']} episodes per object and mode. "
        f"Student: `lerobot-eval --env.type=blindgrasp --env.task={record['preset'].get('eval_task', 'all')}`, "
        f"{n_stu} episodes in all (objects not evaluated show 0). Success = lifted "
        "≥ 1.5 cm and held ≥ 1 s within 10 s; the paper's randomization and noise, no pushes.",
        "",
        "![success](figures/success_per_object.png)",
        "",
        "| object | teacher det. | teacher stoch. | student |",
        "|---|---:|---:|---:|",
    ]
    for i, n in enumerate(names):
        lines.append(f"| {n} | {series['teacher (deterministic)'][i]:.0f} % | "
                     f"{series['teacher (stochastic)'][i]:.0f} % | {series['student (lerobot-eval)'][i]:.0f} % |")
    means = {k: float(np.mean(v)) for k, v in series.items()}
    lines.append("| **mean** | " + " | ".join(f"**{means[k]:.1f} %**" for k in series) + " |")
    lines.append("")

    # --- learning curves
    lines += ["## Learning curves", ""]
    tc = teacher_curves(out / "teacher")
    if tc:
        plot_curves(figs / "teacher_curves.png", tc, "Teacher (PPO)")
        lines += ["![teacher](figures/teacher_curves.png)", ""]
    log = out / "logs" / "student.log"
    steps, losses = student_loss_curve(log.read_text()) if log.exists() else ([], [])
    if steps:
        plot_curves(figs / "student_loss.png", {"train loss (MSE, normalized delta)": (steps, losses)}, "Student (BC)")
        lines += ["![student](figures/student_loss.png)", ""]

    # --- demo yield
    lines += ["## Demonstrations", ""]
    for label, sub in (("curated", "demos"), ("uncurated", "demos_uncurated")):
        path = out / sub / "yield_report.json"
        if not path.exists():
            continue
        y = json.loads(path.read_text())
        rows = y["objects"]
        _bar_chart(figs / f"yield_{sub}.png", names, {"yield (%)": [rows.get(n, {}).get("yield", 0) * 100 for n in names]},
                   f"Demo yield ({label})", "episodes passing curation (%)")
        tot = y["total"]
        lines += [
            f"**{label}** (`{sub}/`): {tot['kept']} episodes written from {tot['rollouts']} rollouts, "
            f"yield {tot['yield'] * 100:.1f} %.",
            "",
            f"![yield](figures/yield_{sub}.png)",
            "",
        ]
    lines += [f"The student was trained on the **{record.get('student_dataset', 'curated')}** set.", ""]
    lines += ["## Next", "", bigger]
    path = out / "report.md"
    path.write_text("\n".join(lines) + "\n")
    return path
