"""Per-object success table of a real-gripper evaluation, from lerobot-eval's `eval_info.json`.

    python -m lerobot_blindgrasp.envs.real_report outputs/eval/<run>/eval_info.json

`--env.type=blindgrasp_real` makes each object its own task group, so `per_group[<object>]` holds its trials.
"""

from __future__ import annotations

import json
import sys
from pathlib import Path


def success_table(eval_info: dict) -> str:
    rows = ["| object | trials | successes | success rate |", "|---|---:|---:|---:|"]
    total_n = total_s = 0
    for task in eval_info["per_task"]:
        successes = [bool(s) for s in task["metrics"]["successes"]]
        n, s = len(successes), sum(successes)
        total_n, total_s = total_n + n, total_s + s
        rows.append(f"| {task['task_group']} | {n} | {s} | {100.0 * s / max(n, 1):.1f} % |")
    rows.append(f"| **overall** | {total_n} | {total_s} | {100.0 * total_s / max(total_n, 1):.1f} % |")
    return "\n".join(rows)


def main(argv: list[str] | None = None) -> None:
    args = sys.argv[1:] if argv is None else argv
    if len(args) != 1:
        raise SystemExit("usage: python -m lerobot_blindgrasp.envs.real_report <eval_info.json>")
    print(success_table(json.loads(Path(args[0]).read_text())))


if __name__ == "__main__":
    main()
