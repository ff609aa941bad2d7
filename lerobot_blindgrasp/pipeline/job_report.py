"""The pipeline report: markdown plus PNG plots, from what each stage left in the output folder. Teacher and student
ran the same start states, so the report pairs them episode by episode; every rate carries its 95 % Wilson interval.
The grasp strips show, per object shape, frames of one successful episode lerobot-eval rendered (PyAV decodes them).
"""

from __future__ import annotations

import json
import re
from pathlib import Path

import numpy as np

from lerobot_blindgrasp import durable, spec
from lerobot_blindgrasp.results import rates
from lerobot_blindgrasp.results.compare import student_successes
from lerobot_blindgrasp.results.plots import bar_chart, plot_curves, teacher_curves
from lerobot_blindgrasp.sim import objects
from lerobot_blindgrasp.sim.objects import object_for_task_id

_LOSS_LINE = re.compile(r"step:\s*([\d.]+[KMB]?)\b.*?\bloss:\s*([\d.eE+-]+)")


def parse_step(s: str) -> float:
    """A step count as lerobot-train logs it: 300, 1K, 2.5M."""
    m = re.fullmatch(r"([\d.]+)([KMB]?)", s)
    if not m:
        raise ValueError(s)
    return float(m.group(1)) * {"": 1, "K": 1e3, "M": 1e6, "B": 1e9}[m.group(2)]


def student_loss_curve(log_text: str) -> tuple[list[float], list[float]]:
    matches = list(_LOSS_LINE.finditer(log_text))
    return [parse_step(m.group(1)) for m in matches], [float(m.group(2)) for m in matches]


def _teacher_lines(record: dict) -> list[str]:
    t = record.get("teacher") or {}
    if not t:
        return []
    return [
        "## Teacher",
        "",
        f"**{t['source']}**: `{t['path']}` (`{t['file']}`, iteration {t['iteration']}, preset "
        f"`{t.get('preset')}`, sha256 `{t['sha256'][:12]}…`).",
        "",
    ]


def write_job_report(out: Path, record: dict, bigger: str) -> Path:
    """report.md with its figures, from what each stage left in the output folder."""
    figs = out / "figures"
    figs.mkdir(exist_ok=True)
    preset = record["preset"]["name"]
    lines = [f"# Blind-grasp pipeline report: preset `{preset}`", ""]
    lines += _teacher_lines(record)
    if record.get("student_recipe"):
        lines += [
            "## Student recipe",
            "",
            f"**{record['student_recipe']}** (preset `{preset}`); evaluated: "
            f"`{record.get('student_checkpoint', '')}`.",
            "",
        ]
    lines += ["## Stages", "", "| stage | wall time | command |", "|---|---:|---|"]
    lines += [f"| {name} | {st['wall_s']:.0f} s | `{st['command']}` |" for name, st in record["stages"].items()]
    lines.append("")
    lines += _success_lines(out, record, figs)
    lines += _curve_lines(out, figs)
    lines += _demo_lines(out, record, figs)
    if record.get("deviations"):
        lines += ["## Deviations from the paper (preset `" + preset + "`)", ""]
        lines += [f"- {d}" for d in record["deviations"]] + [""]
    lines += ["## Next", "", bigger]
    path = out / "report.md"
    durable.atomic_write_text(path, "\n".join(lines) + "\n")
    return path


def _success_lines(out: Path, record: dict, figs: Path) -> list[str]:
    """Teacher and student success per object, paired start state by start state, with the grasp strips."""
    teacher = json.loads((out / "teacher_eval" / "eval.json").read_text())
    t_det = {o: r["successes"] for o, r in teacher["modes"]["deterministic"]["per_object"].items()}
    t_sto = {o: r["successes"] for o, r in teacher["modes"].get("stochastic", {}).get("per_object", {}).items()}
    eval_info = json.loads((out / "student_eval" / "eval_info.json").read_text())
    stu = student_successes(eval_info)
    names = [n for n in objects.PAPER_OBJECTS if n in stu] + [n for n in stu if n not in objects.PAPER_OBJECTS]
    # The quick preset evaluates the teacher deterministically only: no empty stochastic column then.
    # column title -> (chart legend, successes per object)
    teacher_cols = {
        "teacher det.": ("teacher (deterministic)", t_det),
        **({"teacher stoch.": ("teacher (stochastic)", t_sto)} if t_sto else {}),
    }
    series = {
        **{legend: [100 * np.mean(col.get(n) or [0]) for n in names] for legend, col in teacher_cols.values()},
        "student (lerobot-eval)": [100 * np.mean(stu[n] or [0]) for n in names],
    }
    bar_chart(figs / "success_per_object.png", names, series, "Sim success per object", "success (%)")
    seed = record.get("seeds", {}).get("eval_index", teacher.get("seed"))
    n_ep = len(next(iter(stu.values()), []))
    lines = [
        "## Success per object (sim)",
        "",
        f"Student: `lerobot-eval --env.type=blindgrasp --env.task={record['preset']['evaluation']['task']} "
        f"--seed={seed}`; teacher: `blindgrasp-eval-teacher --seed={seed}`. Both ran the same {n_ep} start states "
        "per object (evaluation indices from the seed, each object its own draws, none used in teacher training "
        "or demo collection). Success = lifted ≥ 1.5 cm and held ≥ 1 s within 10 s; the paper's randomization and "
        "noise, no pushes. Rates with their 95 % Wilson interval and counts. *paired* = start states on which "
        "both / only the deterministic teacher / only the student succeeded.",
        "",
        "![success](figures/success_per_object.png)",
        "",
        "| object | " + " | ".join(teacher_cols) + " | student | paired both / teacher only / student only |",
        "|---|" + "---:|" * (len(teacher_cols) + 2),
    ]
    lines += _paired_rows(names, teacher_cols, t_det, stu)
    lines.append("")
    strip = write_grasp_strips(eval_info, figs / "grasp_strips.png")
    if strip is not None:
        lines += [
            "Successful student grasps, one rendered lerobot-eval episode per shape (frames across the 10 s "
            "episode; the videos are in `student_eval/videos/`):",
            "",
            "![grasps](figures/grasp_strips.png)",
            "",
        ]
    return lines


