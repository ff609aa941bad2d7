"""Two evaluations side by side, paired start state by start state: per-object rates and an exact McNemar test. Both
must have run the same seed and episode count, so that episode k of object o is the same start state in both.

    python -m lerobot_blindgrasp.results.compare --a=PATH --b=PATH [--a_label=teacher --b_label=student]
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path

from lerobot_blindgrasp.cli import parse_config
from lerobot_blindgrasp.results import rates
from lerobot_blindgrasp.sim import objects


def student_successes(eval_info: dict) -> dict[str, list[bool]]:
    """Per-object episode successes, in episode (= evaluation index) order, from lerobot-eval's per_task."""
    return {
        objects.object_for_task_id(int(e["task_id"])): [bool(x) for x in e["metrics"].get("successes", [])]
        for e in eval_info.get("per_task", [])
    }


def load_successes(path: str | Path, mode: str | None = None) -> dict[str, list[bool]]:
    """Object -> episode successes in evaluation-index order, from either evaluation tool's output. A teacher
    eval's mode is `mode`, else a `:MODE` suffix of `path`, else deterministic."""
    text = str(path)
    if mode is None:
        text, _, mode = text.partition(":")
    p = Path(text)
    if p.is_dir():
        p = p / "eval_info.json" if (p / "eval_info.json").exists() else p / "eval.json"
    if not p.is_file():
        raise FileNotFoundError(
            f"no eval_info.json (lerobot-eval) or eval.json (blindgrasp-eval-teacher) at {text}"
        )
    data = json.loads(p.read_text())
    if "per_task" in data:
        real = [e for e in data["per_task"] if e.get("task_group") in objects.CATALOGUE]
        if real:  # --env.type=blindgrasp_real: one task group per object, named after it (every task_id is 0)
            return {e["task_group"]: [bool(x) for x in e["metrics"]["successes"]] for e in real}
        return student_successes(data)
    modes = data["modes"]
    mode = mode or "deterministic"
    if mode not in modes:
        raise ValueError(f"{p} has modes {sorted(modes)}, not {mode!r}")
    return {o: [bool(x) for x in r["successes"]] for o, r in modes[mode]["per_object"].items()}


def compare_rates(
    a: dict[str, list[bool]], b: dict[str, list[bool]], label_a: str = "A", label_b: str = "B"
) -> str:
    """Markdown: per object, both rates and the discordant pairs; then all objects pooled, with the McNemar p."""
    names = [o for o in objects.CATALOGUE if o in a and o in b]  # Table I order, then the everyday set
    if not names:
        raise ValueError("the two evaluations share no object")
    for o in names:
        if len(a[o]) != len(b[o]):
            raise ValueError(f"{o}: {len(a[o])} vs {len(b[o])} episodes; pair only runs with the same episodes")
    lines = [f"| object | {label_a} | {label_b} | only {label_a} | only {label_b} |", "|---|---:|---:|---:|---:|"]
    for o in names:
        p = rates.paired_counts(a[o], b[o])
        lines.append(
            f"| {o} | {rates.format_rate(*rates.count(a[o]))} | {rates.format_rate(*rates.count(b[o]))} "
            f"| {p['a_only']} | {p['b_only']} |"
        )
    p = rates.paired_difference(a, b, names)
    ra, rb = (rates.format_rate(p[k], p["n"], digits=1) for k in ("a_successes", "b_successes"))
    lines.append(f"| **all {len(names)}** | **{ra}** | **{rb}** | **{p['a_only']}** | **{p['b_only']}** |")
    lines += [
        "",
        f"{label_b} minus {label_a}: {p['diff_pp']:+.1f} percentage points over {p['n']} paired "
        f"episodes; exact McNemar p = {p['p']:.2g}.",
    ]
    return "\n".join(lines)


@dataclass
class CompareConfig:
    # The two evaluations: an eval_info.json or eval.json, or the folder holding it (a teacher's as `PATH:stochastic`
    # for its stochastic mode). Same seed and episode count, so that they pair.
    a: str
    b: str
    # Their names in the table and in "b minus a".
    a_label: str = "a"
    b_label: str = "b"


def main(argv: list[str] | None = None) -> None:
    cfg = parse_config(CompareConfig, argv)
    print(compare_rates(load_successes(cfg.a), load_successes(cfg.b), cfg.a_label, cfg.b_label))


if __name__ == "__main__":
    main()
