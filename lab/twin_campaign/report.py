"""A twin measurement's record: per-object successes and who judged them, what stopped the real stack, the peak
fingertip forces, the real loop's step timing, the twin's own cost and the machine's load.

    python -m lab.twin_campaign.report --run=OUT [--sim=OUT/sim]

OUT is what `python -m lab.twin_campaign.measure` fills: `real_trials.jsonl` (the real env's trial log, one
line per trial that ended), `stops.jsonl` (trials the real stack's safety latch ended: a failure, with its error),
`twin_trials.jsonl` (the twin's placements, verdicts and true peak forces), `twin.log` and `load.jsonl`. Trials are
keyed by their evaluation index (lerobot-eval's seed), so the result pairs with a `--env.type=blindgrasp` run of the
same seed: `eval_info.json` is written in lerobot-eval's per_task layout for `results/compare.py`, which `--sim`
runs.
"""

from __future__ import annotations

import json
from collections import defaultdict
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from lerobot_blindgrasp import durable, spec
from lerobot_blindgrasp.cli import parse_config
from lerobot_blindgrasp.results import rates
from lerobot_blindgrasp.sim import objects

Outcomes = dict[str, dict[int, tuple[bool, str]]]  # object -> seed -> (success, who decided or what stopped it)


def read_jsonl(path: Path) -> list[dict]:
    if not path.is_file():
        return []
    return [json.loads(line) for line in path.read_text().splitlines() if line.strip()]


def outcomes(run: Path) -> Outcomes:
    out: Outcomes = defaultdict(dict)
    for t in read_jsonl(run / "real_trials.jsonl"):
        out[t["object"]][int(t["seed"])] = (bool(t["success"]), t["decided_by"])
    for s in read_jsonl(run / "stops.jsonl"):
        out[s["object"]].setdefault(int(s["seed"]), (False, "stopped: " + s["error"]))
    return out


def judges(results: Outcomes) -> list[str]:
    """Who decided the trials that ran to their end (the real env's `decided_by`), most frequent first."""
    counts: dict[str, int] = defaultdict(int)
    for per_seed in results.values():
        for _, who in per_seed.values():
            if not who.startswith("stopped: "):
                counts[who] += 1
    return sorted(counts, key=lambda w: -counts[w])


def eval_info(results: Outcomes) -> dict:
    names = [o for o in objects.CATALOGUE if o in results]
    tasks = [{"task_group": o, "task_id": 0,
              "metrics": {"successes": [results[o][k][0] for k in sorted(results[o])], "seeds": sorted(results[o])}}
             for o in names]  # fmt: skip
    return {"judge": "; ".join(judges(results)) or "none (no trial ran to its end)", "per_task": tasks}


def timing(run: Path) -> dict[str, dict[str, float]]:
    """Each trial's p50/p99 of the read, policy and write times (ms), pooled: median of the trials' p50s, median
    and worst p99, and overruns (periods over 75 ms) per trial step."""
    trials = [t for t in read_jsonl(run / "real_trials.jsonl") if t.get("step_ms")]
    out = {}
    for part in ("read", "policy", "write"):
        rows = np.array([t["step_ms"][part][:2] for t in trials if t["step_ms"].get(part)])
        if rows.size:
            out[part] = {"p50_ms": round(float(np.median(rows[:, 0])), 2),
                         "p99_ms_median": round(float(np.median(rows[:, 1])), 2),
                         "p99_ms_worst": round(float(rows[:, 1].max()), 2)}  # fmt: skip
    out["overruns"] = {
        "periods": sum(t["steps"] for t in trials),
        "overruns": sum(t["loop_overruns"] for t in trials),
        "late_steps_rebased": sum(t["late_steps_rebased"] for t in trials),
    }
    return out


def twin_status(run: Path) -> dict | None:
    log = run / "twin.log"
    lines = [x for x in log.read_text().splitlines() if x.startswith("twin ")] if log.is_file() else []
    return json.loads("{" + lines[-1].split("{", 1)[1]) if lines else None  # "twin [final ]status {...}"


STOP_CAUSES = (  # (what the error says, the cause), first match wins
    ("overload", "fingertip force over overload_n"),
    ("stale", "force data stale (> stale_timeout_s)"),
    ("stream stopped", "force data stale (> stale_timeout_s)"),
    ("overrun its", "loop overran its period for max_overrun_s"),
    ("There is no status packet", "bus reply timeout"),
    ("start pose", "did not reach the start pose"),
    ("implausible", "position gate"),
)


def stop_cause(error: str) -> str:
    return next((cause for text, cause in STOP_CAUSES if text in error), error[:80])


def table(results: Outcomes) -> str:
    rows = ["| object | success (95 % Wilson) | stopped by the real stack |", "|---|---:|---:|"]
    n = s = st = 0
    for o in [o for o in objects.CATALOGUE if o in results]:
        r = results[o].values()
        k, ok, stop = len(r), sum(x[0] for x in r), sum(x[1].startswith("stopped") for x in r)
        n, s, st = n + k, s + ok, st + stop
        rows.append(f"| {o} | {rates.format_rate(ok, k)} | {stop} |")
    rows.append(f"| **all** | **{rates.format_rate(s, n, digits=1)}** | {st} |")
    return "\n".join(rows)