def _curve_lines(out: Path, figs: Path) -> list[str]:
    """The teacher's (when trained in this run) and the student's learning curves."""
    lines = ["## Learning curves", ""]
    tc = teacher_curves(out / "teacher") if (out / "teacher").is_dir() else {}  # only when trained in this run
    if tc:
        plot_curves(figs / "teacher_curves.png", tc, "Teacher (PPO)")
        lines += ["![teacher](figures/teacher_curves.png)", ""]
    curves = {}
    for log in sorted((out / "logs").glob("student*.log")):  # the student, then each DAgger round's fine-tuning
        steps, losses = student_loss_curve(log.read_text())
        if steps:
            offset = max((max(c[0]) for c in curves.values()), default=0)
            curves[f"{log.stem}: train loss (MSE, normalized delta)"] = ([offset + x for x in steps], losses)
    if curves:
        plot_curves(figs / "student_loss.png", curves, "Student (BC)")
        lines += ["![student](figures/student_loss.png)", ""]
    return lines


def _demo_lines(out: Path, record: dict, figs: Path) -> list[str]:
    """The demo sets' yield, and what the student trained on."""
    lines = ["## Demonstrations", ""]
    extra = [name for name, _ in ((record.get("preset") or {}).get("demos") or {}).get("extra_episodes", ())]
    sets = [("curated", "demos"), ("uncurated", "demos_uncurated")]
    sets += [(f"{label}, extra episodes of {name}", f"{sub}_{name}") for label, sub in sets for name in extra]
    for label, sub in sets:
        path = out / sub / "yield_report.json"
        if not path.exists():
            continue
        y = json.loads(path.read_text())
        rows = y["objects"]
        demo_names = [n for n in objects.PAPER_OBJECTS if n in rows] or list(rows)
        bar_chart(
            figs / f"yield_{sub}.png",
            demo_names,
            {"yield (%)": [rows.get(n, {}).get("yield", 0) * 100 for n in demo_names]},
            f"Demo yield ({label})",
            "episodes passing curation (%)",
        )
        tot = y["total"]
        lines += [
            f"**{label}** (`{sub}/`): {tot['kept']} episodes written from {tot['rollouts']} rollouts; "
            f"{rates.format_rate(tot['passed'], tot['rollouts'], digits=1)} of the rollouts passed curation.",
            "",
            f"![yield](figures/yield_{sub}.png)",
            "",
        ]
    lines += [f"The student was trained on the **{record.get('student_dataset', 'curated')}** set.", ""]
    sched = record.get("student_schedule") or {}
    if sched.get("steps_per_epoch"):
        lines += [
            f"Student length from its dataset: {sched['total_frames']} frames = {sched['steps_per_epoch']} "
            f"steps per epoch, {sched['steps']} steps, LR constant for the first {sched['constant_lr_steps']}.",
            "",
        ]
    return lines


