"""The robustness envelope: per factor, how far from its training condition the student stays >= 90 %, and what
how a student's card reports it. No MuJoCo and no torch here.

Two readings of "stays >= 90 %", both reported:
- `rate`: the measured rate itself is >= 90 % (the strict reading);
- `ci`: the 95 % Wilson interval still reaches 90 %, i.e. the data do not show the rate below 90 %. With 10
  episodes per object (180 per point) a student at 87 % passes this and fails the strict one.
The envelope grows from the factor's nominal point outwards in plot order and stops at the first point that fails;
two-sided factors (gain, size, friction, servo gain) get a lower and an upper edge.
"""

from __future__ import annotations

from lerobot_blindgrasp.results import rates

THRESHOLD = 0.90


def passes(k: int, n: int, criterion: str = "ci", threshold: float = THRESHOLD) -> bool:
    if n == 0:
        return False
    if criterion == "rate":
        return k / n >= threshold
    if criterion == "ci":
        return rates.wilson_interval(k, n)[1] >= threshold
    raise ValueError(f"unknown criterion {criterion!r}; choose 'rate' or 'ci'")


def envelope(
    points: list[dict], nominal: int, role: str = "student", criterion: str = "ci", threshold: float = THRESHOLD
) -> tuple[int | None, int | None]:
    """(lowest, highest) index of the contiguous run of passing points around `nominal`; (None, None) when the
    nominal point itself fails or has not been run. `points`: dicts with `<role>` = [successes, episodes]."""

    def ok(i: int) -> bool:
        c = points[i].get(role)
        return c is not None and passes(c[0], c[1], criterion, threshold)

    if not ok(nominal):
        return None, None
    lo = hi = nominal
    while lo - 1 >= 0 and ok(lo - 1):
        lo -= 1
    while hi + 1 < len(points) and ok(hi + 1):
        hi += 1
    return lo, hi


def describe_envelope(factor: dict, role: str = "student", criterion: str = "ci") -> str:
    """The envelope of one factor of a sweep summary in words: 'up to 2 N (fails at 3 N)', 'x0.7 (fails at x0.5)
    to x2 (all tested)', ..."""
    pts, nom = factor["points"], factor["nominal"]
    lo, hi = envelope(pts, nom, role, criterion)
    if lo is None:
        return "below at the nominal point" if pts[nom].get(role) else "not run"

    def edge(last: int, nxt: int | None, end: str) -> str:
        if nxt is None:
            return f"{pts[last]['label']} ({end} tested)"
        return (
            f"{pts[last]['label']} ("
            + ("fails at " if pts[nxt].get(role) else "not run at ")
            + f"{pts[nxt]['label']})"
        )

    low = edge(lo, lo - 1 if lo > 0 else None, "smallest") if nom > 0 else None
    high = edge(hi, hi + 1 if hi + 1 < len(pts) else None, "largest") if nom < len(pts) - 1 else None
    if low and high:
        return f"{low} to {high}"
    return f"down to {low}" if low else f"up to {high}" if high else pts[nom]["label"]


def card_section(summary: dict, threshold: float = THRESHOLD) -> str:
    """The robustness section of a student's card, from a sweep summary (`python -m lab.robustness.sweep`'s summary.json)."""
    pct = f"{100 * threshold:g} %"
    lines = [
        "## Robustness envelope (simulation)",
        "",
        f"How far each condition can move from the training randomization before the student drops below {pct} "
        f"success over the {len(summary['objects'])} objects ({summary['episodes_per_object']} episodes per object "
        f"and point, evaluation seeds from {summary['seed']}, the teacher on the same start states). "
        f"*Not shown below {pct}*: the 95 % Wilson interval still reaches {pct}; *>= {pct}*: the measured rate "
        "itself. Made by `" + summary.get("command", "python -m lab.robustness.sweep") + "`.",
        "",
        f"| factor | trained on | student: not shown below {pct} | student: >= {pct} | teacher: >= {pct} |",
        "|---|---|---|---|---|",
    ]
    for f in summary["factors"]:
        if f["name"] == "combined":
            continue
        trained = f.get("train_label") or f["points"][f["nominal"]]["label"]
        lines.append(
            f"| {f['title']} | {trained} | {describe_envelope(f, 'student', 'ci')} | {describe_envelope(f, 'student', 'rate')}"
            f" | {describe_envelope(f, 'teacher', 'rate')} |"
        )
    first = first_to_break(summary)
    if first:
        lines += [
            "",
            f"Broke soonest (student, first magnitude past training whose rate is shown below {pct}): "
            + "; ".join(f"{t} at {lab} ({r})" for t, lab, r in first[:3])
            + ".",
        ]
    return "\n".join(lines) + "\n"


def first_to_break(summary: dict, threshold: float = THRESHOLD) -> list[tuple[str, str, str]]:
    """(factor title, magnitude label, student rate) of each factor's first point past training whose rate is shown
    below `threshold` (its 95 % Wilson interval ends under it), ordered by how close to training that point is (in
    plot steps from the nearest trained point), then by the rate there."""
    out = []
    for f in summary["factors"]:
        if f["name"] == "combined":
            continue
        pts, trained = f["points"], [i for i, p in enumerate(f["points"]) if p["in_training"]]
        for i, p in sorted(enumerate(pts), key=lambda ip: min(abs(ip[0] - t) for t in trained)):
            c = p.get("student")
            if p["in_training"] or not c:
                continue
            if not passes(c[0], c[1], "ci", threshold):
                dist = min(abs(i - t) for t in trained)
                out.append((dist, c[0] / c[1], f["title"], p["label"], rates.format_rate(*c)))
                break
    out.sort()
    return [(t, lab, r) for _, _, t, lab, r in out]
