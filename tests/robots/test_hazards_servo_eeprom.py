"""Hazards of the XM430 control table's setup items, read at connect (docs/hardware.md, "Hazard analysis", table
"XM430-W350 control table": Firmware_Version, ID, Baud_Rate, Max/Min_Voltage_Limit, Current_Limit,
Max/Min_Position_Limit, Startup_Configuration, Status_Return_Level). Each fault as a lab meets it (a register a tool
changed, a servo set up twice, a bus at another rate) against the emulated bus, and the gripper's response: refused
before any torque, or stopped with the torque off, with the error that names it. The registers that protect the
gripper with no host are `test_hazards_no_host.py`."""

from __future__ import annotations

import logging

import numpy as np
import pytest
from emulators.harness import connect_gripper
from emulators.loop import hold, stopped

from lerobot_blindgrasp import spec
from lerobot_blindgrasp.hardware import xm430
from lerobot_blindgrasp.robots.blindgrasp_gripper import BlindgraspGripper, BlindgraspGripperConfig
from lerobot_blindgrasp.robots.blindgrasp_gripper.errors import (
    GripperBusError,
    GripperFirmwareError,
    GripperHardwareError,
    GripperSafetyStop,
    GripperStateError,
)


def _refused(rig, tmp_path, monkeypatch, error, match: str) -> None:
    monkeypatch.setattr("builtins.input", rig.calibration_inputs())
    robot = BlindgraspGripper(rig.robot_config(tmp_path / "cal"))
    with pytest.raises(error, match=match):
        robot.connect()
    assert stopped(rig, robot)
    assert all(s.get("Operating_Mode") == 3 for s in rig.dxl.servos.values())  # nothing was configured


def test_firmware_older_than_the_watchdog_is_refused(rig, tmp_path, monkeypatch):
    """Bus_Watchdog(98) and Drive_Mode(10) are "available from firmware v38" (e-Manual)."""
    rig.servo("th_j31").set("Firmware_Version", 37)
    _refused(rig, tmp_path, monkeypatch, GripperFirmwareError, r"\{'th_j31 \(ID 31\)': 37\} is older than v38")


def test_two_servos_on_one_id_are_refused_before_any_torque(rig, tmp_path, monkeypatch):
    """A tenth servo set to ID 10 (set up twice): both answer every read at once. Identical replies (model number,
    EEPROM) survive the collision; the first that differ (their positions) fail the CRC on every try."""
    rig.dxl.add_twin(10, shaft=3000.0)
    _refused(rig, tmp_path, monkeypatch, GripperBusError, r"Failed to sync read")


def test_a_bus_at_another_baud_rate_is_refused_naming_the_register(rig, tmp_path, monkeypatch):
    """Servos still at the factory 57 600 bps (Baud_Rate(8) = 1) on a 1 Mbps host: none answers."""
    for servo in rig.dxl.servos.values():
        servo.set("Baud_Rate", 1)
    _refused(rig, tmp_path, monkeypatch, GripperBusError, r"missing IDs \[10, 11, 12, 20.*Baud_Rate register")


def test_the_firmware_voltage_flag_stops_the_gripper(rig, tmp_path, monkeypatch):
    """Under Min_Voltage_Limit(34) (9.5 V; a value a tool left is restored at connect) the firmware flags input
    voltage (0x01) and, the bit not being in Shutdown(63), keeps the torque on. The flag stops the gripper at the
    next period, before the host's own rule (under the 10 V rating for 0.5 s) would."""
    rig.servo("ff_j12").set("Min_Voltage_Limit", 110)
    robot = connect_gripper(rig, tmp_path, monkeypatch)
    assert rig.servo("ff_j12").get("Min_Voltage_Limit") == 95
    rig.dxl.supply.open_v = 9.3
    with pytest.raises(GripperHardwareError, match=r"ff_j\d\d \(ID \d\d\): input voltage"):
        hold(robot, 4)
    assert stopped(rig, robot)


def test_a_current_limit_outside_the_register_range_is_refused():
    """Current_Limit(38) takes 0..1193 units of 2.69 mA (3.21 A): the config accepts exactly that range."""
    top = xm430.CURRENT_LIMIT_MAX_UNITS * xm430.CURRENT_UNIT_A
    BlindgraspGripperConfig(current_limit_a=top)  # 1193 units
    for amps in (top + 0.003, 4.0, 0.0, -1.0):  # 1194 units and beyond; no current at all
        with pytest.raises(ValueError, match=r"current_limit_a must be in \(0, 3.21\] A"):
            BlindgraspGripperConfig(current_limit_a=amps)


def test_position_mode_refuses_to_hold_a_pose_outside_the_limits(rig, robot, tmp_path):
    with robot.torque_disabled():
        rig.hand_move(np.r_[spec.JOINT_UPPER[0] + 0.3, spec.HOME_POSE[1:]])
    robot.disconnect()
    r = BlindgraspGripper(rig.robot_config(robot.calibration_dir, operating_mode="POSITION"))
    with pytest.raises(GripperSafetyStop, match=r"ff_j10.*outside their limits.*POSITION mode"):
        r.connect()
    assert stopped(rig, r)


def test_a_servo_set_to_turn_its_torque_on_at_power_up_is_set_back(rig, tmp_path, monkeypatch, caplog):
    """Startup_Configuration(60) bit 0 (firmware v45+): after a brown-out such a servo comes back with its torque on,
    so a reset would not show as a dropped torque (here with the bus watchdog off, which would also show it)."""
    rig.servo("mf_j20").set("Startup_Configuration", 0x03)  # Startup Torque On | RAM Restore
    with caplog.at_level(logging.WARNING):
        robot = connect_gripper(rig, tmp_path, monkeypatch, bus_watchdog_ms=0)
    assert "Startup_Configuration(60) of ['mf_j20'] had Startup Torque On" in caplog.text
    assert rig.servo("mf_j20").get("Startup_Configuration") == 0x02  # RAM Restore kept
    rig.dxl.reset_servo(20)
    with pytest.raises(GripperStateError, match=r"mf_j20 \(ID 20\): Torque_Enable 0 \(set 1\)"):
        hold(robot, 2)
    assert stopped(rig, robot)


def test_a_status_return_level_that_hides_replies_is_named(rig, tmp_path, monkeypatch):
    """Status_Return_Level(68): 1 answers reads but not writes, 0 answers PING only. Both named at connect."""
    rig.servo("ff_j11").set("Status_Return_Level", 1)
    _refused(rig, tmp_path, monkeypatch, GripperBusError, r"Status_Return_Level\(68\) \{11: 1\}")
    rig.servo("ff_j11").set("Status_Return_Level", 0)
    _refused(rig, tmp_path, monkeypatch, GripperBusError,
             r"missing IDs \[11\].*IDs \[11\] answer PING but not READ: their Status_Return_Level\(68\) is 0")  # fmt: skip
