"""Force calibration (docs/force_board.md, "Calibration"): per fingertip, scale = mass x g / (loaded - unloaded mean
counts) in N/count (a push reads positive) and offset = the unloaded mean; the loaded pad's channel must respond
most, so a swapped cable is named before anything is saved. At connect (`apply`) the file `<robot id>.force.json`
replaces the config's scales, and refuses a channel_map other than the one it was measured with.
"""

from __future__ import annotations

import dataclasses
import json
import logging
import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from lerobot_blindgrasp import durable, spec

logger = logging.getLogger(__name__)

FORMAT = "blindgrasp-force-calibration"
VERSION = 1
STANDARD_GRAVITY = 9.80665
SUFFIX = ".force.json"  # <robot id>.force.json, next to the servo calibration <robot id>.json


class ForceCalibrationError(ValueError):
    """The calibration cannot be trusted (wiring, response, noise) or its file is unusable; the message says why
    and what to do."""


@dataclass(frozen=True)
class Window:
    """Raw counts of every stream channel over a sampling window (all frames' channels, not only the mapped)."""

    mean: np.ndarray
    std: np.ndarray
    frames: int

    @classmethod
    def of(cls, samples) -> Window:
        a = np.asarray(samples, dtype=np.float64)
        return cls(mean=a.mean(axis=0), std=a.std(axis=0), frames=len(a))


@dataclass
class FingerCalibration:
    channel: int  # stream channel the finger's cell is wired to (= channel_map entry, verified)
    scale_n_per_count: float
    offset_counts: float
    noise_n: float  # at-rest standard deviation, N
    response_counts: float  # counts the weight moved the channel


@dataclass
class ForceCalibration:
    mass_kg: float
    g: float
    channel_map: list[int]
    fingers: dict[str, FingerCalibration]

    def scales(self) -> list[float]:
        return [self.fingers[n].scale_n_per_count for n in spec.FORCE_SENSOR_NAMES]

    def offsets(self) -> list[float]:
        return [self.fingers[n].offset_counts for n in spec.FORCE_SENSOR_NAMES]


def _suggested_map(channel_map: list[int], finger: int, channel: int) -> list[int]:
    """channel_map with finger `finger` on `channel`, and the finger that had `channel` on the freed one."""
    out = list(channel_map)
    if channel in out:
        out[out.index(channel)] = out[finger]
    out[finger] = channel
    return out


def check_response(
    finger: int, channel_map: list[int], unloaded: Window, loaded: Window, min_snr: float, max_crosstalk: float
) -> float:
    """The counts the weight on `finger`'s pad moved its channel; ForceCalibrationError when the wrong channel, no
    channel, or more than one channel responded."""
    names = spec.FORCE_SENSOR_NAMES
    name, wired = names[finger], channel_map[finger]
    delta = loaded.mean - unloaded.mean
    noise = np.maximum(unloaded.std, 1.0)  # a count is the resolution even when the window read one value
    main = int(np.argmax(np.abs(delta) / noise))
    if abs(delta[main]) < min_snr * noise[main]:
        raise ForceCalibrationError(
            f"No channel responded to the weight on {name}: the largest change, channel {main} by "
            f"{delta[main]:+.0f} counts, is under {min_snr:g} x its at-rest noise ({noise[main]:.0f} counts). Is the "
            f"weight resting on the {name} pad alone, is that cell wired to the board, and is the weight heavy enough?"
        )
    if main != wired:
        owner = names[channel_map.index(main)] if main in channel_map else None
        other = f"which channel_map assigns to {owner}" if owner else "which no finger is mapped to"
        swap = f"the {name} and {owner} cables are swapped on the board" if owner else f"{name}'s cable is on it"
        raise ForceCalibrationError(
            f"Wiring: the weight on {name} moved channel {main} ({delta[main]:+.0f} counts), {other}; "
            f"channel_map puts {name} on channel {wired}. So {swap}, or channel_map is wrong. Swap the cables back, "
            f"or pass --robot.force_sensor.channel_map={_suggested_map(channel_map, finger, main)}, and calibrate "
            "again. Nothing was saved."
        )
    for j in range(len(delta)):
        if j != main and abs(delta[j]) >= min_snr * noise[j] and abs(delta[j]) > max_crosstalk * abs(delta[main]):
            owner = names[channel_map.index(j)] if j in channel_map else f"unmapped channel {j}"
            raise ForceCalibrationError(
                f"The weight on {name} moved channel {main} by {delta[main]:+.0f} counts and also channel {j} "
                f"({owner}) by {delta[j]:+.0f} counts, more than {max_crosstalk:.0%} of it: the pads touch each "
                "other or the weight rests on two of them, or the cells share a wire. Nothing was saved."
            )
    return float(delta[main])


