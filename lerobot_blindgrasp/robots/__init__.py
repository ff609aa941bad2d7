"""Robots of this plugin; importing registers them with LeRobot (`--robot.type=blindgrasp_gripper`)."""

from . import blindgrasp_gripper  # noqa: F401  (registration)
