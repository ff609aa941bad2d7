"""Held-out faults: found by the hazard analysis (docs/hardware.md), named by no issue. One case each, against
the emulators (servo bus, force board, glove bridge), the checkpoint files themselves, or the OS as the code meets
it (a port another program holds, a user without permissions, memory, the wall clock)."""

from __future__ import annotations

import errno
import json
import logging
import os
import socket
import time
from types import SimpleNamespace

import pytest
from emulators.glove_sender import FIST, OPEN, GloveEmulator, free_udp_port
from test_hw_health import _hold
from test_policy_check import ROBOT, _checkpoint

from lerobot_blindgrasp import policy_contract
from lerobot_blindgrasp.hardware import xm430
from lerobot_blindgrasp.hardware.servo_diagnostics import ERROR, OK, WARN, ServoHealth
from lerobot_blindgrasp.robots.blindgrasp_gripper import BlindgraspGripper
from lerobot_blindgrasp.robots.blindgrasp_gripper.errors import (
    ForceSensorError,
    GripperHealthError,
    GripperPortAccessError,
    PolicyMismatchError,
)
from lerobot_blindgrasp.teleoperators.manus_glove import ManusGlove, ManusGloveConfig
from lerobot_blindgrasp.teleoperators.manus_glove import receiver as stream_mod
from lerobot_blindgrasp.teleoperators.manus_glove.manus_glove import GloveStreamLost

JOINTS = ["ff_j10"]


def _connect(rig, tmp_path, monkeypatch) -> BlindgraspGripper:
    monkeypatch.setattr("builtins.input", rig.calibration_inputs())
    robot = BlindgraspGripper(rig.robot_config(tmp_path / "cal"))
    robot.connect()
    return robot


def _block(temp=35, volts=12.0, current=0) -> dict:
    return {"ff_j10": {"Present_Temperature": temp, "Present_Input_Voltage": round(volts * 10),
                       "Present_Current": current & 0xFFFF}}  # fmt: skip


def test_a_cleared_shutdown_register_is_restored_at_connect(rig, tmp_path, monkeypatch, caplog):
    """Shutdown(63) = 0 (a tool wrote it): the firmware would never drop the torque itself. Restored, named."""
    rig.servo("mf_j22").set("Shutdown", 0)
    with caplog.at_level(logging.WARNING):
        robot = _connect(rig, tmp_path, monkeypatch)
    robot.disconnect()
    assert "mf_j22 Shutdown 0 -> 52" in caplog.text
    assert rig.servo("mf_j22").get("Shutdown") == 0x34


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
    bad, _ = policy_contract.checkpoint_problems(ckpt, ROBOT)
    assert bad == [
        f"'observation.state' shape (10,) in {ckpt / 'policy_preprocessor.json'} (normalizer), the robot has (12,)"
    ]


def test_a_truncated_checkpoint_config_is_refused_before_anything_moves(tmp_path):
    ckpt = _checkpoint(tmp_path)
    (ckpt / "config.json").write_text((ckpt / "config.json").read_text()[:40])
    with pytest.raises(PolicyMismatchError, match=r"config.json is unreadable \(JSONDecodeError"):
        policy_contract.check_checkpoint(ckpt, ROBOT)


# --- glove, force stream, files and the OS -----------------------------------------------------------------------
def _glove(tmp_path, port: int, **config) -> ManusGlove:
    (tmp_path / "op.json").write_text(json.dumps({"open": OPEN, "fist": FIST}))
    return ManusGlove(ManusGloveConfig(id="op", port=port, calibration_dir=tmp_path, **config))


def _until_lost(teleop, seconds: float = 3.0) -> str:
    deadline = time.monotonic() + seconds
    while time.monotonic() < deadline:
        try:
            teleop.get_action()
        except GloveStreamLost as e:
            return str(e)
        time.sleep(0.01)
    raise AssertionError("the glove stream was never declared lost")


def test_a_bridge_that_is_behind_at_connect_is_not_followed(tmp_path):
    """Every pose leaves the bridge (on this machine) already 0.5 s old: a lagging SDK, a link still draining a
    backlog when the teleoperator connects. Its first pose cannot be the reference of its own age: the shared clock
    says it is stale, and connect refuses instead of driving the gripper half a second behind the hand."""
    port = free_udp_port()
    with GloveEmulator(port) as glove:
        glove.clock_offset_s = -0.5
        teleop = _glove(tmp_path, port, connect_timeout_s=0.5)
        with pytest.raises(ConnectionError, match=r"No glove data .* queued > 0.1 s"):
            teleop.connect()


