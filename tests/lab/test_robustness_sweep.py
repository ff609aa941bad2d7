"""python -m lab.robustness.sweep end to end at the smoke preset (the real shipped student and teacher, real lerobot
loaders), its resumption, and the envelope and connect-check functions on known numbers."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

from lab.robustness import envelope
from lerobot_blindgrasp.hardware import force

REPO = Path(__file__).resolve().parents[2]


def test_smoke_sweep_end_to_end_then_a_rerun_skips_every_point(tmp_path):
    out = tmp_path / "rob"
    env = {**os.environ, "PYTHONPATH": str(REPO), "MUJOCO_GL": "egl", "HF_HUB_OFFLINE": "1"}
    cmd = [
        sys.executable,
        "-m",
        "lab.robustness.sweep",
        "--preset=smoke",
        f"--output_dir={out}",
        "--threads=1",
        "--progress=false",
    ]
    r = subprocess.run(cmd, cwd=REPO, env=env, capture_output=True, text=True, timeout=600)
    assert r.returncode == 0, r.stderr[-2000:]
    assert "## Robustness envelope" in r.stdout
    summary = json.loads((out / "summary.json").read_text())
    assert [f["name"] for f in summary["factors"]] == ["obs_latency", "force_gain", "torque_limit"]
    for f in summary["factors"]:
        assert (out / "plots" / f"{f['name']}.png").stat().st_size > 5000
        for p in f["points"]:
            assert p["student"][1] == p["teacher"][1] == 2  # 1 episode x 2 objects, both policies
            pr = p["paired"]
            assert pr["both"] + pr["a_only"] + pr["b_only"] + pr["neither"] == 2
    # The nominal point is shared by the three factors: one simulation, four points in all.
    points = sorted((out / "points").glob("*.json"))
    assert len(points) == 4
    assert "force sensor gain error" in (out / "summary.md").read_text()
    assert "| factor | trained on |" in (out / "envelope.md").read_text()

    before = {p: p.stat().st_mtime_ns for p in points}
    r = subprocess.run(cmd, cwd=REPO, env=env, capture_output=True, text=True, timeout=600)
    assert r.returncode == 0, r.stderr[-2000:]
    assert "continuing: 4 of 4 points" in r.stdout
    assert {p: p.stat().st_mtime_ns for p in points} == before


def _factor(rates_student, nominal, teacher=None, name="f"):
    pts = [
        {"label": f"m{i}", "in_training": i == nominal, "student": [k, 100]} for i, k in enumerate(rates_student)
    ]
    for p, k in zip(pts, teacher or [], strict=False):
        p["teacher"] = [k, 100]
    return {"name": name, "title": name, "unit": "", "nominal": nominal, "train_range": None, "points": pts}


def test_envelope_grows_from_nominal_and_stops_at_the_first_failure():
    f = _factor([70, 95, 92, 88, 95], nominal=1)
    assert envelope.envelope(f["points"], 1, criterion="rate") == (1, 2)
    # 88/100: Wilson upper 93 % still reaches 90 %; 70/100 does not.
    assert envelope.envelope(f["points"], 1, criterion="ci") == (1, 4)
    assert envelope.describe_envelope(f, criterion="rate") == "m1 (fails at m0) to m2 (fails at m3)"
    # passing out to both ends: the edges name the smallest and the largest point tested
    assert envelope.describe_envelope(_factor([95, 95, 95], nominal=1), criterion="rate") == (
        "m0 (smallest tested) to m2 (largest tested)"
    )
    assert envelope.envelope(_factor([80, 99], 0)["points"], 0, criterion="rate") == (None, None)
    summary = {
        "objects": ["a"] * 18,
        "episodes_per_object": 10,
        "seed": 1000,
        "command": "x",
        "factors": [_factor([95, 80, 60], 0, [99, 99, 99], "gain"), _factor([95, 94, 50], 0, name="lag")],
    }
    text = envelope.card_section(summary)
    assert "| gain | m0 |" in text and "gain at m1" in text
    assert envelope.first_to_break(summary)[0][:2] == ("gain", "m1")  # one step out, before lag's two


def test_connect_check_warns_only_beyond_the_tolerated_force_bias():
    tol = force.FORCE_BIAS_TOLERANCE_N
    assert force.force_bias_warning([0.0, 0.5 * tol, -tol]) is None
    msg = force.force_bias_warning([0.0, -(tol + 0.5), 0.0])
    assert "mf_tip" in msg and "re-tare" in msg
    with pytest.raises(ValueError):
        envelope.passes(1, 2, criterion="median")
