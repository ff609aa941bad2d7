"""Hazards with no host (docs/hardware.md, "Hazard analysis", "Protection with no host"; the Bus_Watchdog and
Shutdown rows of the control table): when the host pauses, is killed or goes quiet, the servos' Bus_Watchdog stops
them, and from then on only their firmware acts by the registers listed there. Each of those registers, found
changed in a servo's EEPROM, is restored at connect and named; one that does not keep its value refuses the connect
with the torque off."""

from __future__ import annotations

import logging
import time

import numpy as np
import pytest
from emulators.harness import connect_gripper, robot_loop_process, time_until
from emulators.loop import as_q, settle, stopped

from lerobot_blindgrasp import spec
from lerobot_blindgrasp.hardware import xm430
from lerobot_blindgrasp.hardware.xm430 import RAD_PER_TICK, WATCHDOG_TRIPPED
from lerobot_blindgrasp.robots.blindgrasp_gripper import BlindgraspGripper
from lerobot_blindgrasp.robots.blindgrasp_gripper.errors import GripperProtectionError

WATCHDOG_S = 0.200  # BlindgraspGripperConfig.bus_watchdog_ms


# --- Bus_Watchdog: the stop itself ------------------------------------------------------------------------------
def test_killed_host_is_stopped_by_the_servo_watchdog(rig, robot, tmp_path):
    """SIGKILL leaves no cleanup at all: the servos' Bus_Watchdog stops them where they are."""
    proc = robot_loop_process(rig, robot, tmp_path)
    ids = spec.SERVO_IDS
    proc.proc.kill()
    t_kill = time.monotonic()
    proc.wait(30)
    time_until(lambda: all(rig.dxl.servos[i].get("Bus_Watchdog") == WATCHDOG_TRIPPED for i in ids), timeout_s=2.0)
    stopped = max(rig.dxl.servos[i].watchdog_tripped_at for i in ids) - t_kill
    print(f"SIGKILL: all 9 servos stopped by their bus watchdog {stopped * 1e3:.0f} ms after the kill")
    # The watchdog counts from the last packet, which came <= one loop iteration before the kill.
    assert stopped <= WATCHDOG_S + 0.1
    q = rig.true_q()
    time.sleep(0.3)
    np.testing.assert_allclose(rig.true_q(), q, atol=RAD_PER_TICK)  # stopped, and stays stopped
    # Goals are refused until someone clears the watchdog error: a stray write cannot restart the motion.
    assert all(rig.dxl.torque_enabled(i) for i in ids)


def test_watchdog_stop_after_a_host_pause_is_rearmed(rig, robot, caplog):
    servos = [rig.dxl.servos[i] for i in spec.SERVO_IDS]
    assert {s.get("Bus_Watchdog") for s in servos} == {10}  # 10 x 20 ms
    q0 = as_q(robot.get_observation())
    time.sleep(WATCHDOG_S + 0.15)  # a slow save between episodes, an operator prompt
    assert {s.get("Bus_Watchdog") for s in servos} == {WATCHDOG_TRIPPED}
    assert all(s.get("Torque_Enable") == 1 for s in servos)  # stopped, not limp
    with caplog.at_level("WARNING"):
        robot.get_observation()
    assert "re-arming" in caplog.text and {s.get("Bus_Watchdog") for s in servos} == {10}
    target = dict(zip(spec.ACTION_NAMES, (q0 + 0.1).tolist(), strict=True))
    np.testing.assert_allclose(as_q(settle(robot, target, steps=8)), q0 + 0.1, atol=1.01 * RAD_PER_TICK)


# --- the registers the firmware acts by -------------------------------------------------------------------------
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
        robot = connect_gripper(rig, tmp_path, monkeypatch)
    robot.disconnect()
    want = {**xm430.NO_HOST_PROTECTION, "Current_Limit": xm430.amps_to_current_units(robot.config.current_limit_a)}
    assert set(want) == {reg for reg, _ in WRONG.values()}  # the test covers every register of the list
    for joint, (reg, value) in WRONG.items():
        assert rig.servo(joint).get(reg) == want[reg]
        assert f"{joint} {reg} {value} -> {want[reg]}" in caplog.text


def test_a_cleared_shutdown_register_is_restored_at_connect(rig, tmp_path, monkeypatch, caplog):
    """Shutdown(63) = 0 (a tool wrote it): the firmware would never drop the torque itself. Restored, named."""
    rig.servo("mf_j22").set("Shutdown", 0)
    with caplog.at_level(logging.WARNING):
        robot = connect_gripper(rig, tmp_path, monkeypatch)
    robot.disconnect()
    assert "mf_j22 Shutdown 0 -> 52" in caplog.text
    assert rig.servo("mf_j22").get("Shutdown") == 0x34


def test_a_register_that_does_not_keep_its_value_refuses_the_connect(rig, tmp_path, monkeypatch):
    """A worn EEPROM cell acknowledges the write and keeps Temperature_Limit at 99 degC."""
    servo = rig.servo("th_j32")
    servo.set("Temperature_Limit", 99)
    servo.unwritable.add("Temperature_Limit")
    monkeypatch.setattr("builtins.input", rig.calibration_inputs())
    robot = BlindgraspGripper(rig.robot_config(tmp_path / "cal"))
    with pytest.raises(GripperProtectionError, match=r"th_j32 \(ID 32\) Temperature_Limit = 99 \(configured 80\)"):
        robot.connect()
    assert stopped(rig, robot)
