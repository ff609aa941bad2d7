"""Manus glove teleoperator: absolute gripper joint targets from the operator's hand, at the recording rate.

The action is q_glove, the retargeted hand pose, under the robot's action keys. With the shared action contract
(absolute targets) this is the paper's a_t = q_glove - q_robot once the policy's processor subtracts the state.
"""

from __future__ import annotations

import logging
import time
from dataclasses import dataclass
from functools import cached_property
from pathlib import Path

import draccus
import numpy as np
from lerobot.teleoperators.teleoperator import Teleoperator
from lerobot.utils.decorators import check_if_already_connected, check_if_not_connected
from lerobot.utils.errors import DeviceNotConnectedError

from lerobot_blindgrasp import spec

from . import retarget as rt
from .config_manus_glove import ManusGloveConfig
from .stream import GloveReceiver

logger = logging.getLogger(__name__)


@dataclass
class GloveCalibration:
    """Glove ergonomics (deg) of one operator in the two reference poses, per ergonomics channel."""

    open: dict[str, float]
    fist: dict[str, float]


class GloveStreamLost(DeviceNotConnectedError):
    """No glove datagram for longer than `disconnect_timeout_s`."""


class ManusGlove(Teleoperator):
    config_class = ManusGloveConfig
    name = "manus_glove"

    def __init__(self, config: ManusGloveConfig):
        super().__init__(config)  # loads the calibration file through our _load_calibration, if there is one
        if not isinstance(self.calibration, GloveCalibration):
            self.calibration: GloveCalibration | None = None
        self.config = config
        self.receiver = GloveReceiver(config.host, config.port, config.side, rt.REQUIRED_KEYS)
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
        with open(fpath or self.calibration_fpath) as f, draccus.config_type("json"):
            self.calibration = draccus.load(GloveCalibration, f)

    def _save_calibration(self, fpath: Path | None = None) -> None:
        with open(fpath or self.calibration_fpath, "w") as f, draccus.config_type("json"):
            draccus.dump(self.calibration, f, indent=4)

    @check_if_already_connected
    def connect(self, calibrate: bool = True) -> None:
        self.receiver.open()
        if not self.receiver.wait_frames(1, self.config.connect_timeout_s):
            self.receiver.close()
            raise ConnectionError(
                f"No glove data on udp://{self.config.host}:{self.config.port} for the {self.config.side} hand "
                f"within {self.config.connect_timeout_s:.1f} s ({self.receiver.rejected} datagrams rejected): "
                "is the SDK bridge running?"
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
            samples.append(self.receiver.latest().ergonomics)
        return {k: float(np.mean([s[k] for s in samples])) for k in sorted(rt.REQUIRED_KEYS)}

    @check_if_not_connected
    def calibrate(self) -> None:
        input("Glove calibration. OPEN HAND: fingers straight and together, thumb alongside; hold, press ENTER: ")
        open_pose = self._average(self.config.calibration_s)
        input("FIST: close the hand fully, thumb over the fingers; hold it and press ENTER: ")
        fist_pose = self._average(self.config.calibration_s)
        open_f = rt.glove_features(open_pose)
        fist_f = rt.glove_features(fist_pose)
        weak = [j for j, flex, o, f in zip(spec.JOINT_NAMES, rt.IS_FLEX, open_f, fist_f, strict=True)
                if flex and abs(f - o) < self.config.min_flex_range_deg]
        if weak:
            raise ValueError(
                f"Flexion for {weak} changed by less than {self.config.min_flex_range_deg} deg between open hand "
                "and fist: check the glove fit and calibrate again."
            )
        self.calibration = GloveCalibration(open=open_pose, fist=fist_pose)
        self._save_calibration()
        logger.info("Glove calibration saved to %s", self.calibration_fpath)

    @check_if_not_connected
    def get_action(self) -> dict[str, float]:
        if self.calibration is None:
            raise RuntimeError(f"{self} is not calibrated: run lerobot-calibrate --teleop.type=manus_glove first.")
        frame = self.receiver.latest()
        age = time.monotonic() - frame.received
        if age > self.config.disconnect_timeout_s:
            raise GloveStreamLost(
                f"Glove stream lost: no datagram for {age:.2f} s (limit {self.config.disconnect_timeout_s} s). "
                "Stopping teleoperation; the robot's cleanup turns its torque off."
            )
        if age > self.config.hold_timeout_s and self._last_target is not None:
            if not self._holding:
                logger.warning("Glove data %.0f ms old: holding the last target (motion stops).", age * 1e3)
                self._holding = True
            target = self._last_target
        else:
            self._holding = False
            c = self.calibration
            keys = sorted(rt.REQUIRED_KEYS)
            target = rt.retarget(
                rt.glove_features(frame.ergonomics),
                rt.glove_features({k: c.open[k] for k in keys}),
                rt.glove_features({k: c.fist[k] for k in keys}),
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
        self.receiver.close()
        logger.info("%s disconnected.", self)
