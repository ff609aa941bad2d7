"""`blindgrasp-bench {sim,teacher,demos,policy}`: benchmarks that print one table per run (and JSON with --json).

Each subcommand lives in its own module (`bench/sim.py`, `bench/teacher.py`, `bench/demos.py`, `bench/policy.py`) exposing
`add_arguments(parser)` and `run(args) -> dict`; only the chosen one is imported.
"""

from __future__ import annotations

import argparse
import importlib
import json
import sys

SUBCOMMANDS = ("sim", "teacher", "demos", "policy")


def main(argv=None) -> None:
    argv = list(sys.argv[1:] if argv is None else argv)
    if not argv or argv[0] not in SUBCOMMANDS:
        print(f"usage: blindgrasp-bench {{{','.join(SUBCOMMANDS)}}} [--json] [options]", file=sys.stderr)
        raise SystemExit(2)
    what = argv.pop(0)
    mod = importlib.import_module(f"lerobot_blindgrasp.bench.{what}")
    parser = argparse.ArgumentParser(prog=f"blindgrasp-bench {what}", description=mod.__doc__)
    parser.add_argument("--json", action="store_true", help="print machine-readable JSON instead of a table")
    mod.add_arguments(parser)
    args = parser.parse_args(argv)
    result = mod.run(args)
    if args.json:
        print(json.dumps(result, indent=2))
