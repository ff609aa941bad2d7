"""`python -m lab.robustness.sweep`: the shipped student (and its teacher, on the same start states) one factor at a time
beyond the training randomization, then several factors combined.

    python -m lab.robustness.sweep --output_dir=outputs/robustness                  # default: ~20 factors, 10 eps/object
    python -m lab.robustness.sweep --preset=smoke --output_dir=/tmp/rob             # what the tests run
    python -m lab.robustness.sweep --factors=obs_latency,force_gain --output_dir=... # a subset

Each point (one `DomainRandomization`, see `factors.py`) runs `episodes` evaluation episodes per object for the
student and the teacher (`point.run_point`) and is saved as its own JSON under `<output_dir>/points/`, named by a
hash of everything that decides its outcome (condition, objects, episodes, seed, both checkpoints' SHA-256, the
sim's source fingerprint). A re-run with the same arguments skips the points already there, so a killed sweep
continues where it stopped. After every point the summary is rewritten (summary.json, summary.md, envelope.md for
the student's card); at the end one plot per factor goes to `<output_dir>/plots/`.
"""

from __future__ import annotations

import hashlib
import io
import json
import logging
import time
from dataclasses import dataclass
from pathlib import Path

from tqdm import tqdm

from lab.robustness import envelope, factors
from lab.robustness.factors import SWEEPS
from lerobot_blindgrasp import durable, spec
from lerobot_blindgrasp.cli import command_line, parse_config
from lerobot_blindgrasp.results import rates
from lerobot_blindgrasp.sim import objects

log = logging.getLogger(__name__)


@dataclass
class RobustnessConfig:
    """Success of the student and its teacher as each factor moves beyond the training randomization."""

    output_dir: Path = Path("outputs/robustness")
    preset: str = "default"  # "default" (<= 30 min on 2 idle cores) or "smoke" (seconds; what the tests run)
    student: Path | None = None  # a LeRobot policy folder; default: the shipped models/student_cpu
    teacher: Path | None = None  # a teacher folder; default: the shipped teacher ($BLINDGRASP_TEACHER or models/)
    episodes: int | None = None  # per object and point; default: the preset's
    objects: str | None = None  # "all", "medium" or a comma list; default: the preset's
    factors: str | None = None  # comma list of factor names to run, in this order (default: all of the preset)
    # only these points, as a comma list of factor=label (labels as in summary.md, e.g. "force_bias=2 N"); each
    # factor's nominal point always runs. For a cut-down run on a busy machine; the rest show as not run.
    points: str | None = None
    seed: int = spec.EVAL_SEED  # first evaluation index: episode k of every object is index seed + k
    threads: int = 0  # physics threads (0: all CPUs); torch uses the same number
    progress: bool = True
    # where models/ lives (the shipped student): the repository root, found from the package by default
    models_dir: Path | None = None

    def __post_init__(self):
        if self.preset not in SWEEPS:
            raise ValueError(f"unknown preset {self.preset!r}; choose from {', '.join(SWEEPS)}")
        sweep = SWEEPS[self.preset]
        self.episodes = self.episodes or sweep.episodes
        if self.episodes < 1:
            raise ValueError(f"episodes must be >= 1, got {self.episodes}")
        self.object_names = objects.resolve_objects(self.objects or sweep.objects)
        spec.eval_env_seed(self.seed + self.episodes - 1, 0)
        all_factors = sweep.factors()
        if self.factors:
            wanted = [x.strip() for x in self.factors.split(",") if x.strip()]
            known = {f.name for f in all_factors}
            unknown = [w for w in wanted if w not in known]
            if unknown:
                raise ValueError(f"unknown factor(s) {unknown}; this preset has {', '.join(sorted(known))}")
            by_name = {f.name: f for f in all_factors}
            all_factors = [by_name[w] for w in wanted]  # run in the order given
        self.factor_list = all_factors
        self.point_filter = None
        if self.points:
            pairs = {tuple(x.strip().split("=", 1)) for x in self.points.split(",") if x.strip()}
            labels = {(f.name, p.label) for f in all_factors for p in f.points}
            unknown = sorted("=".join(pr) for pr in pairs if pr not in labels)
            if unknown:
                raise ValueError(f"unknown point(s) {unknown}; use factor=label as summary.md lists them")
            self.point_filter = pairs


def default_student(models_dir: Path | None = None) -> Path:
    from lerobot_blindgrasp import shipped

    d = (models_dir or shipped.folder("models")) / "student_cpu"
    if not (d / "config.json").is_file():
        raise FileNotFoundError(f"the shipped student is not at {d}; pass --student=<a LeRobot policy folder>")
    return d


