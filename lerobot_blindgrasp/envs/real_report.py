"""Per-object success table of a real-gripper evaluation, from lerobot-eval's `eval_info.json`.

    python -m lerobot_blindgrasp.envs.real_report --eval_info=outputs/eval/<run>/eval_info.json

`--env.type=blindgrasp_real` makes each object its own task group, so `per_group[<object>]` holds its trials.
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path

from lerobot_blindgrasp.cli import parse_config


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


@dataclass
class RealReportConfig:
    eval_info: Path  # lerobot-eval's eval_info.json of a `--env.type=blindgrasp_real` run


def main(argv: list[str] | None = None) -> None:
    print(success_table(json.loads(parse_config(RealReportConfig, argv).eval_info.read_text())))


if __name__ == "__main__":
    main()
