"""`blindgrasp-sim-viewer`: the scripted lift renders to a playable mp4 and reports what happened."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import imageio.v3 as iio
import pytest

from lerobot_blindgrasp.sim import objects
from lerobot_blindgrasp.sim.viewer import SimDemoConfig, run_demo

DEMO = Path(sys.executable).with_name("blindgrasp-sim-viewer")


@pytest.mark.slow
def test_demo_cli_writes_a_video_and_prints_the_summary(tmp_path):
    out = tmp_path / "demo.mp4"
    env = {**os.environ, "MUJOCO_GL": "egl", "HF_HUB_OFFLINE": "1"}
    args = ["--steps", "100", "--width", "160", "--height", "120", "--shadows=false", "--output", str(out)]
    res = subprocess.run([str(DEMO), *args], env=env, capture_output=True, text=True, timeout=120)
    assert res.returncode == 0, res.stderr
    assert "cylinder_a_medium" in res.stdout and "success       yes" in res.stdout, res.stdout
    assert f"video         {out}" in res.stdout
    frames = iio.imread(out, plugin="pyav")
    assert frames.shape == (101, 120, 160, 3)  # the reset frame plus one per step, at the requested size
    assert frames[0].std() > 10


@pytest.mark.parametrize("name", objects.PAPER_OBJECTS)
def test_scripted_lift_works_on_every_paper_object(name):
    # The open-loop pinch is not robust to every randomization draw (measured: capsule_large and cuboid_b_large
    # hold the lift on 3 of the 5 per-object evaluation draws 0-4), so it must hold on most of five draws.
    held = []
    for seed in range(5):
        s = run_demo(SimDemoConfig(name, seed=seed, steps=100, video=False))
        assert s["max_lift_m"] < 0.045, s  # lifted by about the scripted 3 cm, not thrown by a physics blow-up
        if s["success"] and 0.02 < s["final_lift_m"] < 0.04:
            # No reading near a physics blow-up. No lower bound: the sensor is axial, and a pinch that holds a large
            # cylinder on the side of the tips reads 0 N on all three (seen on draw 3 of cylinder_b_large).
            assert all(0.0 <= f < 30.0 for f in s["hold_force_n"]), s["hold_force_n"]
            held.append(seed)
    assert len(held) >= 3, f"{name}: held only on draws {held} of 0-4"


def test_demo_rejects_bad_options():
    with pytest.raises(ValueError, match="unknown object"):
        SimDemoConfig("teapot")
    with pytest.raises(ValueError, match="steps"):
        SimDemoConfig(steps=0)
