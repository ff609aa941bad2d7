"""The twin's parts and records, without a host: the servo registers' signs against the sim's physics, the position
gate's allowance for a grasp that pushes a finger back, the measurement's report, the judge in lerobot-eval's
eval_info.json, and the overload limit that the shipped yaml, the robot's defaults and the docs state.
"""

from __future__ import annotations

import json
import re
import subprocess
import sys
from dataclasses import fields
from pathlib import Path

import numpy as np
import pytest
import yaml

from lerobot_blindgrasp import spec
from lerobot_blindgrasp.hardware.xm430 import RAD_PER_TICK

ROOT = Path(__file__).resolve().parents[2]


# --- the twin's servo registers against the sim ------------------------------------------------------------------
def test_present_velocity_and_current_have_the_sims_signs_once_calibrated():
    """After calibration (Drive_Mode = 1 where a servo is mounted reversed) a joint opening in the sim (q rising,
    the actuator pushing it open) reads a positive Present_Velocity and Present_Current, closing a negative one."""
    from lerobot_blindgrasp.emulators import mount
    from lerobot_blindgrasp.emulators.dynamixel import EmulatedServo
    from lerobot_blindgrasp.twin.physics import TwinPhysics
    from lerobot_blindgrasp.twin.servo_link import SimShaft

    servos = [EmulatedServo(i, shaft=float(mount.shaft_for_q(0.0, k))) for k, i in enumerate(spec.SERVO_IDS)]
    for k, s in enumerate(servos):
        s.set("Drive_Mode", 1 if mount.MOUNT_SIGN[k] < 0 else 0)  # what lerobot-calibrate writes (test_twin.py)
    for direction in (+1.0, -1.0):
        p = TwinPhysics()  # joints at rest at q = 0, the object parked off the workspace
        p.command.enabled[:] = True
        p.command.goal_q[:] = p.q + direction * 0.3
        for _ in range(4):  # 20 ms: the joints are accelerating toward the goals
            p.substep()
        velocity, current = [], []
        for k, s in enumerate(servos):
            s._publish(SimShaft(p, k).advance(s, 0.005))
            velocity.append(s.get("Present_Velocity"))
            current.append(s.get("Present_Current"))
        moving = np.abs(p.qd) > 0.05  # a joint held by contact or its stop has no sign to compare
        assert moving.sum() >= 6
        np.testing.assert_array_equal(np.sign(velocity)[moving], np.sign(p.qd)[moving])
        np.testing.assert_array_equal(np.sign(current)[moving], np.sign(p.tau)[moving])
        assert (np.sign(p.qd)[moving] == direction).all()


# --- the position gate ----------------------------------------------------------------------------------------------
def test_the_position_gate_lets_a_load_push_a_torqued_joint_back_by_backdrive_ticks_and_no_further():
    from lerobot_blindgrasp.hardware.plausibility import ImplausibleReadingError, PositionGate

    backdrive = 0.3 / RAD_PER_TICK  # the robot's default plausibility_backdrive_rad
    gate = PositionGate(speed_ticks_s=1e6, margin_ticks=10, backdrive_ticks=backdrive, rereads=1)
    gate.estimate, gate.estimate_t = np.array([2000.0]), 0.0
    gate.goal = np.array([1900.0])  # closing: the goal lies below the estimate
    pushed_open = np.array([2000.0 + 10 + backdrive - 1])  # the grasp pushed it back, away from its goal
    assert gate.read(lambda: pushed_open, ["ff_j11"], free=False)[0] == pushed_open[0]
    # the accepted read re-stamped the estimate "now": put it back far in the past, so that the speed bound (which a
    # read a fraction of a millisecond later would trip first) leaves only the direction check to decide
    gate.estimate, gate.estimate_t = np.array([2000.0]), 0.0
    too_far = np.array([2000.0 + 10 + backdrive + 5])
    with pytest.raises(ImplausibleReadingError, match="moved away from both the estimate and the goal"):
        gate.read(lambda: too_far, ["ff_j11"], free=False)
    strict = PositionGate(speed_ticks_s=1e6, margin_ticks=10, backdrive_ticks=0.0, rereads=1)
    strict.estimate, strict.estimate_t, strict.goal = np.array([2000.0]), 0.0, np.array([1900.0])
    with pytest.raises(ImplausibleReadingError):  # without the allowance the same push is refused
        strict.read(lambda: pushed_open, ["ff_j11"], free=False)


