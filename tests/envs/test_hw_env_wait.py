"""The waits of a real trial (the operator's ENTER, the tare, the y/n at the time limit) on the emulated gripper: the
torque stays on holding the pose, the bus stays alive so the servos' bus watchdog never trips on a person's pause,
and a host killed while waiting is still stopped by that watchdog."""

from __future__ import annotations

import json
import logging
import sys
import threading
import time
from pathlib import Path

import numpy as np
from emulators.harness import Operator, ScriptedKeyboard, cli_env, trial_env
from emulators.rig import LATENCY_TIMER_MS

from lerobot_blindgrasp import spec
from lerobot_blindgrasp.envs.operator import OperatorKeys
from lerobot_blindgrasp.hardware.xm430 import RAD_PER_TICK, WATCHDOG_TRIPPED, WATCHDOG_UNIT_MS

TRIAL_WAIT = Path(__file__).resolve().parents[1] / "emulators" / "trial_wait.py"
# Longer than the shipped 200 ms, so that a loaded CI host that starves this process for a few periods does not trip
# the watchdog through the keep-alive; the silent waits below are still twice as long, which the old env tripped on.
WATCHDOG_MS = 600


def _armed(rig) -> bool:
    units = WATCHDOG_MS // WATCHDOG_UNIT_MS
    return all(rig.dxl.servos[i].get("Bus_Watchdog") == units for i in spec.SERVO_IDS)


def test_an_operator_slower_than_the_watchdog_trips_nothing(rig, robot, caplog):
    """ENTER three watchdog periods after the prompt, and the y/n answer as late: no servo's watchdog trips, no
    re-arm is logged, and the watchdog is armed (not disarmed) when the trial starts."""
    robot.disconnect()
    robot.config.bus_watchdog_ms = WATCHDOG_MS
    pause_s = 2 * WATCHDOG_MS / 1e3
    keys = OperatorKeys(listener_factory=ScriptedKeyboard)
    env = trial_env(robot.config, "sphere_medium", keys, episode_s=0.1)
    caplog.set_level(logging.WARNING)
    try:
        threading.Timer(pause_s, keys.listener.press, ["enter"]).start()
        env.reset()
        assert _armed(rig) and all(rig.dxl.torque_enabled(i) for i in spec.SERVO_IDS)
        threading.Timer(pause_s, keys.listener.press, ["y"]).start()  # answers the question at the time limit
        for _ in range(env._max_episode_steps):
            *_, term, trunc, info = env.step(spec.HOME_POSE)
            if term or trunc:
                break
        assert term and info["is_success"]
        assert _armed(rig)
    finally:
        env.close()
    assert [i for i in spec.SERVO_IDS if rig.dxl.servos[i].watchdog_tripped_at is not None] == []
    assert "Bus watchdog stopped" not in caplog.text


def test_unattended_waits_and_tares_trip_nothing(rig, robot, caplog):
    """Force mode waits `unattended_reset_s` and tares for `tare_s`, both longer than the watchdog here."""
    robot.disconnect()
    robot.config.bus_watchdog_ms = WATCHDOG_MS
    robot.config.force_sensor.tare_s = 2 * WATCHDOG_MS / 1e3
    env = trial_env(robot.config, "sphere_medium", success_mode="force", unattended_reset_s=2 * WATCHDOG_MS / 1e3,
                    episode_s=0.1)  # fmt: skip
    caplog.set_level(logging.WARNING)
    try:
        env.reset()
        env.step(spec.HOME_POSE)
        assert _armed(rig)
    finally:
        env.close()
    assert [i for i in spec.SERVO_IDS if rig.dxl.servos[i].watchdog_tripped_at is not None] == []
    assert "Bus watchdog stopped" not in caplog.text


def test_a_host_killed_while_waiting_is_stopped_by_the_watchdog(rig, robot, tmp_path):
    """SIGKILL while the trial waits for ENTER: the watchdog stayed armed through the wait, so the servos stop on
    their own one watchdog period after the last keep-alive, torque on, holding where they are."""
    watchdog_s = WATCHDOG_MS / 1e3
    robot.disconnect()  # the calibration file stays; the subprocess connects without prompting
    args = {"port": rig.dxl.port, "force_port": rig.force.port, "calibration_dir": str(robot.calibration_dir),
            "scale": rig.force.scale.tolist(), "latency_timer_ms": LATENCY_TIMER_MS, "bus_watchdog_ms": WATCHDOG_MS}  # fmt: skip
    proc = Operator([sys.executable, str(TRIAL_WAIT), json.dumps(args)], cli_env(tmp_path))
    proc.expect("place the object at the claw centre")
    waited = time.monotonic() + 2 * watchdog_s
    while time.monotonic() < waited:  # a person's pause: the keep-alive holds the watchdog off
        time.sleep(spec.CONTROL_DT)
        assert all(rig.dxl.servos[i].watchdog_tripped_at is None for i in spec.SERVO_IDS), proc.text[-3000:]
    assert _armed(rig) and all(rig.dxl.torque_enabled(i) for i in spec.SERVO_IDS)
    proc.proc.kill()
    t_kill = time.monotonic()
    proc.wait(30)
    deadline = t_kill + 10.0
    while not all(rig.dxl.servos[i].get("Bus_Watchdog") == WATCHDOG_TRIPPED for i in spec.SERVO_IDS):
        assert time.monotonic() < deadline, "the watchdog never stopped the servos"
        time.sleep(0.001)
    # It counts from the last packet, which came at most one keep-alive period (plus its sync read) before the kill.
    last = max(rig.dxl.servos[i].last_instruction for i in spec.SERVO_IDS)
    assert t_kill - last <= spec.CONTROL_DT + watchdog_s
    q = rig.true_q()
    time.sleep(0.3)
    np.testing.assert_allclose(rig.true_q(), q, atol=RAD_PER_TICK)  # stopped, and stays stopped
    assert all(rig.dxl.torque_enabled(i) for i in spec.SERVO_IDS)
