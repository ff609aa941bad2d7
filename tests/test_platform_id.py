"""Recorded comparisons say which machine made them (lerobot_blindgrasp.platform_id): the CPU family, overridable
for tests, and what else moves the last bits of a float."""

from __future__ import annotations

import json
from pathlib import Path

from lerobot_blindgrasp import platform_id
from lerobot_blindgrasp.teacher import evaluate
from lerobot_blindgrasp.teacher.policy import TeacherPolicy, default_teacher

ROOT = Path(__file__).resolve().parents[1]


def test_the_cpu_model_can_be_played_and_float_paths_count_as_another_platform(monkeypatch):
    for name in (*platform_id.FLOAT_ENV, platform_id.CPU_MODEL_ENV):  # this machine as itself, whatever plays it
        monkeypatch.delenv(name, raising=False)
    here = platform_id.platform()
    assert here["cpu"] and set(here["versions"]) == {"mujoco", "torch", "numpy"}
    assert set(here["isa"]) <= set(platform_id.FLOAT_ISA) and here["env"] == {}
    assert platform_id.same(here, json.loads(json.dumps(here)))  # survives a record's round trip
    monkeypatch.setenv(platform_id.CPU_MODEL_ENV, "Newcomer CPU 9000")
    newcomer = platform_id.platform()
    assert newcomer["cpu"] == "Newcomer CPU 9000" and not platform_id.same(here, newcomer)
    monkeypatch.delenv(platform_id.CPU_MODEL_ENV)
    monkeypatch.setenv("MKL_CBWR", "SSE4_2")  # a float-path variable: on some CPUs it moves MKL's products
    other = platform_id.platform()
    assert other["env"] == {"MKL_CBWR": "SSE4_2"} and not platform_id.same(here, other)
    assert "MKL_CBWR=SSE4_2" in platform_id.describe(other)
    # Two CPUs that report one model name (two EPYC generations) still read apart, by their instruction sets: the
    # other one is built from this machine's, with AVX-512 toggled, so the check holds with or without it here.
    toggled = sorted(set(here["isa"]) ^ {"avx512f"})
    assert not platform_id.same(here, {**here, "isa": toggled})
    with_512 = {**here, "isa": ["avx", "avx2", "avx512f", "fma", "sse4_2"]}
    without_512 = {**here, "isa": ["avx", "avx2", "fma", "sse4_2"]}
    assert not platform_id.same(with_512, without_512)
    assert "[AVX-512]" in platform_id.describe(with_512) and "[AVX2]" in platform_id.describe(without_512)
    assert "[NEON]" in platform_id.describe({**here, "isa": ["asimd"]})  # an ARM board
    assert not platform_id.same(None, here) and platform_id.describe(None) == "an unrecorded machine"


def test_a_teacher_eval_records_the_platform_it_ran_on(monkeypatch):
    monkeypatch.setenv(platform_id.CPU_MODEL_ENV, "Newcomer CPU 9000")
    res = evaluate.evaluate_teacher(
        TeacherPolicy(default_teacher()), ("cuboid_b_large",), 1, modes=("deterministic",), progress=False
    )
    assert res["platform"] == platform_id.platform() and res["platform"]["cpu"] == "Newcomer CPU 9000"


def test_the_shipped_teachers_carried_evals_say_where_they_were_made():
    """The main job reuses a carried eval only on its platform (tests/test_pipeline.py), so each must name one."""
    for path in sorted((ROOT / "models").glob("*/eval/eval.json")):
        p = json.loads(path.read_text()).get("platform")
        assert p and p["cpu"] and p["versions"]["mujoco"] == "4.0.0", path
