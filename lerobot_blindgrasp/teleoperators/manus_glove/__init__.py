"""Manus glove teleoperator (`--teleop.type=manus_glove`)."""

from .config_manus_glove import ManusGloveConfig
from .manus_glove import ManusGlove

__all__ = ["ManusGlove", "ManusGloveConfig"]
