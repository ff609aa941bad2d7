"""`blindgrasp-bench --bench.type={sim,teacher,demos,policy,student}`: benchmarks that print one table per run (JSON
with --bench.json=true).

    blindgrasp-bench --bench.type=sim --bench.num_envs=1026 --bench.threads=[1,2]
    blindgrasp-bench --bench.type=teacher --bench.preset=cpu --bench.iterations=6 --bench.json=true

`--bench.type` picks the benchmark (as `--policy.type` picks a LeRobot policy); `--bench.*` are that benchmark's
options (`--bench.type=sim --help` lists them). Each lives in its own module (`bench/sim.py`, `bench/teacher.py`,
`bench/demos.py`, `bench/policy.py`, `bench/student.py`) that registers its `BenchConfig` subclass under its name and
has `run(cfg) -> dict`.
"""

from __future__ import annotations

import importlib
import json
from dataclasses import dataclass

import draccus

from lerobot_blindgrasp.cli import parse_config, sleeping_openmp_threads

BENCHMARKS = ("sim", "teacher", "demos", "policy", "student")


@dataclass
class BenchConfig(draccus.ChoiceRegistry):
    """What every benchmark takes."""

    json: bool = False  # print machine-readable JSON instead of a table


@dataclass
class BenchCommand:
    bench: BenchConfig  # --bench.type: sim, teacher, demos, policy or student


def main(argv=None) -> None:
    # The benchmarks time torch as training runs it, with idle OpenMP threads asleep.
    sleeping_openmp_threads(restart=argv is None)
    for name in BENCHMARKS:  # each registers its --bench.type
        importlib.import_module(f"lerobot_blindgrasp.bench.{name}")
    cfg = parse_config(BenchCommand, argv).bench
    result = importlib.import_module(type(cfg).__module__).run(cfg)
    if cfg.json:
        print(json.dumps(result, indent=2))
