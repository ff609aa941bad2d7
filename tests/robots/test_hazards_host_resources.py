"""Hazards of the OS resources the host loop holds (docs/hardware.md, "Hazard analysis", table "The host loop's
timing and OS resources": wall clock, serial ports, glove UDP port, signals, a dead host, memory, power returning
to a servo). A port another program holds or the user may not open is named before a byte is sent; an adapter that
vanishes stops the gripper with the error that says what to do; a termination signal, an exception or running out
of memory inside a call turns the torque off and keeps the first error; a wall-clock step does not age live glove
poses; after a lost servo's power returns, a reconnect works. The latency timer and the host's scheduling are
`test_bringup.py` and `test_host_realtime.py`."""

from __future__ import annotations

import errno
import os
import signal
import socket
import time
from types import SimpleNamespace

import numpy as np
import pytest
from emulators.glove_sender import GloveEmulator, calibrated_glove, free_udp_port
from emulators.harness import robot_loop_process, time_until
from emulators.loop import as_action, as_q, no_prompt, settle, stopped

from lerobot_blindgrasp import spec
from lerobot_blindgrasp.hardware.force_board.reader import ForceSensorReader
from lerobot_blindgrasp.hardware.ports import PortInUseError
from lerobot_blindgrasp.hardware.xm430 import RAD_PER_TICK
from lerobot_blindgrasp.robots.blindgrasp_gripper import BlindgraspGripper
from lerobot_blindgrasp.robots.blindgrasp_gripper.errors import (
    ForceSensorError,
    GripperBusError,
    GripperPortAccessError,
    GripperPortBusyError,
)
from lerobot_blindgrasp.teleoperators.manus_glove import receiver as stream_mod

TICK = RAD_PER_TICK


# --- wall clock -------------------------------------------------------------------------------------------------
def test_a_wall_clock_step_does_not_age_live_poses(tmp_path, monkeypatch):
    """NTP steps the wall clock by an hour while a datagram waits in the socket: the kernel stamped it before the
    step, this process reads the clock after it. Taken at face value it waited an hour (5 s once bounded), and that
    one arrival would shift the offset estimate for ever: every later pose stale. The receiver sees the step (wall -
    monotonic moved between two reads) and takes the read time for that datagram."""
    port = free_udp_port()
    with GloveEmulator(port, rate_hz=100.0):
        teleop = calibrated_glove(tmp_path, port)
        teleop.connect()
        try:
            step, real = [3600.0], time.time

            def stepped() -> float:  # one read straddles the step: its stamp is before it, the read after
                now, step[0] = real() + step[0], 0.0
                return now

            time.sleep(0.2)
            monkeypatch.setattr(stream_mod, "time", SimpleNamespace(monotonic=time.monotonic, time=stepped))
            time.sleep(0.3)
            for _ in range(20):
                teleop.get_action()
                time.sleep(0.01)
            assert step == [0.0] and teleop.receiver.stale == 0 and teleop.receiver.latest()[1] < 0.05
        finally:
            teleop.disconnect()


# --- serial ports -----------------------------------------------------------------------------------------------
def test_a_second_owner_is_refused_before_it_sends_a_byte(rig, robot):
    robot.get_observation()
    before = dict(rig.dxl.instruction_counts)
    second = BlindgraspGripper(rig.robot_config(robot.calibration_dir))
    with pytest.raises(GripperPortBusyError, match=r"already in use by another process.*Nothing was sent"):
        second.connect()
    assert rig.dxl.instruction_counts == before  # not one packet: no ping, no torque-off
    assert all(rig.dxl.torque_enabled(i) for i in spec.SERVO_IDS) and robot.is_connected
    robot.get_observation()
    with pytest.raises(PortInUseError, match="force-sensor port"):  # the sensor port alone, too
        ForceSensorReader(rig.force.port, 115_200, [1, 1, 1]).connect()


def test_a_serial_port_without_permission_is_named_not_taken_for_busy(rig, tmp_path, monkeypatch):
    """A user outside the `dialout` group: open() fails with EACCES, which pyserial reports with the errno a busy
    port's lock also has. Named as permissions, with what to run; nothing was sent."""
    real_open = os.open

    def no_access(path, *args, **kwargs):
        if path == rig.dxl.port:
            raise PermissionError(errno.EACCES, "Permission denied", path)
        return real_open(path, *args, **kwargs)

    monkeypatch.setattr(os, "open", no_access)
    monkeypatch.setattr("builtins.input", rig.calibration_inputs())
    robot = BlindgraspGripper(rig.robot_config(tmp_path / "cal"))
    with pytest.raises(GripperPortAccessError, match=r"No permission to open the Dynamixel bus port .*dialout"):
        robot.connect()
    assert rig.dxl.instruction_counts == {} and not robot.is_connected


