"""Faults on the physics twin, each injected while the gripper squeezes an object: a servo's overload shutdown,
the force stream stopping, and the host process killed (SIGKILL).

The host is its own process (`tests/twin_grasp_host.py`, the real robot class at 20 Hz), as on a lab PC; the twin
runs in the test, which injects the faults into the emulators and reads the truth from the physics.
The bounds are the documented ones (docs/hardware.md, fault table): a servo hardware error and stale force data
(> 150 ms) stop the gripper with the torque off within the call that sees them; a dead host leaves the servos to
their bus watchdog, which stops them 200 ms after the last packet (torque on, goals refused: they hold, they do not
squeeze harder). "Not crushed": no fingertip reaches 40 N, half the robot's 80 N overload stop, during the grasp or after the stop
(a released object may drop onto a limp fingertip), and once things settle no tip is pressed harder than during the
grasp.
"""

from __future__ import annotations

import json
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
from emulators.harness import BIN, as_from_a_terminal, cli_env

from lerobot_blindgrasp import durable, spec
from lerobot_blindgrasp.hardware.emulators.dynamixel import HW_OVERLOAD
from lerobot_blindgrasp.hardware.xm430 import WATCHDOG_TRIPPED

sys.path.insert(0, str(Path(__file__).parent))
from twin_grasp_host import LATENCY_TIMER_MS  # noqa: E402

pytestmark = pytest.mark.slow

HOST = Path(__file__).parent / "twin_grasp_host.py"
OBJECT, SEED = "sphere_medium", 1000  # this start state puts the sphere within 6 mm of the claw centre
CRUSH_N = 40.0  # "not crushed": the test's own bound, half the robot's 80 N overload stop
STOP_BOUND_S = 0.6  # "within the call": one 50 ms period plus reply timeouts (122 ms each) on a loaded CI host
WATCHDOG_S = 0.2  # bus_watchdog_ms


@pytest.fixture(scope="module")
def station(tmp_path_factory):
    """A running twin, calibrated through lerobot-calibrate (blindgrasp-twin-calibrate plays the operator)."""
    from lerobot_blindgrasp.twin.cli import TwinConfig
    from lerobot_blindgrasp.twin.runner import Twin

    tmp = tmp_path_factory.mktemp("twin_faults")
    with Twin(TwinConfig(socket=str(tmp / "twin.sock"))) as twin:
        durable.atomic_write_json(tmp / "ports.json", twin.ports())
        res = subprocess.run([str(BIN / "blindgrasp-twin-calibrate"), f"--ports_json={tmp / 'ports.json'}",
                              "--robot_id=twin", f"--calibration_dir={tmp}",
                              f"--latency_timer_ms={LATENCY_TIMER_MS}"], env=cli_env(tmp),
                             capture_output=True, text=True, timeout=240)  # fmt: skip
        assert res.returncode == 0, res.stdout[-3000:]
        yield twin, tmp


class Host:
    """twin_grasp_host.py squeezing the object; the twin holds the object at the claw centre first."""

    def __init__(self, twin, tmp: Path):
        twin.physics.end_trial()  # an empty claw, as the operator leaves it
        twin.physics.place(OBJECT, SEED)
        self.twin = twin
        args = json.dumps({**twin.ports(), "calibration_dir": str(tmp)})
        self.proc = subprocess.Popen(as_from_a_terminal([sys.executable, str(HOST), args]), env=cli_env(tmp),
                                     stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)  # fmt: skip
        self.lines: list[str] = []
        while not self.lines or self.lines[-1].strip() != "READY":
            line = self.proc.stdout.readline()
            assert line, "the host ended before grasping:\n" + "".join(self.lines[-40:])
            self.lines.append(line)
        self.peak = peak_force(twin, 0.5)

    def stopped_with(self) -> str:
        out = self.proc.communicate(timeout=30)[0]
        return next((x for x in out.splitlines() if x.startswith("STOPPED")), out[-2000:])


def peak_force(twin, seconds: float) -> float:
    peak, end = 0.0, time.monotonic() + seconds
    while time.monotonic() < end:
        peak = max(peak, float(twin.physics.tip_force_n.max()))
        time.sleep(0.005)
    return peak


