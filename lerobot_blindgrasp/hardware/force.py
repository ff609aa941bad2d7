"""The uniaxial fingertip force reading: one pipeline for the sim and the real load cells (no MuJoCo here).

    signal  = clip(gain x true force + bias + noise, -range, +range)      the cell and its ADC (`load_cell`)
    reading = deadband(signal)                                             the host: |reading| < 0.1 N reads 0

Noise comes before the deadband because on the gripper it is part of the measured counts, which the host can only
tare, scale and threshold; the paper (Sec. III-B) thresholds small magnitudes "to suppress noise", which the
threshold must see. The sim's Gaussian noise (`spec.FORCE_NOISE_STD_N`, Table II) therefore goes through the same
`reading`; the noise-free `reading(true_force)` is what the rewards and demo curation see.
"""

from __future__ import annotations

import numpy as np
import torch

from lerobot_blindgrasp import spec

DEADBAND_N = spec.FORCE_THRESHOLD_N

# Force bias (N, on any one load cell at rest) the shipped student tolerates with margin (`python -m
# lab.robustness.sweep`): beyond it at connect, the sensors need a new tare.
FORCE_BIAS_TOLERANCE_N = 1.0


def _array(x):
    """The sim's torch tensors stay tensors (on their device); the robot's readings become float64 numpy."""
    return x if isinstance(x, torch.Tensor) else np.asarray(x, dtype=np.float64)


def _xp(x):
    return torch if isinstance(x, torch.Tensor) else np


def deadband(force, threshold: float = DEADBAND_N):
    """Magnitudes under the threshold read 0; the rest pass unchanged (no offset step at the threshold)."""
    force = _array(force)
    return _xp(force).where(abs(force) < threshold, 0.0, force)


def reading(true_force, noise=0.0, threshold: float = DEADBAND_N):
    """What a uniaxial fingertip sensor reports for `true_force` (N) and its noise sample (N), numpy (the robot) or
    torch (the sim). On the robot the noise is already inside the measured newtons, so `noise` stays 0."""
    return deadband(_array(true_force) + noise, threshold)


def load_cell(true_force, noise=0.0, gain: float = 1.0, bias=0.0, range_n: float = 0.0):
    """The signal a load cell delivers (N) for `true_force`: its gain and bias errors, its noise sample, and
    saturation at +-`range_n` (0: none). Each error is applied only when set, so the defaults give exactly
    true force + noise. A tensor `bias` is always added (testing it for zeros would wait on its device)."""
    f = _array(true_force)
    if gain != 1.0:
        f = gain * f
    if isinstance(bias, torch.Tensor) or np.any(bias):
        f = f + bias
    f = f + noise
    if range_n > 0:
        f = _xp(f).clip(f, -range_n, range_n)
    return f


def counts_to_newtons(counts, tare_counts, scale_n_per_count) -> np.ndarray:
    """Raw load-cell ADC counts -> newtons: subtract the tare (free-air counts), times the per-channel scale."""
    return (np.asarray(counts, dtype=np.float64) - tare_counts) * np.asarray(scale_n_per_count, dtype=np.float64)


def force_bias_warning(bias_n) -> str | None:
    """A warning for the gripper's connect check when a load cell reads more than the student tolerates at rest
    (fingers in free air, after the tare, N per cell): None when every |bias| is within the tolerance."""
    tolerance_n = FORCE_BIAS_TOLERANCE_N
    bad = {name: float(v) for name, v in zip(spec.FORCE_SENSOR_NAMES, bias_n, strict=True) if abs(v) > tolerance_n}
    if not bad:
        return None
    read = ", ".join(f"{k} {v:+.2f} N" for k, v in bad.items())
    return (
        f"Fingertip force at rest reads {read}, beyond the +-{tolerance_n:g} N bias the shipped student was "
        "measured to tolerate in simulation; re-tare the sensors (fingers in free air) before running a policy."
    )
