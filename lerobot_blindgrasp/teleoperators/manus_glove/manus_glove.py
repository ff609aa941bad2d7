"""Manus glove teleoperator: absolute gripper joint targets from the operator's hand, at the recording rate.

The action is q_glove, the retargeted hand pose, under the robot's action keys. With the shared action contract
(absolute targets) this is the paper's a_t = q_glove - q_robot once the policy's processor subtracts the state.
"""

from __future__ import annotations

import dataclasses
import logging
import math
import time
from functools import cached_property
from pathlib import Path

import numpy as np
from lerobot.teleoperators.teleoperator import Teleoperator
from lerobot.utils.decorators import check_if_already_connected, check_if_not_connected
from lerobot.utils.errors import DeviceNotConnectedError

from lerobot_blindgrasp import durable, spec
from lerobot_blindgrasp.robots.blindgrasp_gripper.servo_calibration import read_raw as read_json

from . import retarget as rt
from .config_manus_glove import ManusGloveConfig
from .manus_bridge import canonical
from .receiver import GloveReceiver

logger = logging.getLogger(__name__)


@dataclasses.dataclass
class GloveCalibration:
    """Glove ergonomics (deg) of one operator in the two reference poses, per ergonomics channel."""

    open: dict[str, float]
    fist: dict[str, float]


class GloveStreamLost(DeviceNotConnectedError):
    """No glove datagram for longer than `disconnect_timeout_s`."""


class GloveCalibrationError(ValueError):
    """A glove calibration (recorded now or loaded from a file) that would map the hand wrongly or to NaN."""


def calibration_schema_problems(raw: object) -> list[str]:
    """The file's shape on the raw JSON: exactly {"open": {...}, "fist": {...}}, each pose an object of channel name
    -> number (a bool or a string is not a number, whatever a lenient decoder would make of it)."""
    if not isinstance(raw, dict) or set(raw) != {"open", "fist"}:
        keys = sorted(raw) if isinstance(raw, dict) else type(raw).__name__
        return [f"expected exactly the poses ['fist', 'open'], found {keys}"]
    out = []
    for name in ("open", "fist"):
        pose = raw[name]
        if not isinstance(pose, dict):
            out.append(f"{name} pose is {type(pose).__name__}, not an object")
            continue
        wrong = [k for k, v in pose.items() if isinstance(v, bool) or not isinstance(v, (int, float))]
        if wrong:
            out.append(f"{name} pose has non-numbers at {sorted(wrong)[:5]}")
    return out


def calibration_problems(open_pose: dict, fist_pose: dict, min_flex_range_deg: float,
                         required: set[str] = rt.REQUIRED_KEYS) -> list[str]:  # fmt: skip
    """The rules of `ManusGlove.calibrate()`, also applied to a loaded file: every channel the retargeting uses,
    finite values, and open hand and fist distinct by `min_flex_range_deg` on every flexion joint (equal poses would
    divide by zero in the retargeting)."""
    keys = sorted(required)
    out = []
    for name, pose in (("open", open_pose), ("fist", fist_pose)):
        missing = [k for k in keys if k not in pose]
        bad = [k for k in keys if k in pose and not (isinstance(pose[k], (int, float)) and math.isfinite(pose[k]))]
        if missing:
            out.append(f"{name} pose lacks {missing}")
        if bad:
            out.append(f"{name} pose has non-finite {bad}")
    if out:
        return out
    open_f, fist_f = rt.glove_features(open_pose, required), rt.glove_features(fist_pose, required)
    weak = [j for j, flex, o, f in zip(spec.JOINT_NAMES, rt.IS_FLEX, open_f, fist_f, strict=True)
            if flex and abs(f - o) < min_flex_range_deg]  # fmt: skip
    if weak:
        out.append(f"flexion for {weak} changed by less than {min_flex_range_deg} deg between open hand and fist")
    return out