def fit(
    channel_map: list[int],
    unloaded_before: Window,
    loaded: list[Window],
    unloaded_after: Window,
    mass_kg: float,
    g: float = STANDARD_GRAVITY,
    *,
    min_snr: float = 20.0,
    max_crosstalk: float = 0.1,
    max_zero_shift_n: float = 0.5,
) -> ForceCalibration:
    """Scale and offset per fingertip from the unloaded windows and one loaded window per finger (the weight
    moved from pad to pad, each loading compared with the unloaded mean before the first)."""
    if not (mass_kg > 0 and math.isfinite(mass_kg) and g > 0):
        raise ForceCalibrationError(f"mass_kg must be a positive mass (got {mass_kg}) and g positive (got {g})")
    fingers = {}
    for k, name in enumerate(spec.FORCE_SENSOR_NAMES):
        c = channel_map[k]
        response = check_response(k, channel_map, unloaded_before, loaded[k], min_snr, max_crosstalk)
        scale = mass_kg * g / response
        offset = (unloaded_before.mean[c] + unloaded_after.mean[c]) / 2
        shift_n = (unloaded_after.mean[c] - unloaded_before.mean[c]) * scale
        if abs(shift_n) > max_zero_shift_n:
            raise ForceCalibrationError(
                f"{name} did not come back to its zero once the weight was off: {shift_n:+.2f} N against the start "
                f"(at most {max_zero_shift_n} N): the cell creeps, the pad rubs on something, or the weight was "
                "still touching. Fix the mount and calibrate again. Nothing was saved."
            )
        noise_n = float(max(unloaded_before.std[c], unloaded_after.std[c]) * abs(scale))
        fingers[name] = FingerCalibration(c, float(scale), float(offset), noise_n, response)
    return ForceCalibration(float(mass_kg), float(g), list(channel_map), fingers)


def path_for(calibration_dir, robot_id: str) -> Path:
    return Path(calibration_dir) / f"{robot_id}{SUFFIX}"


def is_force_calibration(path) -> bool:
    """Whether a file in the calibration folder is a force calibration (not a servo calibration `<id>.json`)."""
    return Path(path).name.endswith(SUFFIX)


def missing_warning(path, robot_id: str, scales) -> str:
    """What connect says when the robot has no force calibration: forces in newtons then rest on the config's
    `scale_n_per_count`, a placeholder of the right order of magnitude unless someone measured these cells."""
    return (
        f"No force calibration for robot id '{robot_id}' ({path}): the fingertip forces use the config's "
        f"force_sensor.scale_n_per_count {[f'{s:.3g}' for s in scales]} N/count, a placeholder unless measured on "
        "these cells, so forces in newtons (and the overload stop) may be off by about a factor of two, or of the "
        "wrong sign where a bridge is wired the other way round. Weigh the cells once, with the force board "
        'plugged in:\n    blindgrasp-calibrate-force --robot="include robot_configs/blindgrasp_gripper.yaml" '
        f"--robot.id={robot_id} --mass_kg=0.5\n(docs/force_board.md, Calibration)."
    )


def save_force_calibration(calibration: ForceCalibration, path) -> Path:
    record = {"format": FORMAT, "version": VERSION, **dataclasses.asdict(calibration)}
    return durable.atomic_write_json(path, record, indent=2)


def load_force_calibration(path) -> ForceCalibration:
    """The calibration in `path`; ForceCalibrationError naming the file and the problem when it is unusable."""
    try:
        raw = json.loads(Path(path).read_text(encoding="utf-8"))
        if raw.get("format") != FORMAT or raw.get("version") != VERSION:
            raise ValueError(f"not a {FORMAT} file of version {VERSION}")
        fingers = {n: FingerCalibration(**raw["fingers"][n]) for n in spec.FORCE_SENSOR_NAMES}
        cal = ForceCalibration(
            float(raw["mass_kg"]), float(raw["g"]), [int(c) for c in raw["channel_map"]], fingers
        )
    except (OSError, ValueError, KeyError, TypeError, AttributeError) as e:
        raise ForceCalibrationError(
            f"Force calibration file {path} is unusable ({type(e).__name__}: {e}). Run blindgrasp-calibrate-force "
            "again, or delete the file to use force_sensor.scale_n_per_count."
        ) from e
    bad = [n for n, f in cal.fingers.items() if not (math.isfinite(f.scale_n_per_count) and f.scale_n_per_count)]
    bad += [n for n, f in cal.fingers.items() if f.channel != cal.channel_map[spec.FORCE_SENSOR_NAMES.index(n)]]
    if bad:
        raise ForceCalibrationError(
            f"Force calibration file {path} has unusable entries for {bad}: calibrate again."
        )
    return cal


def apply(reader, calibration_dir, robot_id: str) -> ForceCalibration | None:
    """Give `reader` the scales and zero of the robot's force calibration file; None when there is none (the
    config's scales stay, with a warning naming the command that measures them)."""
    path = path_for(calibration_dir, robot_id)
    if not path.is_file():
        logger.warning(missing_warning(path, robot_id, reader.scale))
        return None
    cal = load_force_calibration(path)
    if list(reader.channel_map) != cal.channel_map:
        raise ForceCalibrationError(
            f"Force calibration {path} was measured with channel_map {cal.channel_map}, but the config has "
            f"{list(reader.channel_map)}: the scales would go to the wrong fingers. Run blindgrasp-calibrate-force "
            "with the new channel_map, or restore the old one."
        )
    reader.scale = np.asarray(cal.scales(), dtype=np.float64)
    reader.offset = np.asarray(cal.offsets(), dtype=np.float64)
    logger.info("Force scales %s N/count from %s.", [f"{s:.4g}" for s in cal.scales()], path)
    return cal