def _paired_rows(names: list[str], teacher_cols: dict, t_det: dict, stu: dict) -> list[str]:
    """One row per object (every teacher column, the student, the paired counts), the pooled row, and the paired
    McNemar test of the deterministic teacher against the student over all objects."""
    lines: list[str] = []
    pooled = {label: [] for label in teacher_cols}
    pooled_student: list[bool] = []
    paired_all = {"both": 0, "a_only": 0, "b_only": 0}

    def paired_cell(t: list[bool], s: list[bool]) -> str:
        if len(t) != len(s):  # no teacher episodes for this object: nothing to pair
            return "n/a"
        p = rates.paired_counts(t, s)
        for k in paired_all:
            paired_all[k] += p[k]
        return f"{p['both']} / {p['a_only']} / {p['b_only']}"

    for n in names:
        cells = []
        for label, (_, col) in teacher_cols.items():
            pooled[label] += col.get(n, [])
            cells.append(rates.format_rate(*rates.count(col.get(n, []))))
        pooled_student += stu[n]
        lines.append(
            f"| {n} | " + " | ".join(cells) + f" | {rates.format_rate(*rates.count(stu[n]))} | "
            f"{paired_cell(t_det.get(n, []), stu[n])} |"
        )
    cells = [f"**{rates.format_rate(*rates.count(v), digits=1)}**" for v in pooled.values()]
    t_only, s_only = paired_all["a_only"], paired_all["b_only"]
    lines.append(
        f"| **all {len(names)}** | " + " | ".join(cells) + " | "
        f"**{rates.format_rate(*rates.count(pooled_student), digits=1)}** | "
        f"**{paired_all['both']} / {t_only} / {s_only}** |"
    )
    p_paired = rates.mcnemar_exact_p(t_only, s_only)
    lines += [
        "",
        f"Paired over all objects: the teacher alone solved {t_only} start states, the student alone "
        f"{s_only}; exact McNemar p = {p_paired:.3g} ({rates.paired_verdict(p_paired)}).",
    ]
    return lines


SIZE_PREFERENCE = ("medium", "large", "small")  # the medium objects are the paper's headline set


def successful_videos(eval_info: dict) -> dict[str, list[Path]]:
    """Object name -> videos of its successful episodes that exist on disk (episode k is video k)."""
    out: dict[str, list[Path]] = {}
    for task in eval_info.get("per_task", []):
        m = task.get("metrics", {})
        ok = [Path(p) for p, s in zip(m.get("video_paths", []), m.get("successes", []), strict=False) if s]
        ok = [p for p in ok if p.exists()]
        if ok:
            out[object_for_task_id(int(task["task_id"]))] = ok
    return out


def pick_per_class(videos: dict[str, list[Path]]) -> dict[str, tuple[str, Path]]:
    """Shape -> (object, video): for each shape, the first successful video, medium size first."""
    picked: dict[str, tuple[str, Path]] = {}
    for size in SIZE_PREFERENCE:
        for name, paths in videos.items():
            o = objects.get_object(name)
            shape = o.geometry.split("_")[0]  # cuboid_a and cuboid_b are one class
            if o.size_label == size and shape not in picked:
                picked[shape] = (name, paths[0])
    return dict(sorted(picked.items()))


def read_frames(video: Path, n: int) -> tuple[list[np.ndarray], np.ndarray]:
    """n RGB frames evenly spaced over the video (first and last included), and their frame indices. Decoding stops
    at the last index the container's frame count gives; a video without a count, or a wrong one, is decoded whole."""
    import av  # lerobot[dataset] dependency; imported here so the report works without any video

    with av.open(str(video)) as container:
        total = container.streams.video[0].frames  # 0: the container does not say
        if total > 0 and n > 0:
            idx = np.linspace(0, total - 1, n).round().astype(int)
            picked: dict[int, np.ndarray] = {}
            decoded = container.decode(video=0)
            for k, frame in enumerate(decoded):
                if k in idx:
                    picked[k] = frame.to_ndarray(format="rgb24")
                if k == idx[-1]:
                    break
            # With n > 1 the last index is the last frame: no frame may follow it, or the count was wrong. With
            # n == 1 the index is 0 whatever the count.
            if len(picked) == len(set(idx.tolist())) and (n == 1 or next(decoded, None) is None):
                return [picked[i] for i in idx], idx
    with av.open(str(video)) as container:
        frames = [f.to_ndarray(format="rgb24") for f in container.decode(video=0)]
    if not frames:
        raise ValueError(f"{video} has no frames")
    idx = np.linspace(0, len(frames) - 1, n).round().astype(int)
    return [frames[i] for i in idx], idx


def write_grasp_strips(
    eval_info: dict, out_png: Path, frames_per_row: int = 5, fps: float = spec.CONTROL_HZ
) -> Path | None:
    """One PNG: a row of frames per shape. Returns None when no successful episode was rendered."""
    picked = pick_per_class(successful_videos(eval_info))
    if not picked:
        return None
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    rows = len(picked)
    fig, axes = plt.subplots(rows, frames_per_row, figsize=(2.2 * frames_per_row, 1.75 * rows), squeeze=False)
    for r, (_shape, (name, video)) in enumerate(picked.items()):
        frames, idx = read_frames(video, frames_per_row)
        for c, (img, t) in enumerate(zip(frames, idx / fps, strict=True)):
            ax = axes[r][c]
            ax.imshow(img)
            ax.set_xticks([])
            ax.set_yticks([])
            ax.set_title(f"t = {t:.1f} s", fontsize=7)
            if c == 0:
                ax.set_ylabel(name.replace("_", " "), fontsize=8)
    fig.suptitle("Successful student grasps (lerobot-eval videos), one per shape", fontsize=9)
    fig.tight_layout()
    out_png.parent.mkdir(parents=True, exist_ok=True)
    with durable.atomic_path(out_png) as tmp:
        fig.savefig(tmp, dpi=100)
    plt.close(fig)
    return out_png