# --- the measurement's report --------------------------------------------------------------------------------------
def _jsonl(path: Path, rows: list[dict]) -> None:
    path.write_text("".join(json.dumps(r) + "\n" for r in rows))


def test_the_twin_report_pairs_names_the_judge_and_counts_stops_timing_forces_and_load(tmp_path):
    from lab.twin_campaign import report

    judge = "twin (the sim's rule)"
    step = {"read": [10.0, 40.0, 50.0], "policy": [5.0, 15.0, 20.0], "write": [4.0, 20.0, 30.0]}
    _jsonl(tmp_path / "real_trials.jsonl", [
        {"object": "sphere_medium", "seed": 1000, "success": True, "decided_by": judge, "steps": 40,
         "peak_force_n": [5.0, 6.0, 30.0], "loop_overruns": 1, "late_steps_rebased": 0, "step_ms": step},
        {"object": "sphere_medium", "seed": 1002, "success": False, "decided_by": judge, "steps": 200,
         "peak_force_n": [1.0, 2.0, 3.0], "loop_overruns": 20, "late_steps_rebased": 4, "step_ms": step}])  # fmt: skip
    _jsonl(tmp_path / "stops.jsonl", [{"object": "sphere_medium", "seed": 1001,
                                       "error": "Fingertip force overload {'th_tip': 81.0} N > 80.0 N"}])  # fmt: skip
    _jsonl(tmp_path / "twin_trials.jsonl", [
        {"object": "sphere_medium", "seed": s, "peak_tip_force_n": f, "t_end": t}
        for s, f, t in ((1000, [5, 6, 31], 1010.0), (1001, [2, 3, 82], 1030.0), (1002, [1, 2, 3], 1050.0))])  # fmt: skip
    _jsonl(tmp_path / "load.jsonl", [{"t": 1000.0 + 10 * k, "load1": 1.0 if k < 3 else 9.0, "running": 2,
                                      "cpu_busy": 0.5} for k in range(7)])  # fmt: skip
    (tmp_path / "twin.log").write_text('twin final status {"behind_s": 0.0}\n')
    sim = tmp_path / "sim"
    sim.mkdir()
    (sim / "eval_info.json").write_text(json.dumps(
        {"per_task": [{"task_group": "sphere_medium", "task_id": 0, "metrics": {"successes": [True, True, True]}}]}))  # fmt: skip

    text = report.render(tmp_path, sim=sim)
    info = json.loads((tmp_path / "eval_info.json").read_text())
    assert info["judge"] == judge and info["per_task"][0]["metrics"]["successes"] == [True, False, False]
    assert f"Judged by: {judge}" in text
    assert "| sphere_medium | 33 % [6-79] (1/3) | 1 |" in text
    assert '"fingertip force over overload_n": 1' in text
    assert "exact McNemar p = 0.5" in (tmp_path / "compare.md").read_text()
    assert "| sphere_medium | 16.5 / 30.0 | 31.0 / 82.0 (th_tip) |" in text  # host vs the twin's truth
    assert '"overruns": 21' in text and '"p50_ms": 10.0' in text
    assert "trials at load 0-2: 1 trials, 1 overruns in 40 periods" in text
    assert "trials at load 4-8: 1 trials, 20 overruns in 200 periods" in text


def test_lerobot_evals_eval_info_names_the_judge_when_the_output_dir_is_given(tmp_path):
    """stamp_judge_at_exit runs when the process exits, after lerobot-eval has written its file."""
    code = ("import json, sys; from pathlib import Path; from lerobot_blindgrasp.envs import real_report; "
            f"real_report.stamp_judge_at_exit('operator', ['--output_dir={tmp_path}']); "
            f"Path('{tmp_path}/eval_info.json').write_text(json.dumps({{'per_task': []}}))")  # fmt: skip
    subprocess.run([sys.executable, "-c", code], check=True, cwd=ROOT, timeout=120)
    assert json.loads((tmp_path / "eval_info.json").read_text()) == {"judge": "operator", "per_task": []}


