"""Faults on the physics twin, each interrupting the shipped student's own grasp through lerobot-eval
(`--env.type=blindgrasp_real`): a servo's overload shutdown raised by the servo's firmware model, the force stream
stopping and the host process killed (SIGKILL), the last two at a firm squeeze near the grasp's peak.

The host is its own process (`tests/twin_grasp_host.py`: lerobot-eval's `eval_main`, one trial per run), as on a lab
PC; the twin runs in the test, which injects the faults into the emulators and reads the truth from the physics.
The bounds are the documented ones (docs/hardware.md, fault table): a servo hardware error and stale force data
(> 150 ms) stop the gripper with the torque off within the call that sees them. A dead host cannot turn the torque
off: the XM430's Bus Watchdog stops each servo `bus_watchdog_ms` after the last packet with the torque on, holding
where it is (Goal_Position := Present_Position), so the squeeze relaxes to what holding that pose takes.
"Not crushed": after the fault no fingertip is pressed harder than the grasp had pressed it before the fault, beyond
what the stop's reaction time lets the grasp add (MARGIN_N), nothing reaches the robot's overload stop, and once
things settle no tip is pressed harder than the grasp pressed it.
"""

from __future__ import annotations

import json
import queue
import subprocess
import sys
import threading
import time
from pathlib import Path

import numpy as np
import pytest
from emulators.harness import BIN, cli_env

from lerobot_blindgrasp import durable
from lerobot_blindgrasp.hardware.xm430 import WATCHDOG_TRIPPED
from lerobot_blindgrasp.robots.blindgrasp_gripper import ForceSensorConfig

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from twin_grasp_host import LATENCY_TIMER_MS  # noqa: E402

pytestmark = pytest.mark.slow

ROOT = Path(__file__).resolve().parents[2]
HOST = Path(__file__).resolve().parents[1] / "twin_grasp_host.py"
OBJECT, SEED = "sphere_medium", 1000  # the student squeezes it to ~30 N on the thumb (docs/results/twin.md)
SQUEEZE_N = 15.0  # a tip force past which the grasp is firm
PEAK_DIP = 0.05  # the faults strike as the force turns down from its largest value so far, within this of it
# What the grasp may still add after the fault, before the stop acts: the force stream's 150 ms staleness is three
# more periods of the student's squeeze.
MARGIN_N = 10.0
STOP_BOUND_S = 0.6  # "within the call": one 50 ms period plus reply timeouts (302 ms each) on a loaded CI host
WATCHDOG_S = 0.2  # bus_watchdog_ms
FIRMWARE_OVERLOAD_S = 0.3  # the emulated firmware's time at the current limit before its overload error


@pytest.fixture(scope="module")
def station(tmp_path_factory):
    """A running twin, calibrated through lerobot-calibrate, and the host, its LeRobot imported."""
    from lerobot_blindgrasp.twin.command import TwinConfig
    from lerobot_blindgrasp.twin.runner import Twin

    tmp = tmp_path_factory.mktemp("twin_faults")
    with Twin(TwinConfig(socket=str(tmp / "twin.sock"))) as twin:
        durable.atomic_write_json(tmp / "ports.json", twin.ports())
        res = subprocess.run([str(BIN / "blindgrasp-twin-calibrate"), f"--ports_json={tmp / 'ports.json'}",
                              "--robot_id=twin", f"--calibration_dir={tmp}", "--force=false",
                              f"--latency_timer_ms={LATENCY_TIMER_MS}"], env=cli_env(tmp),
                             capture_output=True, text=True, timeout=240)  # fmt: skip
        assert res.returncode == 0, res.stdout[-3000:]
        args = {**twin.ports(), "calibration_dir": str(tmp), "object": OBJECT, "seed": SEED,
                "output_dir": str(tmp / "eval"), "runs": 3}  # fmt: skip
        host = subprocess.Popen([sys.executable, str(HOST), json.dumps(args)], env=cli_env(tmp), cwd=ROOT,
                                stdin=subprocess.PIPE, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)  # fmt: skip
        host.output = HostOutput(host)
        try:
            yield twin, host
        finally:
            host.kill()
            host.wait(timeout=10)