class ManusGlove(Teleoperator):
    config_class = ManusGloveConfig
    name = "manus_glove"

    def __init__(self, config: ManusGloveConfig):
        self.config = config
        self.required = rt.required_keys(config.spread_gain)  # the channels the retargeting reads
        self.calibration_error: GloveCalibrationError | None = None
        super().__init__(config)  # loads the calibration file through our _load_calibration, if there is one
        if not isinstance(self.calibration, GloveCalibration):
            self.calibration: GloveCalibration | None = None
        self.receiver = GloveReceiver(config.host, config.port, config.side, self.required, config.hold_timeout_s,
                                      sender=config.sender_address(), frozen_frames=config.frozen_frames,
                                      max_latency_s=config.max_latency_s)  # fmt: skip
        self._last_target: np.ndarray | None = None
        self._holding = False

    @cached_property
    def action_features(self) -> dict[str, type]:
        return dict.fromkeys(spec.ACTION_NAMES, float)

    @cached_property
    def feedback_features(self) -> dict:
        return {}

    @property
    def is_connected(self) -> bool:
        return self.receiver.is_open

    @property
    def is_calibrated(self) -> bool:
        return self.calibration is not None

    def _load_calibration(self, fpath: Path | None = None) -> None:
        """Load and check the file by `calibrate()`'s rules; a bad one is refused by `connect()`, and
        lerobot-calibrate (connect(calibrate=False), then calibrate()) replaces it."""
        fpath = fpath or self.calibration_fpath
        try:
            raw = read_json(fpath)
            bad = calibration_schema_problems(raw)
            if not bad:  # keyed by channel, whichever accepted name the file used (e.g. the ROS 2 IndexSpread)
                (open_pose, p1), (fist_pose, p2) = (canonical(raw[k], self.config.side) for k in ("open", "fist"))
                cal, bad = GloveCalibration(open_pose, fist_pose), p1 + p2
                bad = bad or calibration_problems(
                    cal.open, cal.fist, self.config.min_flex_range_deg, self.required
                )
        except Exception as e:  # unreadable: empty, truncated, not JSON, not UTF-8
            bad = [f"unreadable ({type(e).__name__}: {e})"]
        if bad:
            self.calibration = None
            self.calibration_error = GloveCalibrationError(
                f"Glove calibration file {fpath} is invalid: {'; '.join(bad)}. Run lerobot-calibrate "
                f"--teleop.type={self.name} --teleop.id={self.id} to replace it."
            )
            logger.error("%s", self.calibration_error)
            return
        self.calibration_error = None
        self.calibration = cal

    def _save_calibration(self, fpath: Path | None = None) -> None:
        # Atomic: a failed save (a full disk) keeps the previous calibration and says why (durable.WriteError).
        durable.atomic_write_json(fpath or self.calibration_fpath, dataclasses.asdict(self.calibration), indent=4)

    @check_if_already_connected
    def connect(self, calibrate: bool = True) -> None:
        if self.calibration_error is not None and calibrate:
            raise self.calibration_error
        self.receiver.start()
        if not self.receiver.wait_frames(1, self.config.connect_timeout_s):
            self.receiver.stop()
            raise ConnectionError(
                f"No glove data on udp://{self.config.host}:{self.config.port} for the {self.config.side} hand "
                f"within {self.config.connect_timeout_s:.1f} s: {self.receiver.diagnosis()}."
            )
        if not self.is_calibrated and calibrate:
            self.calibrate()
        self.configure()
        logger.info("%s connected.", self)

    def configure(self) -> None:
        self._last_target = None
        self._holding = False

    def _average(self, seconds: float) -> dict[str, float]:
        samples: list[dict[str, float]] = []
        deadline = time.monotonic() + seconds
        while time.monotonic() < deadline or not samples:
            if not self.receiver.wait_frames(1, self.config.hold_timeout_s * 4):
                raise ConnectionError("The glove stream stopped during calibration.")
            samples.append(self.receiver.latest()[0].ergonomics)
        return {k: float(np.mean([s[k] for s in samples])) for k in sorted(self.required)}

    @check_if_not_connected
    def calibrate(self) -> None:
        input("Glove calibration. OPEN HAND: fingers straight and together, thumb alongside; hold, press ENTER: ")
        open_pose = self._average(self.config.calibration_s)
        input("FIST: close the hand fully, thumb over the fingers; hold it and press ENTER: ")
        fist_pose = self._average(self.config.calibration_s)
        bad = calibration_problems(open_pose, fist_pose, self.config.min_flex_range_deg, self.required)
        if bad:
            raise GloveCalibrationError(f"Glove calibration refused: {'; '.join(bad)}. Check the glove fit and "
                                        "calibrate again.")  # fmt: skip
        self.calibration = GloveCalibration(open=open_pose, fist=fist_pose)
        self.calibration_error = None
        self._save_calibration()
        logger.info("Glove calibration saved to %s", self.calibration_fpath)

    @check_if_not_connected
    def get_action(self) -> dict[str, float]:
        if self.calibration is None:
            raise RuntimeError(f"{self} is not calibrated: run lerobot-calibrate --teleop.type=manus_glove first.")
        frame, age = self.receiver.latest()
        if age > self.config.disconnect_timeout_s:
            raise GloveStreamLost(
                f"Glove stream lost: no usable datagram for {age:.2f} s (limit {self.config.disconnect_timeout_s} s; "
                f"{self.receiver.diagnosis()}). Stopping teleoperation; the robot's cleanup turns its torque off."
            )
        if age > self.config.hold_timeout_s and self._last_target is not None:
            if not self._holding:
                logger.warning("Glove data %.0f ms old: holding the last target (motion stops).", age * 1e3)
                self._holding = True
            target = self._last_target
        else:
            self._holding = False
            c = self.calibration
            target = rt.retarget(
                rt.glove_features(frame.ergonomics, self.required),
                rt.glove_features(c.open, self.required),
                rt.glove_features(c.fist, self.required),
                np.asarray(self.config.open_pose),
                np.asarray(self.config.closed_pose),
                np.asarray(self.config.spread_gain),
            )
            self._last_target = target
        return {name: float(v) for name, v in zip(spec.ACTION_NAMES, target, strict=True)}

    def send_feedback(self, feedback: dict) -> None:
        pass

    @check_if_not_connected
    def disconnect(self) -> None:
        self.receiver.stop()
        logger.info("%s disconnected.", self)
