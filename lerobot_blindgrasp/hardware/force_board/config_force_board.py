"""The force board's settings on the host (`--robot.force_sensor.*` of the gripper)."""

from __future__ import annotations

from dataclasses import dataclass, field

from .reader import ForceSensorReader


@dataclass
class ForceSensorConfig:
    """The fingertip load-cell board: its port, the scales until a calibration file replaces them, and the thresholds
    its reader (`reader.py`) stops on."""

    # The Nano's serial port (ttyUSB1 with the U2D2 plugged in first; robot_configs use /dev/blindgrasp_force).
    port: str = "/dev/ttyUSB1"
    baudrate: int = 115_200
    # N per raw count per fingertip (`spec.FORCE_SENSOR_NAMES` order), a push positive: a placeholder of an HX711's
    # order of magnitude until `blindgrasp-calibrate-force` measures yours (its file replaces these at connect).
    scale_n_per_count: list[float] = field(default_factory=lambda: [2.5e-5, 2.5e-5, 2.5e-5])
    # Which stream channel feeds ff_tip, mf_tip, th_tip (wiring can differ from the firmware's order).
    channel_map: list[int] = field(default_factory=lambda: [0, 1, 2])
    # Tare window at connect (fingers must touch nothing). The HX711 board streams at ~80 frames/s.
    tare_s: float = 0.5
    # A reading older than this is stale: the gripper stops (3 control periods at 20 Hz).
    stale_timeout_s: float = 0.15
    # Fewer fresh frames per second than this is a slow stream (stop): 2 samples per 20 Hz control period.
    min_rate_hz: float = 40.0
    # First frame after the port opens. Opening it resets an Arduino Nano (DTR): its bootloader waits ~1 s, then
    # the HX711s settle (~0.1 s at 80/s).
    connect_timeout_s: float = 3.0
    # A tip force above this stops the gripper: below the 10 kg cells' 98 N rating (a straight finger is a strut the
    # servos' torque does not cap) and above any grasp's peak. No grip-force limit: lower current_limit_a for that.
    overload_n: float = 80.0
    # Liveness by content: a channel whose raw counts repeat bit for bit for this many frames in a row is frozen
    # (a load cell's ADC noise never does that), and the stream is stale. 0 disables the check.
    frozen_frames: int = 10
    # The at-rest envelope of a tare: per-channel standard deviation over the tare window, and how far a re-tare
    # may move the zero (drift between trials). Beyond either, a pad is loaded and the tare is refused.
    tare_max_std_n: float = 1.0
    tare_max_shift_n: float = 1.0
    # A compressive-only load cell reading below -this (N) is a fault (stop), not a value.
    negative_fault_n: float = 1.0

    def reader(self, scale_n_per_count=None) -> ForceSensorReader:
        """The board's reader with these settings (`scale_n_per_count` replaces the config's when given)."""
        scale = self.scale_n_per_count if scale_n_per_count is None else scale_n_per_count
        return ForceSensorReader(self.port, self.baudrate, scale, channel_map=self.channel_map,
                                 stale_timeout_s=self.stale_timeout_s, connect_timeout_s=self.connect_timeout_s,
                                 frozen_frames=self.frozen_frames, min_rate_hz=self.min_rate_hz,
                                 tare_max_std_n=self.tare_max_std_n, tare_max_shift_n=self.tare_max_shift_n,
                                 negative_fault_n=self.negative_fault_n)  # fmt: skip
