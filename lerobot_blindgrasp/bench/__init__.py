"""`blindgrasp-bench {sim,demos,policy}`: benchmarks that print one table per run (and JSON with --json).

Each subcommand lives in its own module (`bench/sim.py`, `bench/demos.py`, `bench/policy.py`) exposing
`add_arguments(parser)` and `run(args) -> dict`.
"""

from __future__ import annotations

import argparse
import importlib
import json

SUBCOMMANDS = ("sim", "demos", "policy")


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(prog="blindgrasp-bench", description=__doc__)
    sub = parser.add_subparsers(dest="what", required=True)
    modules = {}
    for name in SUBCOMMANDS:
        mod = importlib.import_module(f"lerobot_blindgrasp.bench.{name}")
        modules[name] = mod
        p = sub.add_parser(name, help=(mod.__doc__ or "").strip().splitlines()[0])
        p.add_argument("--json", action="store_true", help="print machine-readable JSON instead of a table")
        mod.add_arguments(p)
    args = parser.parse_args(argv)
    result = modules[args.what].run(args)
    if args.json:
        print(json.dumps(result, indent=2))