def _sha256_dir(path: Path) -> str:
    h = hashlib.sha256()
    for p in sorted(path.glob("*.safetensors")) + sorted(path.glob("*.json")):
        h.update(p.name.encode())
        h.update(p.read_bytes())
    return h.hexdigest()


def point_id(point: factors.Point, context: dict) -> str:
    blob = json.dumps({"key": point.key, **context}, sort_keys=True, default=str)
    return hashlib.sha256(blob.encode()).hexdigest()[:16]


def run(cfg: RobustnessConfig, command: str = "") -> dict:
    """Run (or continue) the sweep; returns the summary it wrote. `command`: the command line, for the records."""
    import torch

    from lab.robustness.point import run_point
    from lerobot_blindgrasp.rollout.actors import StudentActor
    from lerobot_blindgrasp.teacher.policy import TeacherPolicy, default_teacher

    if cfg.threads:
        torch.set_num_threads(cfg.threads)
    student_path = Path(cfg.student or default_student(cfg.models_dir))
    student = StudentActor.load(student_path, cfg.object_names)
    teacher = TeacherPolicy(cfg.teacher or default_teacher())
    context = {
        "objects": list(cfg.object_names),
        "episodes": cfg.episodes,
        "seed": cfg.seed,
        "student_sha256": _sha256_dir(student_path),
        "teacher_sha256": teacher.sha256,
    }
    out = Path(cfg.output_dir)
    (out / "points").mkdir(parents=True, exist_ok=True)
    todo: dict[str, factors.Point] = {}
    for f in cfg.factor_list:
        for i, p in enumerate(f.points):
            if cfg.point_filter is None or i == f.nominal or (f.name, p.label) in cfg.point_filter:
                todo.setdefault(point_id(p, context), p)
    done = {pid for pid in todo if (out / "points" / f"{pid}.json").is_file()}
    if done:
        print(f"continuing: {len(done)} of {len(todo)} points already in {out / 'points'}")
    meta = {"student": str(student_path), "teacher": str(teacher.checkpoint), "command": command, **context}
    bar = tqdm(total=len(todo), initial=len(done), desc="robustness points", disable=not cfg.progress, unit="pt")
    for pid, p in todo.items():
        if pid in done:
            continue
        bar.set_postfix_str(p.key[:60])
        t0 = time.perf_counter()
        res = run_point(p.dr(), student, teacher, cfg.object_names, cfg.episodes, cfg.seed, nthread=cfg.threads)
        record = {
            "key": p.key,
            "overrides": [[k, v] for k, v in p.overrides],
            **context,
            "wall_s": time.perf_counter() - t0,
            **res,
        }
        durable.atomic_write_json(out / "points" / f"{pid}.json", record)
        write_summary(cfg, out, context, meta)
        bar.update(1)
    bar.close()
    summary = write_summary(cfg, out, context, meta)
    for f in summary["factors"]:
        plot_factor(f, out / "plots" / f"{f['name']}.png", summary)
    return summary


def _counts(flags: dict[str, list[bool]]) -> list[int]:
    k, n = rates.count(x for v in flags.values() for x in v)
    return [k, n]


def build_summary(cfg: RobustnessConfig, out: Path, context: dict, meta: dict) -> dict:
    """Every factor with the points run so far: counts per role, in-training flags, the combined levels."""
    fs = []
    total_s = 0.0
    for f in cfg.factor_list:
        pts = []
        for p in f.points:
            path = out / "points" / f"{point_id(p, context)}.json"
            entry = {"label": p.label, "magnitude": p.magnitude, "in_training": f.in_training(p), "key": p.key}
            if path.is_file():
                rec = json.loads(path.read_text())
                entry["student"] = _counts(rec["student"])
                entry["teacher"] = _counts(rec["teacher"])
                entry["paired"] = rates.paired_counts(
                    [x for o in cfg.object_names for x in rec["teacher"][o]],
                    [x for o in cfg.object_names for x in rec["student"][o]],
                )
                total_s += rec["wall_s"]
            pts.append(entry)
        tr = f.train_range
        fs.append(
            {
                "name": f.name,
                "title": f.title,
                "unit": f.unit,
                "group": f.group,
                "nominal": f.nominal,
                "train_range": list(tr) if tr else None,
                "train_label": f"{tr[0]:g} to {tr[1]:g} {f.unit}" if tr else None,
                "points": pts,
            }
        )
    return {
        **meta,
        "objects": list(cfg.object_names),
        "episodes_per_object": cfg.episodes,
        "threshold": envelope.THRESHOLD,
        "combined_levels": factors.describe_combined(),
        "points_wall_s": total_s,
        "factors": fs,
    }