class HostOutput:
    """The host's output, drained by a thread (a full pipe would stall the host's control loop), as a queue."""

    def __init__(self, proc: subprocess.Popen):
        self.lines: queue.Queue[str] = queue.Queue()
        self.seen: list[str] = []
        threading.Thread(target=self._drain, args=(proc.stdout,), daemon=True).start()

    def _drain(self, stream) -> None:
        for line in stream:
            self.lines.put(line)
        self.lines.put("")

    def read_until(self, prefixes: tuple[str, ...], timeout_s: float = 240.0) -> str:
        deadline = time.monotonic() + timeout_s
        while (left := deadline - time.monotonic()) > 0:
            try:
                line = self.lines.get(timeout=left)
            except queue.Empty:
                break
            assert line, "the host ended:\n" + "".join(self.seen[-40:])
            self.seen.append(line)
            at = [line.find(p) for p in prefixes if p in line]  # a progress bar may share the marker's line
            if at:
                return line[min(at) :].strip()
        raise AssertionError("the host never said " + " or ".join(prefixes) + ":\n" + "".join(self.seen[-40:]))


def read_until(host, prefixes: tuple[str, ...]) -> str:
    return host.output.read_until(prefixes)


def next_run(twin, host) -> int:
    """Let the host start its next trial; returns the twin's trial counter before it."""
    twin.physics.end_trial()  # an empty claw, as the operator leaves it
    trial = twin.physics.trial
    host.stdin.write("\n")
    host.stdin.flush()
    return trial


def wait_for(cond, timeout_s: float = 120.0, what: str = "") -> float:
    deadline = time.monotonic() + timeout_s
    while not cond():
        assert time.monotonic() < deadline, f"timed out waiting for {what}"
        time.sleep(0.002)
    return time.monotonic()


def peak_force(twin, seconds: float) -> float:
    peak, end = 0.0, time.monotonic() + seconds
    while time.monotonic() < end:
        peak = max(peak, float(twin.physics.tip_force_n.max()))
        time.sleep(0.005)
    return peak


def at_a_peak(twin, trial: int) -> bool:
    """The student's grasp of this run's placement has pressed a tip with SQUEEZE_N and the force just turned down
    from its largest value so far (within PEAK_DIP of it): the fault strikes at the grasp's peak."""
    if twin.physics.trial <= trial:
        return False
    peak = float(twin.physics.peak_tip_force_n.max())
    return peak >= SQUEEZE_N and float(twin.physics.tip_force_n.max()) <= (1.0 - PEAK_DIP) * peak


def wait_for_squeeze(twin, host, trial: int) -> None:
    deadline = time.monotonic() + 120.0
    while not at_a_peak(twin, trial):
        try:
            line = host.output.lines.get_nowait()
            host.output.seen.append(line)
        except queue.Empty:
            time.sleep(0.002)
        assert time.monotonic() < deadline, "no squeeze; the host said:\n" + "".join(host.output.seen[-30:])


def after_the_fault(twin, t_fault: float) -> tuple[float, float]:
    """The largest tip force from the fault for 0.5 s, and over 0.2 s a second later (a released object has
    landed by then)."""
    after = peak_force(twin, max(0.0, t_fault + 0.5 - time.monotonic()))
    time.sleep(1.0)
    return after, peak_force(twin, 0.2)


def check_not_crushed(before: float, after: float, settled: float) -> None:
    """No harder squeeze than the grasp's own beyond what the stop's reaction time allows, never the overload
    stop's level, and once things settle no tip pressed harder than the grasp pressed it."""
    assert after <= before + MARGIN_N, (before, after)
    assert max(before, after) < ForceSensorConfig().overload_n
    assert settled <= before + 1.0, (before, settled)


