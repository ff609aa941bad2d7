"""Per-object success table of a real-gripper evaluation, from lerobot-eval's `eval_info.json`. Each rate comes
with its 95 % Wilson interval, under a first line naming who judged the trials.

    python -m lerobot_blindgrasp.envs.real_report --eval_info=outputs/eval/<run>/eval_info.json   # or its folder
"""

from __future__ import annotations

import atexit
import json
import sys
from dataclasses import dataclass
from pathlib import Path

from lerobot_blindgrasp import durable
from lerobot_blindgrasp.cli import parse_config
from lerobot_blindgrasp.results.rates import wilson_interval

USAGE = "python -m lerobot_blindgrasp.envs.real_report --eval_info=outputs/eval/<run>/eval_info.json"


def _row(name: str, n: int, s: int) -> str:
    lo, hi = wilson_interval(s, n)
    rate = f"{100.0 * s / n:.1f} %" if n else "n/a"
    return f"| {name} | {n} | {s} | {rate} | {100 * lo:.0f}-{100 * hi:.0f} % |"


def success_table(eval_info: dict) -> str:
    if not isinstance(eval_info, dict) or not isinstance(eval_info.get("per_task"), list):
        raise ValueError("not a lerobot-eval eval_info.json: it has no per_task list")
    rows = ["| object | trials | successes | success rate | 95 % interval |", "|---|---:|---:|---:|---:|"]
    total_n = total_s = 0
    for task in eval_info["per_task"]:
        try:
            name, successes = task["task_group"], [bool(s) for s in task["metrics"]["successes"]]
        except (KeyError, TypeError) as e:
            raise ValueError(f"a per_task entry lacks task_group or metrics.successes ({e!r})") from None
        n, s = len(successes), sum(successes)
        total_n, total_s = total_n + n, total_s + s
        rows.append(_row(name, n, s))
    rows.append(_row("**overall**", total_n, total_s))
    return "\n".join(rows)


_STAMPED: set[Path] = set()


def stamp_judge_at_exit(judge: str, argv: list[str] | None = None) -> Path | None:
    """Name `judge` in the eval_info.json this lerobot-eval process writes (into its `--output_dir`) once it exits.
    A file older than this call (another run's) is left alone. Returns the path it will stamp, or None when the
    command line names no output folder (lerobot-eval then makes one up; the trial log still names the judge)."""
    from lerobot.configs.parser import parse_arg

    out = parse_arg("output_dir", sys.argv[1:] if argv is None else argv)
    if not out:
        return None
    path = Path(out) / "eval_info.json"
    if path in _STAMPED:  # every per-object env closes the one session
        return path
    _STAMPED.add(path)
    # What is there now is another run's. Compared by identity, not by time: the kernel stamps files from a coarse
    # clock that may lag time.time() by a tick, so a file written right after this call can look older than it.
    before = _identity(path)

    def stamp() -> None:
        try:
            if path.is_file() and _identity(path) != before:
                info = json.loads(path.read_text())
                durable.atomic_write_json(path, {"judge": judge, **info}, indent=2)
        except (OSError, ValueError):
            pass  # the record stays as lerobot-eval wrote it; the trial log names the judge

    atexit.register(stamp)
    return path


def _identity(path: Path) -> tuple[int, int, int] | None:
    try:
        st = path.stat()
    except OSError:
        return None
    return st.st_ino, st.st_mtime_ns, st.st_size


def judged_by(eval_info: dict, trial_log: Path | None) -> str:
    if eval_info.get("judge"):
        return str(eval_info["judge"])
    if trial_log is not None and trial_log.is_file():
        rows = [json.loads(x) for x in trial_log.read_text().splitlines() if x.strip()]
        names = sorted({str(r.get("decided_by")) for r in rows})
        if names:
            return "; ".join(names) + f" (from {trial_log.name})"
    return "not recorded (an eval_info.json without 'judge': pass --trial_log=<the run's --env.trial_log>)"


@dataclass
class RealReportConfig:
    # lerobot-eval's eval_info.json of a `--env.type=blindgrasp_real` run, or the folder that holds it
    eval_info: Path
    # The run's --env.trial_log, when its eval_info.json does not name the judge
    trial_log: Path | None = None


def load_eval_info(path: Path) -> dict:
    path = Path(path)
    if path.is_dir():
        path = path / "eval_info.json"
    if not path.is_file():
        raise SystemExit(f"error: {path} does not exist (lerobot-eval writes it into its --output_dir)")
    try:
        return json.loads(path.read_text())
    except (UnicodeDecodeError, json.JSONDecodeError) as e:
        raise SystemExit(f"error: {path} is not JSON: {e}") from None


def main(argv: list[str] | None = None) -> None:
    args = list(sys.argv[1:] if argv is None else argv)
    if len(args) == 1 and not args[0].startswith("-"):
        typed = USAGE.replace("outputs/eval/<run>/eval_info.json", args[0])
        raise SystemExit(f"error: named flags only; type\n    {typed}")
    cfg = parse_config(RealReportConfig, args)
    info = load_eval_info(cfg.eval_info)
    try:
        table = success_table(info)
    except ValueError as e:
        raise SystemExit(f"error: {cfg.eval_info}: {e}") from None
    print(f"Judged by: {judged_by(info, cfg.trial_log)}\n")
    print(table)


if __name__ == "__main__":
    main()