def test_another_runs_eval_info_is_left_as_it_was(tmp_path):
    """A file that is there when the envs close and that this run does not rewrite is another run's: no judge."""
    (tmp_path / "eval_info.json").write_text('{"per_task": []}')
    code = ("from lerobot_blindgrasp.envs import real_report; "
            f"real_report.stamp_judge_at_exit('operator', ['--output_dir={tmp_path}'])")  # fmt: skip
    subprocess.run([sys.executable, "-c", code], check=True, cwd=ROOT, timeout=120)
    assert (tmp_path / "eval_info.json").read_text() == '{"per_task": []}'


# --- the overload limit: one number in the yaml, the robot's defaults and the docs ---------------------------------
SITE_SPECIFIC = {"type", "id", "port", "force_sensor.port"}  # what a lab sets for its own gripper


def _flat(d: dict, prefix: str = "") -> dict:
    out = {}
    for k, v in d.items():
        out.update(_flat(v, f"{prefix}{k}.") if isinstance(v, dict) else {f"{prefix}{k}": v})
    return out


def test_the_shipped_yaml_states_the_robots_defaults():
    from lerobot_blindgrasp.robots.blindgrasp_gripper import BlindgraspGripperConfig

    shipped = _flat(yaml.safe_load((ROOT / "robot_configs" / "blindgrasp_gripper.yaml").read_text()))
    default = BlindgraspGripperConfig()
    for key, value in shipped.items():
        if key in SITE_SPECIFIC:
            continue
        want = default
        for part in key.split("."):
            want = getattr(want, part)
        assert np.allclose(value, want) if not isinstance(value, str) else value == want, (key, value, want)
    assert "force_sensor.overload_n" in shipped
    assert {f.name for f in fields(default.force_sensor)} >= {k.split(".")[1] for k in shipped if "." in k}


def test_the_docs_state_the_robots_overload_limit():
    from lerobot_blindgrasp.robots.blindgrasp_gripper import ForceSensorConfig

    limit = ForceSensorConfig().overload_n
    for doc in ("docs/force_board.md", "docs/hardware.md", "docs/results/twin.md"):
        text = (ROOT / doc).read_text()
        stated = {float(n) for n in re.findall(r"(\d+(?:\.\d+)?) N overload stop", text)}
        assert stated == {limit}, f"{doc} states the overload stop as {stated}, the robot's default is {limit} N"


def test_the_measurement_keeps_the_robots_defaults_unless_told_and_resumes_from_its_records(tmp_path):
    from lab.twin_campaign.measure import TwinMeasureConfig, done_seeds, last_error

    assert TwinMeasureConfig(output_dir=tmp_path).robot_flags() == []  # the shipped defaults
    assert TwinMeasureConfig(output_dir=tmp_path, overload_n=40.0, current_limit_a=1.15).robot_flags() == [
        "--env.robot.force_sensor.overload_n=40.0", "--env.robot.current_limit_a=1.15"]  # fmt: skip
    _jsonl(
        tmp_path / "real_trials.jsonl", [{"object": "sphere_small", "seed": 1000}, {"object": "x", "seed": 1000}]
    )
    _jsonl(tmp_path / "stops.jsonl", [{"object": "sphere_small", "seed": 1001, "error": "..."}])
    assert done_seeds(tmp_path, "sphere_small") == {1000, 1001}  # the next lerobot-eval starts at seed 1002
    log = tmp_path / "run.log"
    log.write_text(
        "INFO fine\nTraceback\nForceOverloadError: Fingertip force overload {'th_tip': 81.0} N > 80.0 N\n"
    )
    assert last_error(log) == "Fingertip force overload {'th_tip': 81.0} N > 80.0 N"
    assert last_error(tmp_path / "missing.log") == "no error line"
