"""The force board's reader on the host: its serial stream as tared, scaled, deadbanded newtons (the sim's own
`force.reading`). The SEQ is judged against this host's clock (`counter_clock.py`); a board reset keeps the tare
(the HX711s keep their offset). What the host checks and why: docs/force_board.md.
"""

from __future__ import annotations

import logging
import time

import numpy as np

from lerobot_blindgrasp import spec
from lerobot_blindgrasp.hardware import force
from lerobot_blindgrasp.hardware.force_board.counter_clock import CounterClock, FrameVerdict, Restart
from lerobot_blindgrasp.hardware.force_board.frame_codec import Frame, FrameParser, reset_cause_text
from lerobot_blindgrasp.hardware.ports import open_exclusive
from lerobot_blindgrasp.hardware.streams import LatestFrameStream, StreamError

logger = logging.getLogger(__name__)

RECEIVE_TIMEOUT_S = 0.05  # a silent port returns this often, so the reader thread sees a stop request
ADC_RAILS = (0x7FFFFF, -0x800000)  # a 24-bit ADC's full scale: a channel there is saturated, not measuring
BOARD_RATE_HZ = 80.0  # the HX711s' conversions per second with RATE high: one frame each
# The HX711's output settling time after a reset or power-up (50 ms at 80 samples/s), in frames: a board that
# restarted is trusted again only after this many frames advance with time, and it boots silent for at least as long.
SETTLE_FRAMES = 4
MIN_SAMPLES = 5  # a tare or calibration window averages at least this many frames, however short


class ForceStreamError(StreamError):
    """No fresh valid frame, or the microcontroller flags a channel fault."""


class ForceTareError(ValueError):
    """A tare refused because a fingertip pad is loaded (beyond the at-rest envelope); the previous zero is kept.
    Not a safety stop by itself: a re-tare between trials leaves the gripper holding its pose."""


