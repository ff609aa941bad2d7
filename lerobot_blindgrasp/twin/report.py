"""A twin measurement's record: per-object successes, the real loop's step timing, and what stopped the real stack.

    python -m lerobot_blindgrasp.twin.report --run=OUT

OUT is what `docs/results/twin/measure.sh` fills: `real_trials.jsonl` (the real env's trial log, one line per
trial that ended), `stops.jsonl` (trials the real stack's safety latch ended: a failure, with its error) and
`twin.log`. Trials are keyed by their evaluation index (lerobot-eval's seed), so the result pairs with a
`--env.type=blindgrasp` run of the same seed: `eval_info.json` is written in lerobot-eval's per_task layout for
`results/compare.py`.
"""

from __future__ import annotations

import json
from collections import defaultdict
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from lerobot_blindgrasp import durable
from lerobot_blindgrasp.cli import parse_config
from lerobot_blindgrasp.sim import objects


def read_jsonl(path: Path) -> list[dict]:
    if not path.is_file():
        return []
    return [json.loads(line) for line in path.read_text().splitlines() if line.strip()]


def outcomes(run: Path) -> dict[str, dict[int, tuple[bool, str]]]:
    """object -> seed -> (success, who decided or what stopped it)."""
    out: dict[str, dict[int, tuple[bool, str]]] = defaultdict(dict)
    for t in read_jsonl(run / "real_trials.jsonl"):
        out[t["object"]][int(t["seed"])] = (bool(t["success"]), t["decided_by"])
    for s in read_jsonl(run / "stops.jsonl"):
        out[s["object"]].setdefault(int(s["seed"]), (False, "stopped: " + s["error"]))
    return out


def eval_info(results: dict[str, dict[int, tuple[bool, str]]]) -> dict:
    names = [o for o in objects.CATALOGUE if o in results]
    return {
        "per_task": [
            {
                "task_group": o,
                "task_id": 0,
                "metrics": {
                    "successes": [results[o][k][0] for k in sorted(results[o])],
                    "seeds": sorted(results[o]),
                },
            }
            for o in names
        ]
    }


def timing(run: Path) -> dict[str, dict[str, float]]:
    """Each trial's p50/p99 of the read, policy and write times (ms), pooled: median of the trials' p50s, worst
    p99, and overruns (periods over 75 ms) per trial step."""
    trials = [t for t in read_jsonl(run / "real_trials.jsonl") if t.get("step_ms")]
    out = {}
    for part in ("read", "policy", "write"):
        rows = np.array([t["step_ms"][part] for t in trials if t["step_ms"].get(part)])
        if rows.size:
            out[part] = {
                "p50_ms": float(np.median(rows[:, 0])),
                "p99_ms_median": float(np.median(rows[:, 1])),
                "p99_ms_worst": float(rows[:, 1].max()),
            }
    steps = sum(t["steps"] for t in trials)
    out["overruns"] = {
        "periods": steps,
        "overruns": sum(t["loop_overruns"] for t in trials),
        "late_steps_rebased": sum(t["late_steps_rebased"] for t in trials),
    }
    return out


def twin_status(run: Path) -> dict | None:
    log = run / "twin.log"
    lines = [x for x in log.read_text().splitlines() if x.startswith("twin ")] if log.is_file() else []
    return json.loads(lines[-1].split(" ", 3)[-1]) if lines else None


STOP_CAUSES = (  # (what the error says, the cause), first match wins
    ("overload", "fingertip force over overload_n"),
    ("stale", "force data stale (> stale_timeout_s)"),
    ("stream stopped", "force data stale (> stale_timeout_s)"),
    ("There is no status packet", "bus reply timeout"),
    ("start pose", "did not reach the start pose"),
    ("implausible", "position gate"),
)


def stop_cause(error: str) -> str:
    return next((cause for text, cause in STOP_CAUSES if text in error), error[:80])


def table(results: dict[str, dict[int, tuple[bool, str]]]) -> str:
    rows = ["| object | trials | successes | stopped by the real stack |", "|---|---:|---:|---:|"]
    n = s = st = 0
    for o in [o for o in objects.CATALOGUE if o in results]:
        r = results[o].values()
        k, ok, stop = len(r), sum(x[0] for x in r), sum(x[1].startswith("stopped") for x in r)
        n, s, st = n + k, s + ok, st + stop
        rows.append(f"| {o} | {k} | {ok} | {stop} |")
    rows.append(f"| **all** | {n} | {s} ({100.0 * s / max(n, 1):.1f} %) | {st} |")
    return "\n".join(rows)


@dataclass
class TwinReportConfig:
    run: Path  # the measurement's output folder


def main(argv: list[str] | None = None) -> None:
    cfg = parse_config(TwinReportConfig, argv)
    results = outcomes(cfg.run)
    durable.atomic_write_json(cfg.run / "eval_info.json", eval_info(results), indent=1)
    print(table(results))
    stops = defaultdict(int)
    for s in read_jsonl(cfg.run / "stops.jsonl"):
        stops[stop_cause(s["error"])] += 1
    print("\nstops by cause:", json.dumps(dict(stops)))
    print("\nreal loop step timing:", json.dumps(timing(cfg.run), indent=1))
    print("\ntwin status:", json.dumps(twin_status(cfg.run), indent=1))


if __name__ == "__main__":
    main()
