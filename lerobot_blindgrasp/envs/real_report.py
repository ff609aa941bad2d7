"""Per-object success table of a real-gripper evaluation, from lerobot-eval's `eval_info.json`.

    python -m lerobot_blindgrasp.envs.real_report --eval_info=outputs/eval/<run>/eval_info.json

`--eval_info` also takes the run's folder (lerobot-eval's `--output_dir`). Named flags only, as every command of the
package (`lerobot_blindgrasp/cli.py`); a bare path is answered with the command to type.

`--env.type=blindgrasp_real` makes each object its own task group, so `per_task[i].task_group` names the object of
each task's trials. Each rate comes with its 95 % Wilson interval (10 trials per object is the paper's protocol;
the interval says how little that pins down).
"""

from __future__ import annotations

import json
import sys
from dataclasses import dataclass
from pathlib import Path

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


@dataclass
class RealReportConfig:
    # lerobot-eval's eval_info.json of a `--env.type=blindgrasp_real` run, or the folder that holds it
    eval_info: Path


def load(path: Path) -> dict:
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
    try:
        print(success_table(load(cfg.eval_info)))
    except ValueError as e:
        raise SystemExit(f"error: {cfg.eval_info}: {e}") from None


if __name__ == "__main__":
    main()
