"""The registers that protect the gripper when no host is running (docs/hardware.md, "Protection with no host"):
each, found changed in a servo's EEPROM, is restored at connect and named; one that does not keep its value refuses
the connect with the torque off."""

from __future__ import annotations

import logging

import pytest
from test_hw_hazards_servo import _connect
from test_hw_health import _stopped

from lerobot_blindgrasp.hardware import xm430
from lerobot_blindgrasp.robots.blindgrasp_gripper import BlindgraspGripper
from lerobot_blindgrasp.robots.blindgrasp_gripper.errors import GripperProtectionError

# One servo per register, each set to a value a tool could leave: weaker (or, for PWM_Limit, a weaker finger).
WRONG = {
    "ff_j10": ("Shutdown", 0x20),  # only overload drops the torque: an overheating servo would run on
    "ff_j11": ("Temperature_Limit", 99),  # the overheating error 19 degC later
    "ff_j12": ("Max_Voltage_Limit", 150),
    "mf_j20": ("Min_Voltage_Limit", 60),  # a sag to 6 V would never be flagged
    "mf_j21": ("PWM_Limit", 300),
    "mf_j22": ("Current_Limit", 1193),  # 3.2 A: more than the configured 2.3 A stall current
}


def test_every_no_host_protection_register_is_restored_and_named(rig, tmp_path, monkeypatch, caplog):
    for joint, (reg, value) in WRONG.items():
        rig.servo(joint).set(reg, value)
    with caplog.at_level(logging.WARNING):
        robot = _connect(rig, tmp_path, monkeypatch)
    robot.disconnect()
    want = {**xm430.NO_HOST_PROTECTION, "Current_Limit": xm430.amps_to_current_units(robot.config.current_limit_a)}
    assert set(want) == {reg for reg, _ in WRONG.values()}  # the test covers every register of the list
    for joint, (reg, value) in WRONG.items():
        assert rig.servo(joint).get(reg) == want[reg]
        assert f"{joint} {reg} {value} -> {want[reg]}" in caplog.text


def test_a_register_that_does_not_keep_its_value_refuses_the_connect(rig, tmp_path, monkeypatch):
    """A worn EEPROM cell acknowledges the write and keeps Temperature_Limit at 99 degC."""
    servo = rig.servo("th_j32")
    servo.set("Temperature_Limit", 99)
    servo.unwritable.add("Temperature_Limit")
    monkeypatch.setattr("builtins.input", rig.calibration_inputs())
    robot = BlindgraspGripper(rig.robot_config(tmp_path / "cal"))
    with pytest.raises(GripperProtectionError, match=r"th_j32 \(ID 32\) Temperature_Limit = 99 \(configured 80\)"):
        robot.connect()
    assert _stopped(rig, robot)
