"""Table V (the paper's ablations) from a recipe output folder: per-object success of every row, with intervals.

    python -m lab.table_v --output_dir=OUT_DIR   # after `bash scripts/paper_recipe.sh OUT_DIR`

Reads what `scripts/paper_recipe.sh` (`blindgrasp-pipeline --print_commands=STAGE`) leaves in OUT_DIR: each student
row's lerobot-eval (`eval_<row>/eval_info.json`), the RL w/ o_t teacher's own eval (`<teacher>_eval/eval.json`,
deterministic) and each row's demo yield (`demos_<row>/yield_report.json`). Rows not run yet are listed as missing.
All rows are evaluated on the same start states (the preset's eval seed), so the per-object columns are paired.
Each row names the teacher it was made with, as the run recorded it: the demos' provenance (`collection.json`) for
a student row, the teacher's own `teacher_config.json` for RL w/ o_t.
Writes `OUT_DIR/table_v.md` and `OUT_DIR/table_v.png` (bar chart per object).
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path

from lerobot_blindgrasp import durable
from lerobot_blindgrasp.cli import parse_config
from lerobot_blindgrasp.demos.provenance import PROVENANCE_NAME
from lerobot_blindgrasp.presets import TABLE_V
from lerobot_blindgrasp.presets.ablations import teacher_words
from lerobot_blindgrasp.results import rates
from lerobot_blindgrasp.sim import objects


def row_successes(out: Path, name: str) -> dict[str, list[bool]] | None:
    """Object -> episode successes of one Table V row, or None if that row has not been evaluated."""
    from lerobot_blindgrasp.results.compare import load_successes

    row = TABLE_V[name]
    path = out / f"eval_{name}" / "eval_info.json" if row.student else out / f"{row.teacher}_eval" / "eval.json"
    return load_successes(path, mode="deterministic") if path.exists() else None


def row_teacher(out: Path, name: str) -> str:
    """Which teacher recipe made this row, from what its run recorded (not from the registry, which may have
    changed since): preset, switches, iterations, whether it clones scripted grasps, and the checkpoint."""
    row = TABLE_V[name]
    if row.student:
        prov = out / f"demos_{name}" / PROVENANCE_NAME
        if not prov.exists():
            return "not collected"
        t = json.loads(prov.read_text())["teacher"]
        words = teacher_words(t.get("preset") or "?", t.get("variant"), t.get("iteration"))
        return f"{words} ({t['checkpoint_name']})"
    path = out / f"{row.teacher}_eval" / "eval.json"
    if not path.exists():
        return "not evaluated"
    ev = json.loads(path.read_text())
    ckpt = Path(ev["checkpoint"])
    # The recipe trains it in OUT/<teacher>; the eval names the checkpoint as it was given (maybe relative).
    for config in (out / row.teacher / "teacher_config.json", ckpt.parent / "teacher_config.json"):
        if config.exists():
            c = json.loads(config.read_text())
            return f"{teacher_words(c.get('preset') or '?', c.get('variant'), ev.get('iteration'))} ({ckpt.name})"
    return f"`{ckpt}`, iteration {ev.get('iteration')} (its teacher_config.json is not there)"


def demo_budget(out: Path, name: str) -> str:
    path = out / f"demos_{name}" / "yield_report.json"
    if not TABLE_V[name].student:
        return "no demos (PPO on o_t)"
    if not path.exists():
        return "not collected"
    t = json.loads(path.read_text())["total"]
    return f"{t['kept']} episodes, {t['frames']} frames (from {t['rollouts']} rollouts)"


def paired_with_proposed(done: dict[str, dict[str, list[bool]]], names: list[str]) -> list[str]:
    """Each row against the proposed student on the same start states (all objects pooled): the start states only
    one of the two solved, the difference in success, and the exact McNemar p-value of that difference."""
    if "proposed" not in done:
        return []
    lines = [
        "",
        "Paired with the proposed student, all objects pooled, episode by episode on the same start states:",
        "",
        "| row | success difference | only proposed solved | only this row solved | exact McNemar p |",
        "|---|---:|---:|---:|---:|",
    ]
    for n, r in done.items():
        if n == "proposed":
            continue
        try:
            p = rates.paired_difference(done["proposed"], r, names)
        except ValueError:
            n_row, n_base = (sum(len(x.get(o, [])) for o in names) for x in (r, done["proposed"]))
            lines.append(f"| {TABLE_V[n].label} | not paired: {n_row} episodes vs {n_base} | | | |")
            continue
        lines.append(
            f"| {TABLE_V[n].label} | {p['diff_pp']:+.1f} pp | {p['a_only']} | {p['b_only']} | {p['p']:.2g} |"
        )
    return lines


def write_table_v(out: Path) -> Path:
    from lerobot_blindgrasp.results.plots import bar_chart

    results = {name: row_successes(out, name) for name in TABLE_V}
    done = {n: r for n, r in results.items() if r}
    names = [o for o in objects.PAPER_OBJECTS if any(o in r for r in done.values())]
    lines = [
        "# Table V in simulation",
        "",
        f"Rows from `{out}`; every row on the same start states, 95 % Wilson intervals and counts.",
        "",
        "| row | teacher | demos |",
        "|---|---|---|",
    ]
    lines += [f"| {TABLE_V[n].label} | {row_teacher(out, n)} | {demo_budget(out, n)} |" for n in TABLE_V]
    # The paper's last column: each object's success averaged over the rows, its difficulty whatever the method.
    lines += [
        "",
        "| object | " + " | ".join(TABLE_V[n].label for n in done) + " | object average |",
        "|---|" + "---:|" * (len(done) + 1),
    ]

    def average(subset: list[str]) -> str:
        rows = [rates.count([x for o in subset for x in done[n].get(o, [])]) for n in done]
        return f"{100 * sum(k / t for k, t in rows if t) / max(1, sum(1 for _, t in rows if t)):.1f} %"

    for o in names:
        lines.append(
            f"| {o} | "
            + " | ".join(rates.format_rate(*rates.count(done[n].get(o, []))) for n in done)
            + f" | {average([o])} |"
        )
    medium = [o for o in names if o.endswith("_medium")]
    for label, subset in ((f"{len(medium)} medium", medium), (f"all {len(names)}", names)):
        cells = [
            rates.format_rate(*rates.count([x for o in subset for x in done[n].get(o, [])]), digits=1)
            for n in done
        ]
        lines.append(f"| **{label}** | " + " | ".join(f"**{c}**" for c in cells) + f" | {average(subset)} |")
    lines += paired_with_proposed(done, names)
    missing = [TABLE_V[n].label for n in TABLE_V if n not in done]
    if missing:
        lines += ["", "Not run yet: " + ", ".join(missing) + "."]
    lines += ["", "![Table V](table_v.png)", ""]
    if done:
        series = {
            TABLE_V[n].label: [100 * sum(r.get(o, [])) / max(1, len(r.get(o, []))) for o in names]
            for n, r in done.items()
        }
        bar_chart(out / "table_v.png", names, series, "Table V in simulation: success per object", "success (%)")
    path = out / "table_v.md"
    durable.atomic_write_text(path, "\n".join(lines) + "\n")
    return path


@dataclass
class TableVConfig:
    output_dir: (
        Path  # the recipe's folder (`scripts/paper_recipe.sh OUT_DIR`): table_v.md and table_v.png go there
    )


def main(argv: list[str] | None = None) -> None:
    print(write_table_v(parse_config(TableVConfig, argv).output_dir))


if __name__ == "__main__":
    main()
