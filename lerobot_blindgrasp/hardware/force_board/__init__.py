"""The fingertip force board: three HX711 load-cell ADCs on an Arduino Nano (`firmware/`, its simavr harness in
`simavr/`, built by `build.py`), its frames (`frame_codec.py`, `counter_clock.py`), the host's reader (`reader.py`,
`config_force_board.py`) and its calibration (`force_calibration.py`, `force_calibration_cli.py`). Parts, wiring,
flashing and the protocol: docs/force_board.md."""

from . import force_calibration
from .config_force_board import ForceSensorConfig
from .reader import ForceSensorReader, ForceStreamError, ForceTareError

__all__ = ["ForceSensorConfig", "ForceSensorReader", "ForceStreamError", "ForceTareError", "force_calibration"]
