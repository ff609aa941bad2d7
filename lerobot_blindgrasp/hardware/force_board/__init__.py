"""The fingertip force board: three HX711 load-cell ADCs on an Arduino Nano, streaming the frames its reader
on the host decodes. Parts, wiring, flashing and the protocol: docs/force_board.md.

    firmware/force_board.c, firmware/Makefile    the firmware (plain avr-libc) and its build
    simavr/hx711_sim.c                           the board in simavr: the firmware's HEX image, emulated HX711
                                                 chips on its pins, its UART on a pseudo-terminal
    build.py                                     `build_firmware(out_dir)`, `build_simulator(out_dir)`, and the
                                                 command `python -m lerobot_blindgrasp.hardware.force_board.build`
    frame_codec.py                               the wire frames: SYNC, SEQ, STATUS, counts, CRC; encoder, parser
    counter_clock.py                             the frame counter judged against the host's clock (reset, replay)
    reader.py                                    `ForceSensorReader`: the port's newest frame as tared newtons
    config_force_board.py                        `ForceSensorConfig`, the gripper's `--robot.force_sensor.*`
    force_calibration.py                         the known-weight fit, the wiring check and the calibration file
    force_calibration_cli.py                     `blindgrasp-calibrate-force`, which asks the operator for them
    (the board in simavr as a device for the tests and the twin: `emulators/force_board_simavr.py`)
"""

from . import force_calibration
from .config_force_board import ForceSensorConfig
from .reader import ForceSensorReader, ForceStreamError, ForceTareError

__all__ = ["ForceSensorConfig", "ForceSensorReader", "ForceStreamError", "ForceTareError", "force_calibration"]