def settled_force(twin) -> float:
    """The largest tip force 1 s after a stop, over 0.2 s (a released object has landed by then)."""
    time.sleep(1.0)
    return peak_force(twin, 0.2)


def time_to_torque_off(twin, t_fault: float) -> float:
    while twin.bus.any_torque():
        assert time.monotonic() - t_fault < 5.0, "the torque stayed on"
        time.sleep(0.002)
    return time.monotonic() - t_fault


def test_overload_shutdown_of_one_servo_stops_the_gripper(station):
    twin, tmp = station
    host = Host(twin, tmp)
    t_fault = time.monotonic()
    twin.bus.set_hardware_error(21, HW_OVERLOAD)  # mf_j21's firmware trips: its own torque goes off at once
    dt = time_to_torque_off(twin, t_fault)
    after = peak_force(twin, 0.5)
    settled = settled_force(twin)
    stop = host.stopped_with()
    print(
        f"\noverload: torque off on all 9 servos {dt * 1e3:.0f} ms after the fault; grasp peak "
        f"{host.peak:.1f} N, "
        f"after the stop {after:.1f} N, settled {settled:.1f} N; {stop[:160]}"
    )
    assert stop.startswith("STOPPED GripperHardwareError") and "overload" in stop
    assert dt <= STOP_BOUND_S
    assert host.peak < CRUSH_N and after < CRUSH_N and settled <= host.peak + 1.0
    twin.bus.servos[21].reboot()  # a power cycle clears the error for the next test


def test_force_stream_stopping_stops_the_gripper(station):
    twin, tmp = station
    host = Host(twin, tmp)
    t_fault = time.monotonic()
    twin.force.paused = True  # the force board goes silent (crashed firmware, cut cable)
    try:
        dt = time_to_torque_off(twin, t_fault)
        after = peak_force(twin, 0.5)
        settled = settled_force(twin)
    finally:
        twin.force.paused = False
    stop = host.stopped_with()
    print(
        f"\nforce stream stopped: torque off {dt * 1e3:.0f} ms later; grasp peak {host.peak:.1f} N, "
        f"after {after:.1f} N, settled {settled:.1f} N; {stop[:160]}"
    )
    assert stop.startswith("STOPPED ForceSensorError") and "stale" in stop
    # stale_timeout_s after the last frame (which came at most one 5 ms emulator tick plus a 12.5 ms frame period
    # before the pause), then within the call
    assert 0.15 - 0.0175 <= dt <= 0.15 + STOP_BOUND_S
    assert host.peak < CRUSH_N and after < CRUSH_N and settled <= host.peak + 1.0


def test_killed_host_leaves_the_servos_stopped_by_their_watchdog(station):
    twin, tmp = station
    host = Host(twin, tmp)
    host.proc.kill()
    t_kill = time.monotonic()
    host.proc.wait(timeout=10)
    while not all(s.get("Bus_Watchdog") == WATCHDOG_TRIPPED for s in twin.servos):
        assert time.monotonic() - t_kill < 3.0, "the servos' watchdog never stopped them"
        time.sleep(0.002)
    dt = time.monotonic() - t_kill
    goals = [s.get("Goal_Position") for s in twin.servos]
    after = peak_force(twin, 0.5)
    settled = settled_force(twin)
    print(
        f"\nhost killed: every servo stopped by its watchdog {dt * 1e3:.0f} ms after the kill; grasp peak "
        f"{host.peak:.1f} N, after {after:.1f} N, settled {settled:.1f} N"
    )
    assert dt <= WATCHDOG_S + 0.15  # 200 ms after the last packet, which went out before the kill
    assert [s.get("Goal_Position") for s in twin.servos] == goals  # held where they stopped
    assert twin.bus.any_torque()  # documented: the watchdog holds with the torque on, capped by the current limit
    assert host.peak < CRUSH_N and after < CRUSH_N and settled <= host.peak + 1.0
    assert np.isfinite(twin.physics.q).all()