def test_a_frozen_glove_goes_stale_and_stops(tmp_path):
    """The glove's radio drops and the SDK keeps reporting its last values, under new numbers and stamps. With
    `frozen_frames` set, values that repeat bit for bit (a live glove's noise never does) age like silence."""
    port = free_udp_port()
    with GloveEmulator(port, rate_hz=100.0) as glove:
        glove.noise_deg = 0.2
        teleop = _glove(tmp_path, port, frozen_frames=20)
        teleop.connect()
        try:
            time.sleep(0.3)
            teleop.get_action()  # live data with its noise: followed
            glove.frozen = True
            assert "Glove stream lost" in _until_lost(teleop)
        finally:
            teleop.disconnect()


def test_a_wall_clock_step_does_not_age_live_poses(tmp_path, monkeypatch):
    """NTP steps the wall clock by an hour while a datagram waits in the socket: the kernel stamped it before the
    step, this process reads the clock after it. Taken at face value it waited an hour (5 s once bounded), and that
    one arrival would shift the offset estimate for ever: every later pose stale. The receiver sees the step (wall -
    monotonic moved between two reads) and takes the read time for that datagram."""
    port = free_udp_port()
    with GloveEmulator(port, rate_hz=100.0):
        teleop = _glove(tmp_path, port)
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


def test_the_glove_port_in_use_is_named(tmp_path):
    """Another program (a second lerobot-record, the bridge started on the receiver's port) holds the UDP port."""
    port = free_udp_port()
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as other:
        other.bind(("127.0.0.1", port))
        with pytest.raises(
            ConnectionError, match=rf"Cannot listen for the glove on udp://127.0.0.1:{port}: .*in use"
        ):
            _glove(tmp_path, port).connect()


def test_a_force_board_reset_mid_run_stops(rig, robot):
    """The force board resets (a brown-out, a USB glitch) mid-trial: silent for its 0.5 s boot, longer than the stale
    timeout, so the trial stops, torque off (the reader itself resynchronises after it: test_hw_force.py)."""
    _hold(robot, 6)
    rig.force.reset()
    with pytest.raises(ForceSensorError, match=r"Force"):
        _hold(robot, 40)
    assert not robot.is_connected and not rig.dxl.any_torque()


def test_a_policy_with_nan_or_zero_normalizer_stats_is_refused(tmp_path):
    """A state feature that never varied in the training data (a dead load cell) has std 0: the normalizer divides by
    eps, and any change of it reaches the network x 1e8. NaN stats (a broken stats file) make every action NaN."""
    from safetensors.torch import load_file, save_file

    ckpt = _checkpoint(tmp_path)
    path = ckpt / "policy_preprocessor_step_4_normalizer_processor.safetensors"
    stats = load_file(str(path))
    stats["observation.state.std"][10] = 0.0
    stats["observation.state.mean"][0] = float("nan")
    save_file(stats, str(path))
    bad, _ = policy_contract.checkpoint_problems(ckpt, ROBOT)
    assert bad == [f"observation.state.mean not finite at ['observation.state[0] (ff_j10.pos)'] in {path}",
                   f"observation.state.std is 0 at ['observation.state[10] (mf_tip.force)'] in {path}: any change "
                   "of that input would reach the network multiplied by 1/eps"]  # fmt: skip


def test_a_policy_with_nan_weights_is_refused(tmp_path):
    from safetensors.torch import load_file, save_file

    ckpt = _checkpoint(tmp_path)
    weights = load_file(str(ckpt / "model.safetensors"))
    name = sorted(weights)[0]
    weights[name].view(-1)[:3] = float("nan")
    save_file(weights, str(ckpt / "model.safetensors"))
    bad, _ = policy_contract.checkpoint_problems(ckpt, ROBOT)
    assert bad == [f"3 non-finite weights in {ckpt / 'model.safetensors'} (in ['{name}'])"]


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


def test_out_of_memory_inside_a_call_turns_the_torque_off(rig, robot, monkeypatch):
    """MemoryError (a host out of memory, before the kernel's OOM killer, whose SIGKILL the servos' watchdog
    answers): raised inside a call, it stops the gripper like any exception and keeps its own type."""

    def oom(*args, **kwargs):
        raise MemoryError

    monkeypatch.setattr(robot.bus, "sync_read", oom)
    with pytest.raises(MemoryError):
        robot.get_observation()
    assert not robot.is_connected and not rig.dxl.any_torque()
