"""Teleoperators of this plugin; importing registers them with LeRobot (`--teleop.type=manus_glove`)."""

from . import manus_glove  # noqa: F401  (registration)
