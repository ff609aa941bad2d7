"""`python -m lab.bench --bench.type={sim,teacher,demos,policy,student,paper,build,onemodel}`: benchmarks that
print one table per run (JSON with --bench.json=true).

    python -m lab.bench --bench.type=sim --bench.num_envs=1026 --bench.threads=[1,2]
    python -m lab.bench --bench.type=teacher --bench.preset=cpu --bench.iterations=6 --bench.json=true

`--bench.type` picks the benchmark (as `--policy.type` picks a LeRobot policy); `--bench.*` are that benchmark's
options (`--bench.type=sim --help` lists them). Each lives in its own module (`sim_bench.py`, `teacher_bench.py`,
`demos_bench.py`, `policy_bench.py`, `student_bench.py`, `paper_bench.py`, `build_bench.py`, `onemodel_bench.py`)
that registers its `BenchConfig` subclass under its name and has `run(cfg) -> dict`.
"""

from __future__ import annotations

import importlib
import json
import sys
from dataclasses import dataclass

import draccus

from lerobot_blindgrasp.cli import parse_config, sleeping_openmp_threads

BENCHMARKS = ("sim", "teacher", "demos", "policy", "student", "paper", "build", "onemodel")


@dataclass
class BenchConfig(draccus.ChoiceRegistry):
    """What every benchmark takes."""

    json: bool = False  # print machine-readable JSON instead of a table


@dataclass
class BenchCommand:
    bench: BenchConfig  # --bench.type: sim, teacher, demos, policy, student, paper, build or onemodel


def _modules(argv: list[str]) -> tuple[str, ...]:
    """The benchmark named by --bench.type, else all (for --help and the parser's error): each imports only what it
    times, so the student bench runs where MuJoCo is not installed."""
    for arg, following in zip(argv, [*argv[1:], ""], strict=True):
        name = (
            arg.split("=", 1)[1] if arg.startswith("--bench.type=") else following if arg == "--bench.type" else ""
        )
        if name in BENCHMARKS:
            return (name,)
    return BENCHMARKS


def main(argv=None) -> None:
    # The benchmarks time torch as training runs it, with idle OpenMP threads asleep.
    sleeping_openmp_threads(restart=argv is None)
    for name in _modules(sys.argv[1:] if argv is None else list(argv)):  # each registers its --bench.type
        importlib.import_module(f"lab.bench.{name}_bench")
    cfg = parse_config(BenchCommand, argv).bench
    result = importlib.import_module(type(cfg).__module__).run(cfg)
    if cfg.json:
        print(json.dumps(result, indent=2))
