"""The suite's stand-in for a CPU family that no record holds: the tests whose outcome depends on where floats were
made run again, in one fresh process, as such a machine.

Each variable plays part of another CPU (docs/results/cpu_portability.md measures what each moves, on AMD and on
Intel): a model name no record holds, so no bit-for-bit record applies; `ATEN_CPU_CAPABILITY=default`, torch's
kernels without AVX2/AVX-512, which moves the teacher's matrix products on any x86 CPU that has them; and
`MKL_CBWR=SSE4_2`, MKL's SSE4.2 path, which moves every product on Intel and single-row ones on AMD. The module:
the golden simulation (its floats within tolerance, and its two real changes, a reward weight one ulp off and a
flipped success, still caught). The slow single-episode outcomes (tests/policies/test_shipped_student.py, test_wheel.py)
are not re-run here: their outcomes under these variables are measured in cpu_portability.md, and the whole suite
runs under them as that page says."""

from __future__ import annotations

import json
import os
import re
import subprocess
import sys
from pathlib import Path

import float_platform

ROOT = Path(__file__).resolve().parents[2]
NEWCOMER = "Newcomer CPU 9000 (no record holds it)"
UNSEEN = {float_platform.CPU_MODEL_ENV: NEWCOMER, "ATEN_CPU_CAPABILITY": "default", "MKL_CBWR": "SSE4_2"}
TESTS = ("tests/sim/test_sim_golden.py",)


def test_the_float_dependent_tests_pass_on_a_machine_no_record_has_seen_and_still_catch_real_changes(tmp_path):
    env = {**os.environ, **UNSEEN, "GOLDEN_REPORT": str(tmp_path / "matching.json")}
    r = subprocess.run(
        [sys.executable, "-m", "pytest", "-q", "-p", "no:cacheprovider", *TESTS],
        env=env,
        capture_output=True,
        text=True,
        timeout=600,
        cwd=ROOT,
    )
    assert r.returncode == 0, r.stdout[-4000:] + r.stderr[-2000:]
    assert re.search(r"^\d+ passed in ", r.stdout, re.M), r.stdout[-2000:]  # none skipped, none deselected
    # Its floats are another family's: it reproduces no recorded platform's digests.
    assert json.loads((tmp_path / "matching.json").read_text()) == []