def write_summary(cfg, out: Path, context: dict, meta: dict) -> dict:
    summary = build_summary(cfg, out, context, meta)
    durable.atomic_write_json(out / "summary.json", summary)
    durable.atomic_write_text(out / "summary.md", markdown(summary))
    durable.atomic_write_text(out / "envelope.md", envelope.card_section(summary))
    return summary


def _cell(c) -> str:
    return rates.format_rate(*c) if c else "(not run)"


def markdown(summary: dict) -> str:
    lines = [
        f"Student `{summary['student']}` and teacher `{summary['teacher']}` on the same start states: "
        f"{summary['episodes_per_object']} episodes per object x {len(summary['objects'])} objects per point, "
        f"evaluation indices {summary['seed']}..{summary['seed'] + summary['episodes_per_object'] - 1} "
        "(spec.eval_env_seed); 95 % Wilson intervals; *train*: the magnitude lies in the training randomization. "
        "*paired*: start states both / only the student / only the teacher solved.",
        "",
        "| factor | magnitude | train | student | teacher | paired both / student only / teacher only |",
        "|---|---|:-:|---:|---:|---:|",
    ]
    for f in summary["factors"]:
        for p in f["points"]:
            pr = p.get("paired")
            paired = f"{pr['both']} / {pr['b_only']} / {pr['a_only']}" if pr else ""
            lines.append(
                f"| {f['title']} | {p['label']} | {'yes' if p['in_training'] else ''} | "
                f"{_cell(p.get('student'))} | {_cell(p.get('teacher'))} | {paired} |"
            )
    lines += ["", "Combined levels: " + "; ".join(summary["combined_levels"]) + ".", ""]
    return "\n".join(lines)


def plot_factor(f: dict, path: Path, summary: dict) -> None:
    """Success against magnitude (evenly spaced, labelled), student and teacher with 95 % Wilson bars, the
    training span shaded, the 90 % line dashed."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    pts = f["points"]
    x = list(range(len(pts)))
    fig, ax = plt.subplots(figsize=(6.4, 3.8))
    trained = [i for i, p in enumerate(pts) if p["in_training"]]
    if trained:
        ax.axvspan(min(trained) - 0.4, max(trained) + 0.4, color="0.88", label="training range")
    for role, color, marker in (("student", "tab:blue", "o"), ("teacher", "tab:orange", "s")):
        xs, ys, lo, hi = [], [], [], []
        for i, p in enumerate(pts):
            c = p.get(role)
            if not c:
                continue
            a, b = rates.wilson_interval(*c)
            xs.append(i)
            ys.append(100 * c[0] / c[1])
            lo.append(100 * (c[0] / c[1] - a))
            hi.append(100 * (b - c[0] / c[1]))
        if xs:
            ax.errorbar(xs, ys, yerr=[lo, hi], color=color, marker=marker, capsize=3, label=role)
    ax.axhline(100 * summary["threshold"], color="0.4", ls="--", lw=1, label=f"{100 * summary['threshold']:g} %")
    ax.set_xticks(x, [p["label"] for p in pts], fontsize=8)
    ax.set_xlim(-0.6, len(pts) - 0.4)
    ax.set_ylim(0, 102)
    ax.set_ylabel("success (%)")
    ax.set_xlabel(f"{f['title']} ({f['unit']})")
    n = summary["episodes_per_object"] * len(summary["objects"])
    ax.set_title(f"{f['title']}: {n} episodes per point", fontsize=10)
    ax.legend(fontsize=7, loc="lower left")
    fig.tight_layout()
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=110)
    plt.close(fig)
    durable.atomic_write_bytes(path, buf.getvalue())


def main(argv=None) -> None:
    cfg = parse_config(RobustnessConfig, argv)
    try:
        summary = run(cfg, command_line("python -m lab.robustness.sweep", argv))
    except (FileNotFoundError, ValueError) as e:
        raise SystemExit(f"error: {e}") from None
    out = Path(cfg.output_dir)
    print(envelope.card_section(summary))
    print(
        f"wrote {out}/summary.json, summary.md, envelope.md, plots/ ({len(summary['factors'])} factors); "
        f"points took {summary['points_wall_s'] / 60:.1f} min"
    )


if __name__ == "__main__":
    main()