class ForceSensorReader(LatestFrameStream[Frame]):
    """The serial stream (newest frame kept by `LatestFrameStream`'s thread); `read()` returns tared, scaled,
    deadbanded forces in N."""

    name = "Force-sensor"
    error_type = ForceStreamError
    lost_hint = "USB cable unplugged?"

    def __init__(
        self,
        port: str,
        baudrate: int,
        scale_n_per_count,
        *,
        channel_map=(0, 1, 2),
        stale_timeout_s: float = 0.15,
        connect_timeout_s: float = 1.0,
        frozen_frames: int = 0,
        min_rate_hz: float = 0.0,
        rate_hz: float = BOARD_RATE_HZ,
        tare_max_std_n: float = float("inf"),
        tare_max_shift_n: float = float("inf"),
        negative_fault_n: float = float("inf"),
    ):
        super().__init__(port, stale_timeout_s, frozen_frames, min_rate_hz)
        self.tare_max_std_n = tare_max_std_n
        self.tare_max_shift_n = tare_max_shift_n
        self.negative_fault_n = negative_fault_n
        self.tared = False
        self.port = port
        self.baudrate = baudrate
        self.scale = np.asarray(scale_n_per_count, dtype=np.float64)
        self.channel_map = list(channel_map)
        self.connect_timeout_s = connect_timeout_s
        self.offset = np.zeros(len(self.channel_map))
        self.parser = FrameParser()
        self.board_rate_hz = rate_hz
        self.clock = self._new_clock()
        self.seq_ahead = 0  # frames dropped because their SEQ ran ahead of the time that passed
        self._serial = None

    def _new_clock(self) -> CounterClock:
        """The SEQ against this host's clock. Twice the board's rate is as far above it as the slow threshold
        (`min_rate_hz`, half of it) is below: an oscillator errs by percent, a counter that runs faster counts
        something else. The slack is the stale timeout: a frame held up longer leaves the stream stale anyway."""
        return CounterClock(max_rate_hz=2 * self.board_rate_hz, slack_s=self.stale_timeout_s,
                            boot_silence_s=SETTLE_FRAMES / self.board_rate_hz, confirm_frames=SETTLE_FRAMES)  # fmt: skip

    @property
    def dropped_frames(self) -> int:
        """Frames lost on the way: forward SEQ gaps."""
        return self.clock.lost

    @property
    def is_connected(self) -> bool:
        return self._serial is not None

    def connect(self) -> None:
        self.start()
        self.wait_first_frame()

    def wait_first_frame(self) -> None:
        if not self.wait_frames(1, self.connect_timeout_s):
            self.disconnect()
            raise ForceStreamError(
                f"No valid force-sensor frame on '{self.port}' within {self.connect_timeout_s:.1f} s "
                f"({self.parser.garbage_bytes} garbage bytes, {self.parser.crc_errors} CRC errors): "
                "check the cable, the baud rate and the firmware."
            )

    def disconnect(self) -> None:
        self.stop()

    def _open(self) -> None:
        self.clock = self._new_clock()  # a new session: the board may have restarted while the port was closed
        try:
            self._serial = open_exclusive(self.port, self.baudrate, "force-sensor", timeout=RECEIVE_TIMEOUT_S)
        except ConnectionError:
            raise  # PortInUseError: says itself what to do
        except OSError as e:  # pyserial's SerialException is one
            raise ForceStreamError(
                f"Could not open the force-sensor port '{self.port}': {e}. Find the force board's port with "
                "lerobot-find-port and pass --robot.force_sensor.port=..., or install "
                "robot_configs/udev/99-blindgrasp.rules for /dev/blindgrasp_force (docs/bringup.md, section 5)."
            ) from e
        self._serial.reset_input_buffer()

    def _receive(self) -> list[Frame]:
        """What is waiting, and no more than completes the frame in progress: pyserial's `read(n)` returns as soon as
        n bytes are in, so each frame is handed on (and timestamped) the moment its last byte arrives. A fixed
        `read(256)` would wait out the whole timeout on every call, and hand frames on in timed batches."""
        data = self._serial.read(max(self._serial.in_waiting, self.parser.wanted()))
        return self.parser.feed(data) if data else []

    def _close(self) -> None:
        if self._serial is not None:
            try:
                self._serial.close()
            finally:
                self._serial = None

    def _keep(self, frame: Frame, now: float) -> bool:
        cause = reset_cause_text(frame.reset_cause)
        verdict = self.clock.judge(frame.seq, now, frame.reset_cause is not None, cause)
        if verdict is FrameVerdict.LIVE:
            if self.clock.confirmed is not None:
                self._resynchronised(self.clock.confirmed)
            return True
        if verdict is FrameVerdict.AHEAD:
            self.seq_ahead += 1
        elif verdict is not FrameVerdict.HOLD:  # re-sent or replayed: a serial line never reorders frames
            self.counter_faults += 1
        return False

    def _resynchronised(self, r: Restart) -> None:
        """A board reset, confirmed: the rate window restarts (its boot silence is not a slow board), the tare stays."""
        self.reset_rate_window()
        logger.warning(
            "Force board on %s reset (%s): silent for %.0f ms after SEQ %d, its SEQ restarted at %d; resynchronised "
            "after %d frames that advanced with time. The tare is kept (the HX711s keep their offset).",
            self.port, r.cause or "no boot frame; judged by SEQ against time", r.silence_s * 1e3, r.last_seq,
            r.first_seq, SETTLE_FRAMES + 1,
        )  # fmt: skip

    def _content(self, frame: Frame) -> tuple:
        return tuple(frame.counts[c] if c < len(frame.counts) else None for c in self.channel_map)

    def _content_names(self) -> list[str]:
        return list(spec.FORCE_SENSOR_NAMES)

    def _stale_detail(self) -> str:
        out = super()._stale_detail()
        if r := self.clock.resyncing:
            out += (f"; the board reset ({r.cause or 'SEQ ' + str(r.last_seq) + ' -> ' + str(r.first_seq)} after "
                    f"{r.silence_s * 1e3:.0f} ms of silence): resynchronising")  # fmt: skip
        if self.seq_ahead:
            out += (f"; {self.seq_ahead} frames whose SEQ ran further ahead than the time since the last frame allows "
                    f"(> {self.clock.max_rate_hz:g}/s: a corrupted counter)")  # fmt: skip
        return f"{out}; {self.dropped_frames} frames dropped so far"

    def _slow_detail(self) -> str:
        sent = self.clock.seq_rate_hz()
        if sent is not None and sent >= self.min_rate_hz:
            return (f" (the board's SEQ advances at {sent:.0f}/s, so frames are lost on the way: "
                    f"{self.parser.crc_errors} CRC errors, {self.dropped_frames} frames dropped so far)")  # fmt: skip
        return (" (an HX711 with its RATE pin low converts at 10/s: tie RATE to VCC for 80/s, docs/force_board.md; "
                f"{self.dropped_frames} frames dropped so far)")  # fmt: skip

    def _fault(self, frame: Frame) -> str:
        return self.fault_message(frame) if frame.status else ""

    def fault_message(self, frame: Frame) -> str:
        """Which fingertip channels flag a fault, and the likely cause of each (saturated when its counts sit at
        the ADC's full scale, else its ADC stopped converting)."""
        causes = []
        names = dict(zip(self.channel_map, spec.FORCE_SENSOR_NAMES))
        for c in range(len(frame.counts)):
            name = names.get(c, "an unmapped channel")
            if frame.status >> c & 1:
                if frame.counts[c] in ADC_RAILS:
                    causes.append(f"{name} (channel {c}) is saturated at {frame.counts[c]} counts: overload, or a "
                                  "broken load-cell wire")  # fmt: skip
                else:
                    causes.append(f"{name} (channel {c}) stopped converting: its HX711 is unpowered, a DOUT or "
                                  "PD_SCK wire is loose, or its RATE pin is low (10 instead of 80 samples/s)")  # fmt: skip
        causes = causes or ["its bits name channels the frame does not carry (a firmware bug)"]
        return f"Force sensor reports a fault (status {frame.status:#04x}): {'; '.join(causes)}."

    def _channels(self, frame: Frame) -> np.ndarray:
        if max(self.channel_map) >= len(frame.counts):
            raise ForceStreamError(
                f"Force-sensor frames carry {len(frame.counts)} channels, but force_sensor.channel_map "
                f"{self.channel_map} needs channel {max(self.channel_map)}: the firmware and the config disagree."
            )
        return np.array([frame.counts[c] for c in self.channel_map], dtype=np.float64)

    def tare(self, duration_s: float) -> np.ndarray:
        """Zero the sensors: mean counts over `duration_s`, with no fingertip touching anything. Refused
        (`ForceTareError`, the previous zero kept) when a pad is loaded: samples that vary more than an unloaded
        pad does (`tare_max_std_n`), or a re-tare whose zero moved more than drift explains (`tare_max_shift_n`)."""
        samples = np.asarray(self.fresh_samples(duration_s, "during tare", self._channels))
        offset = samples.mean(axis=0)
        std_n = samples.std(axis=0) * np.abs(self.scale)
        shift_n = (offset - self.offset) * self.scale if self.tared else np.zeros_like(offset)
        names = spec.FORCE_SENSOR_NAMES
        loaded = [f"{n} varies by {s:.2f} N (at rest <= {self.tare_max_std_n} N)"
                  for n, s in zip(names, std_n) if s > self.tare_max_std_n]  # fmt: skip
        loaded += [f"{n} reads {d:+.2f} N against the current zero (drift <= {self.tare_max_shift_n} N)"
                   for n, d in zip(names, shift_n) if abs(d) > self.tare_max_shift_n]  # fmt: skip
        if loaded:
            raise ForceTareError(
                f"Tare refused, a fingertip pad is loaded: {'; '.join(loaded)}. The previous zero is kept. Free "
                "the fingertips (nothing touching the pads, gripper still) and tare again."
            )
        self.offset, self.tared = offset, True
        return self.offset

    def fresh_samples(self, duration_s: float, what: str, sample) -> list:
        """`sample(frame)` of every frame over `duration_s` (at least `MIN_SAMPLES`), each passing `fresh()`: a frozen,
        re-sent or faulty stream gives none."""
        samples = []
        deadline = time.monotonic() + duration_s
        while time.monotonic() < deadline or len(samples) < MIN_SAMPLES:
            if not self.wait_frames(1, self.stale_timeout_s * 4):
                raise ForceStreamError(f"Force-sensor stream stopped {what} ({len(samples)} frames).")
            samples.append(sample(self.fresh()))
        return samples

    def read(self) -> np.ndarray:
        counts = self._channels(self.fresh())
        newtons = force.counts_to_newtons(counts, self.offset, self.scale)
        pulling = [
            f"{n} {f:+.2f} N" for n, f in zip(spec.FORCE_SENSOR_NAMES, newtons) if f < -self.negative_fault_n
        ]
        if pulling:
            raise ForceStreamError(
                f"Force sensor reads {pulling}, below -{self.negative_fault_n} N: a fingertip load cell only feels "
                "compression, so this is a fault, not a force (tare taken with a loaded pad, damaged cell, or wrong "
                "sign of scale_n_per_count). Re-tare with the fingertips free."
            )
        return force.reading(newtons)