def peak_forces(run: Path) -> str:
    """Per object: the largest fingertip force of each trial, as the host read it (the real env's trial log, trials
    that ran to their end) and as the twin's physics had it (every placed trial, stopped ones included)."""
    host, truth = defaultdict(list), defaultdict(list)
    for t in read_jsonl(run / "real_trials.jsonl"):
        host[t["object"]].append(max(t["peak_force_n"]))
    for t in read_jsonl(run / "twin_trials.jsonl"):
        if "peak_tip_force_n" in t:
            truth[t["object"]].append((max(t["peak_tip_force_n"]), spec.FORCE_SENSOR_NAMES[int(np.argmax(t["peak_tip_force_n"]))]))  # fmt: skip
    rows = ["| object | host: median / max trial peak (N) | twin: median / max trial peak (N), tip of the max |",
            "|---|---:|---:|"]  # fmt: skip
    for o in [o for o in objects.CATALOGUE if o in host or o in truth]:
        h = f"{np.median(host[o]):.1f} / {max(host[o]):.1f}" if host[o] else "-"
        peaks = [p for p, _ in truth[o]]
        t = f"{np.median(peaks):.1f} / {max(peaks):.1f} ({max(truth[o])[1]})" if truth[o] else "-"
        rows.append(f"| {o} | {h} | {t} |")
    every = [p for v in truth.values() for p, _ in v]
    if every:
        rows.append(f"| **all** | | **{np.median(every):.1f} / {max(every):.1f}**; "
                    f"{sum(p > 40 for p in every)} of {len(every)} trials above 40 N |")  # fmt: skip
    return "\n".join(rows)


def load_by_trial(run: Path) -> list[tuple[float, int, int]]:
    """(mean 1-minute load over the trial, its overruns, its periods) per trial that ran to its end, from the twin's
    end-of-trial time stamps and `load.jsonl`."""
    load = read_jsonl(run / "load.jsonl")
    ends = {(t["object"], t["seed"]): t["t_end"] for t in read_jsonl(run / "twin_trials.jsonl") if "t_end" in t}
    out = []
    for t in read_jsonl(run / "real_trials.jsonl"):
        end = ends.get((t["object"], t["seed"]))
        if end is None or not load:
            continue
        window = [x["load1"] for x in load if end - t["steps"] * spec.CONTROL_DT - 30 <= x["t"] <= end + 10]
        if window:
            out.append((float(np.mean(window)), t["loop_overruns"], t["steps"]))
    return out


def machine_load(run: Path) -> str:
    load = read_jsonl(run / "load.jsonl")
    if not load:
        return "no load samples (load.jsonl)"
    l1, busy = [x["load1"] for x in load], [x["cpu_busy"] for x in load]
    lines = [f"1-minute load average: median {np.median(l1):.1f}, 10-90 % {np.percentile(l1, 10):.1f}-"
             f"{np.percentile(l1, 90):.1f}, max {max(l1):.1f}; CPU busy: median {100 * np.median(busy):.0f} % of "
             f"all cores ({len(load)} samples)"]  # fmt: skip
    trials = load_by_trial(run)
    for lo, hi in ((0, 2), (2, 4), (4, 8), (8, 1e9)):
        sel = [(o, s) for m, o, s in trials if lo <= m < hi]
        if sel:
            o, s = sum(x[0] for x in sel), sum(x[1] for x in sel)
            lines.append(f"- trials at load {lo}-{hi if hi < 1e9 else 'inf'}: {len(sel)} trials, {o} overruns "
                         f"in {s} periods ({100 * o / max(s, 1):.1f} %)")  # fmt: skip
    return "\n".join(lines)


def stops(run: Path) -> dict[str, int]:
    out: dict[str, int] = defaultdict(int)
    for s in read_jsonl(run / "stops.jsonl"):
        out[stop_cause(s["error"])] += 1
    return dict(out)


def render(run: Path, sim: Path | None = None) -> str:
    """The whole record as markdown; writes `eval_info.json` into `run` first."""
    results = outcomes(run)
    info = eval_info(results)
    durable.atomic_write_json(run / "eval_info.json", info, indent=1)
    parts = [f"Judged by: {info['judge']}", "", table(results), "", f"Stops by cause: {json.dumps(stops(run))}"]
    if sim is not None:
        from lerobot_blindgrasp.results.compare import compare_rates, load_successes

        paired = compare_rates(load_successes(sim), load_successes(run), "sim", "twin")
        durable.atomic_write_text(run / "compare.md", paired + "\n")
        parts += ["", "Paired with the sim env on the same start states:", "", paired]
    parts += ["", "Peak fingertip forces:", "", peak_forces(run)]
    parts += ["", "Real loop step timing (ms):", "```", json.dumps(timing(run), indent=1), "```"]
    parts += ["", "Twin status (its own cost):", "```", json.dumps(twin_status(run), indent=1), "```"]
    parts += ["", "Machine load:", machine_load(run)]
    return "\n".join(parts) + "\n"


@dataclass
class TwinReportConfig:
    run: Path  # the measurement's output folder
    sim: Path | None = None  # a --env.type=blindgrasp run of the same seeds, to pair with


def main(argv: list[str] | None = None) -> None:
    cfg = parse_config(TwinReportConfig, argv)
    print(render(cfg.run, cfg.sim))


if __name__ == "__main__":
    main()
