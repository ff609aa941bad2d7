"""Held-out faults: found by the hazard analysis (docs/hardware.md), named by no issue. One case each, against
the emulators or the checkpoint files themselves."""

from __future__ import annotations

import json
import logging

import pytest
from emulators.fixtures import rig, robot  # noqa: F401  (fixtures)
from test_policy_check import ROBOT, _checkpoint

from lerobot_blindgrasp.hardware import xm430
from lerobot_blindgrasp.robots.blindgrasp_gripper import BlindgraspGripper, policy_check
from lerobot_blindgrasp.robots.blindgrasp_gripper.errors import GripperHealthError, PolicyMismatchError
from lerobot_blindgrasp.robots.blindgrasp_gripper.health import ERROR, OK, WARN, ServoHealth

JOINTS = ["ff_j10"]


def _connect(rig, tmp_path, monkeypatch) -> BlindgraspGripper:
    monkeypatch.setattr("builtins.input", rig.calibration_inputs())
    robot = BlindgraspGripper(rig.robot_config(tmp_path / "cal"))
    robot.connect()
    return robot


def _block(temp=35, volts=12.0, current=0) -> dict:
    return {"ff_j10": {"Present_Temperature": temp, "Present_Input_Voltage": round(volts * 10),
                       "Present_Current": current & 0xFFFF}}  # fmt: skip


def test_a_cleared_shutdown_register_is_named_at_connect(rig, tmp_path, monkeypatch, caplog):
    """Shutdown(63) = 0 (a tool wrote it): the firmware would never drop the torque itself. Warned, by joint."""
    rig.servo("mf_j22").set("Shutdown", 0)
    with caplog.at_level(logging.WARNING):
        robot = _connect(rig, tmp_path, monkeypatch)
    robot.disconnect()
    assert "mf_j22: Shutdown(63) = 0x00 lacks overheating, electrical shock, overload" in caplog.text


def test_the_margins_follow_the_servos_own_temperature_limit(rig, tmp_path, monkeypatch):
    """Temperature_Limit lowered to 70 degC in EEPROM: the firmware stops at 70, so 63 degC must not start."""
    rig.servo("ff_j12").set("Temperature_Limit", 70)
    rig.servo("ff_j12").health.temperature_c = 63.0
    with pytest.raises(
        GripperHealthError, match=r"ff_j12 temperature 63 degC \(start needs < 62, Temperature_Limit 70"
    ):
        _connect(rig, tmp_path, monkeypatch)
    assert not rig.dxl.any_torque()


def test_an_over_voltage_supply_below_the_firmware_limit_is_refused(rig, tmp_path, monkeypatch):
    """15.2 V (a wrong power supply): over the XM430's 14.8 V rating, under the firmware's 16.0 V limit (no bit)."""
    rig.dxl.supply.open_v = 15.2
    with pytest.raises(GripperHealthError, match=r"input voltage 15.2 V \(start needs 10.8-14.8 V"):
        _connect(rig, tmp_path, monkeypatch)
    assert not any(s.get("Hardware_Error_Status") for s in rig.dxl.servos.values())


def test_a_negative_current_read_raw_is_a_stall_not_174_amps():
    """LeRobot's raw sync read returns Present_Current unsigned: -855 reads 64681. A reversed servo closing at its
    limit is a stall by magnitude; without the sign it would read 174 A, or pass unseen."""
    health = ServoHealth(JOINTS)
    first = health.assess(_block(current=-855), 855, now=0.0)
    later = health.assess(_block(current=-855), 855, now=xm430.STALL_STOP_S + 0.1)
    assert first[2].level == OK and first[2].value == pytest.approx(2.30, abs=0.01)
    assert later[2].level == ERROR and "stalled" in later[2].message


def test_a_brief_dip_under_the_rating_warns_but_does_not_stop():
    """All fingers starting at once dip the supply for a moment: only a sag held for 0.5 s stops."""
    health = ServoHealth(JOINTS)
    levels = [health.assess(_block(volts=9.8), 855, now=t)[1].level for t in (0.0, 0.2)]
    levels.append(health.assess(_block(volts=11.8), 855, now=0.3)[1].level)
    levels.append(health.assess(_block(volts=9.8), 855, now=0.6)[1].level)  # the hold starts again
    assert levels == [WARN, WARN, OK, WARN]


def test_one_degree_steps_of_a_steady_servo_are_no_trend():
    """Present_Temperature has 1 degC steps: a reading that flips 70 <-> 71 must not look like a rising trend."""
    health = ServoHealth(JOINTS)
    found = [health.assess(_block(temp=70 + (k % 2)), 0, now=0.25 * k)[0] for k in range(40)]
    assert {d.level for d in found} == {WARN}  # near the limit (>= 65), never an over-temperature ERROR


def test_normalizer_stats_fitted_on_another_state_are_refused(tmp_path):
    """config.json edited to 12 while the saved normalizer was fitted on a 10-d state: refused by the file."""
    ckpt = _checkpoint(tmp_path)
    pre = json.loads((ckpt / "policy_preprocessor.json").read_text())
    pre["steps"][-1]["config"]["features"]["observation.state"]["shape"] = [10]
    (ckpt / "policy_preprocessor.json").write_text(json.dumps(pre))
    bad, _ = policy_check.problems(ckpt, ROBOT)
    assert bad == [
        f"'observation.state' shape (10,) in {ckpt / 'policy_preprocessor.json'} (normalizer), the robot has (12,)"
    ]


def test_a_truncated_checkpoint_config_is_refused_before_anything_moves(tmp_path):
    ckpt = _checkpoint(tmp_path)
    (ckpt / "config.json").write_text((ckpt / "config.json").read_text()[:40])
    with pytest.raises(PolicyMismatchError, match=r"config.json is unreadable \(JSONDecodeError"):
        policy_check.check(ckpt, ROBOT)
