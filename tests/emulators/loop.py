"""Helpers for tests that drive the emulated gripper at 20 Hz (the `rig` and `robot` fixtures are in conftest.py)."""

from __future__ import annotations

import time

import numpy as np

from lerobot_blindgrasp import spec


def settle(robot, target: dict[str, float], steps: int = 20) -> dict[str, float]:
    """Send the same target at 20 Hz until the servos get there (emulated time constant ~30 ms)."""
    for _ in range(steps):
        robot.send_action(target)
        time.sleep(spec.CONTROL_DT / 2)
    return robot.get_observation()


def hold(robot, steps: int, target=None):
    """A 20 Hz loop holding `target` (default: the present pose)."""
    for _ in range(steps):
        start = time.perf_counter()
        obs = robot.get_observation()
        goal = target if target is not None else as_q(obs)
        robot.send_action(dict(zip(spec.ACTION_NAMES, np.asarray(goal).tolist(), strict=True)))
        time.sleep(max(0.0, spec.CONTROL_DT - (time.perf_counter() - start)))


def as_q(obs: dict[str, float]) -> np.ndarray:
    return np.array([obs[k] for k in spec.JOINT_FEATURE_NAMES])


def as_action(q) -> dict[str, float]:
    return dict(zip(spec.ACTION_NAMES, np.asarray(q, dtype=float).tolist(), strict=True))


def stopped(rig, robot) -> bool:
    """The gripper stopped as a latched stop leaves it: disconnected, the torque off on every servo of the rig."""
    return not robot.is_connected and not rig.dxl.any_torque()


def no_prompt(monkeypatch) -> None:
    """A test that must not reach an operator: any `input()` fails it."""

    def prompt(text=""):
        raise AssertionError(f"unexpected interactive prompt: {text!r}")

    monkeypatch.setattr("builtins.input", prompt)
