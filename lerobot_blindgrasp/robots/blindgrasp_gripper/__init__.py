"""The real three-finger gripper (`--robot.type=blindgrasp_gripper`): Dynamixel bus + fingertip force sensors."""

from lerobot_blindgrasp.hardware.force_board.config_force_board import ForceSensorConfig

from .blindgrasp_gripper import BlindgraspGripper
from .config_blindgrasp_gripper import BlindgraspGripperConfig

__all__ = ["BlindgraspGripper", "BlindgraspGripperConfig", "ForceSensorConfig"]