def test_unplugged_bus_adapter_is_a_bus_error_that_says_cut_the_power(rig, robot):
    robot.get_observation()
    rig.dxl.stop()  # the USB adapter pulled
    t0 = time.monotonic()
    with pytest.raises(GripperBusError, match=r"port lost.*unplugged.*NOT confirmed.*cut the servo power"):
        robot.get_observation()
    print(f"bus adapter unplugged: GripperBusError after {(time.monotonic() - t0) * 1e3:.0f} ms")
    assert not robot.is_connected


def test_unplugged_bus_adapter_during_send_action(rig, robot):
    rig.dxl.stop()  # the USB adapter pulled
    with pytest.raises(GripperBusError, match="cut the servo power"):
        robot.send_action(dict.fromkeys(spec.ACTION_NAMES, 0.3))
    assert not robot.is_connected


def test_unplugged_force_sensor_is_a_sensor_error(rig, robot):
    rig.force.stop()  # the USB cable pulled
    time.sleep(0.05)
    with pytest.raises(ForceSensorError, match=r"port .* failed \(USB cable unplugged\?\).*Torque is off"):
        robot.get_observation()
    assert stopped(rig, robot)


# --- glove UDP port ---------------------------------------------------------------------------------------------
def test_the_glove_port_in_use_is_named(tmp_path):
    """Another program (a second lerobot-record, the bridge started on the receiver's port) holds the UDP port."""
    port = free_udp_port()
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as other:
        other.bind(("127.0.0.1", port))
        with pytest.raises(
            ConnectionError, match=rf"Cannot listen for the glove on udp://127.0.0.1:{port}: .*in use"
        ):
            calibrated_glove(tmp_path, port).connect()


# --- signals, exceptions, memory --------------------------------------------------------------------------------
@pytest.mark.parametrize("sig", [signal.SIGTERM, signal.SIGHUP])
def test_termination_signal_turns_the_torque_off(rig, robot, tmp_path, sig):
    proc = robot_loop_process(rig, robot, tmp_path)
    proc.proc.send_signal(sig)
    dt = time_until(lambda: not rig.dxl.any_torque())
    assert proc.wait(30) == 128 + sig, proc.text[-3000:]  # SystemExit(128 + signum): unwound, not killed
    assert f"{signal.Signals(sig).name} received: stopping" in proc.text
    # No bound on how soon: that is the host scheduler's; the twin's fault tests bound the stop within a call.
    print(f"{signal.Signals(sig).name}: torque off on all 9 servos {dt * 1e3:.0f} ms after the signal")


def test_out_of_memory_inside_a_call_turns_the_torque_off(rig, robot, monkeypatch):
    """MemoryError (a host out of memory, before the kernel's OOM killer, whose SIGKILL the servos' watchdog
    answers): raised inside a call, it stops the gripper like any exception and keeps its own type."""

    def oom(*args, **kwargs):
        raise MemoryError

    monkeypatch.setattr(robot.bus, "sync_read", oom)
    with pytest.raises(MemoryError):
        robot.get_observation()
    assert not robot.is_connected and not rig.dxl.any_torque()


def test_a_safety_stop_inside_with_robot_raises_the_original_fault(rig, robot, monkeypatch):
    robot.disconnect()
    no_prompt(monkeypatch)
    rig.dxl.drop_responses[22] = 10_000
    with pytest.raises(GripperBusError, match=r"servo IDs \[22\]"):
        with BlindgraspGripper(rig.robot_config(robot.calibration_dir)) as r:
            r.get_observation()
    assert not rig.dxl.any_torque()


def test_with_robot_disconnects_on_other_exceptions(rig, robot):
    robot.disconnect()
    with pytest.raises(ZeroDivisionError), BlindgraspGripper(rig.robot_config(robot.calibration_dir)) as r:
        r.get_observation()
        1 / 0  # noqa: B018  (a bug in the caller's loop)
    assert not r.is_connected and not rig.dxl.any_torque()


# --- power returning to a servo ---------------------------------------------------------------------------------
def test_reconnect_after_power_returns_to_a_lost_servo(rig, robot, monkeypatch):
    """mf_j21 loses power while the host is quiet (> the 200 ms bus watchdog): the others stop on their watchdog,
    the next call stops the gripper. Power returns (the servo boots with RAM defaults), and the operator reconnects.
    The watchdog error of the other servos outlives the torque-off and makes Goal_Current read-only, so configure()
    must clear it before anything else."""
    robot.get_observation()
    rig.dxl.missing_ids.add(21)
    time.sleep(0.3)
    with pytest.raises(Exception, match=r"servo IDs \[21\]"):
        robot.get_observation()
    assert not robot.is_connected and not any(rig.dxl.torque_enabled(i) for i in spec.SERVO_IDS if i != 21)
    rig.dxl.missing_ids.discard(21)
    rig.dxl.reset_servo(21)
    no_prompt(monkeypatch)
    robot.connect()
    q = as_q(robot.get_observation())
    target = q.copy()
    target[4] += 0.2
    np.testing.assert_allclose(as_q(settle(robot, as_action(target), steps=8)), target, atol=2 * TICK)