def test_a_servo_firmware_overload_during_the_students_grasp_stops_the_gripper(station):
    twin, host = station
    read_until(host, ("RUN",))
    trial = twin.physics.trial
    for s in twin.servos:  # the firmware's overload detection, made quick enough to trip inside one grasp
        s.health.overload_s = FIRMWARE_OVERLOAD_S
    try:
        t_fault = wait_for(lambda: any(s.get("Hardware_Error_Status") for s in twin.servos), what="an overload")
        before = float(twin.physics.peak_tip_force_n.max()) if twin.physics.trial > trial else 0.0
        tripped = [s.id for s in twin.servos if s.get("Hardware_Error_Status")]
        dt = wait_for(lambda: not twin.bus.any_torque(), 5.0, "torque off") - t_fault
        after, settled = after_the_fault(twin, t_fault)
    finally:
        for s in twin.servos:
            s.health.overload_s = 8.0
    stop = read_until(host, ("STOPPED", "ENDED"))
    print(f"\nfirmware overload of ID {tripped}: torque off on all 9 {dt * 1e3:.0f} ms later; peak before "
          f"{before:.1f} N, after {after:.1f} N, settled {settled:.1f} N; {stop[:160]}")  # fmt: skip
    assert stop.startswith("STOPPED GripperHardwareError") and "overload" in stop
    assert dt <= STOP_BOUND_S
    check_not_crushed(before, after, settled)
    for servo in twin.servos:  # a power cycle clears the errors (other servos at the limit may have tripped since)
        if servo.get("Hardware_Error_Status"):
            servo.reboot()


def test_the_force_stream_stopping_at_the_students_squeeze_stops_the_gripper(station):
    twin, host = station
    trial = next_run(twin, host)
    read_until(host, ("RUN",))
    wait_for_squeeze(twin, host, trial)
    twin.force.paused = True  # the force board goes silent (crashed firmware, cut cable)
    t_fault = time.monotonic()
    try:
        before = float(twin.physics.peak_tip_force_n.max())
        dt = wait_for(lambda: not twin.bus.any_torque(), 5.0, "torque off") - t_fault
        after, settled = after_the_fault(twin, t_fault)
    finally:
        twin.force.paused = False
    stop = read_until(host, ("STOPPED", "ENDED"))
    print(f"\nforce stream stopped at {before:.1f} N: torque off {dt * 1e3:.0f} ms later; after {after:.1f} N, "
          f"settled {settled:.1f} N; {stop[:160]}")  # fmt: skip
    assert stop.startswith("STOPPED ForceSensorError") and "stale" in stop
    # stale_timeout_s after the last frame (which came at most one 5 ms emulator tick plus a 12.5 ms frame period
    # before the pause), then within the call
    assert 0.15 - 0.0175 <= dt <= 0.15 + STOP_BOUND_S
    check_not_crushed(before, after, settled)


def test_a_killed_host_leaves_the_servos_holding_by_their_watchdog(station):
    twin, host = station
    trial = next_run(twin, host)
    read_until(host, ("RUN",))
    wait_for_squeeze(twin, host, trial)
    host.kill()
    t_kill = time.monotonic()
    at_kill = float(twin.physics.tip_force_n.max())
    before = float(twin.physics.peak_tip_force_n.max())
    waiting = 0.0  # the squeeze while the watchdog waits: the servos still hold the last goals the host sent
    while not all(s.get("Bus_Watchdog") == WATCHDOG_TRIPPED for s in twin.servos):
        assert time.monotonic() - t_kill < 3.0, "the servos' watchdog never stopped them"
        waiting = max(waiting, float(twin.physics.tip_force_n.max()))
        time.sleep(0.002)
    t_trip = time.monotonic()
    host.wait(timeout=10)
    goals = [s.get("Goal_Position") for s in twin.servos]
    after, settled = after_the_fault(twin, t_trip)
    quiet = max(s.watchdog_tripped_at - s.last_instruction for s in twin.servos)
    print(f"\nhost killed at {at_kill:.1f} N (grasp peak {before:.1f} N): up to {waiting:.1f} N until every servo's "
          f"watchdog stopped it, {(t_trip - t_kill) * 1e3:.0f} ms after the kill and {quiet * 1e3:.0f} ms after its "
          f"last packet, torque still on; then {after:.1f} N, settled {settled:.1f} N")  # fmt: skip
    assert quiet <= WATCHDOG_S + 0.03  # the bus watchdog's own bound (its 20 ms units, the emulator's 10 ms tick)
    assert twin.bus.any_torque()  # the watchdog does not turn the torque off (XM430 e-Manual, Bus Watchdog)
    assert [s.get("Goal_Position") for s in twin.servos] == goals  # goals read-only: held where they stopped
    check_not_crushed(before, max(waiting, after), settled)
    assert np.isfinite(twin.physics.q).all()
