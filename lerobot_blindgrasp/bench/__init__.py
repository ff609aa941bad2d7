"""`blindgrasp-bench {sim,teacher,demos,policy,student}`: benchmarks that print one table per run (JSON with --json=true).

    blindgrasp-bench sim --num_envs=1026 --threads=[1,2]
    blindgrasp-bench teacher --preset=cpu --iterations=6 --json=true

The first argument picks the benchmark; the rest is that benchmark's draccus config. Each lives in its own module
(`bench/sim.py`, `bench/teacher.py`, `bench/demos.py`, `bench/policy.py`, `bench/student.py`) exposing `CONFIG` (a `BenchConfig`
subclass) and `run(cfg) -> dict`; only the chosen one is imported.
"""

from __future__ import annotations

import importlib
import json
import sys
from dataclasses import dataclass

from lerobot_blindgrasp.cli import parse_config

SUBCOMMANDS = ("sim", "teacher", "demos", "policy", "student")


@dataclass
class BenchConfig:
    """What every benchmark takes."""

    json: bool = False  # print machine-readable JSON instead of a table


def main(argv=None) -> None:
    argv = list(sys.argv[1:] if argv is None else argv)
    usage = f"usage: blindgrasp-bench {{{','.join(SUBCOMMANDS)}}} [--json=true] [options]  (NAME --help: options)"
    if argv and argv[0] in ("-h", "--help"):
        print(usage)
        print(__doc__)
        return
    if not argv or argv[0] not in SUBCOMMANDS:
        print(usage, file=sys.stderr)
        raise SystemExit(2)
    what = argv.pop(0)
    mod = importlib.import_module(f"lerobot_blindgrasp.bench.{what}")
    cfg = parse_config(mod.CONFIG, argv)
    result = mod.run(cfg)
    if cfg.json:
        print(json.dumps(result, indent=2))
