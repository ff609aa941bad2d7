"""Counter-based random numbers, vectorized over envs.

Every draw is a pure function of (env seed, stream, counter, index), so env i of a batch and a single env built with
env i's seed see exactly the same randomness, whatever the batch size or the order of resets. A per-env
`np.random.Generator` would need a Python loop over envs on every reset; this needs none.

The mixer is SplitMix64 (Steele et al., 2014), applied to a key built from the inputs.
"""

from __future__ import annotations

import numpy as np

_M64 = np.uint64(0xFFFFFFFFFFFFFFFF)
_GOLDEN = np.uint64(0x9E3779B97F4A7C15)

# Streams: one per kind of draw, so that adding a draw of one kind never shifts another.
STREAM_DR = 1  # per-env physics parameters, drawn once
STREAM_RESET = 2  # joint offsets and object position, per episode
STREAM_OBS_NOISE = 3  # per step
STREAM_PUSH = 4  # external force schedule, per push
# 5: retired (a training-only start-state draw); kept unused so that no other stream changes number
STREAM_SENSOR = 6  # sensor errors beyond Table II (force bias signs, joint calibration signs), drawn once
STREAM_HOLD_PUSH = 7  # direction of the push during the hold, per episode
STREAM_JITTER = 8  # how late each control step's command reaches the servos, per step


def _splitmix64(x: np.ndarray) -> np.ndarray:
    with np.errstate(over="ignore"):
        z = x + _GOLDEN
        z = (z ^ (z >> np.uint64(30))) * np.uint64(0xBF58476D1CE4E5B9)
        z = (z ^ (z >> np.uint64(27))) * np.uint64(0x94D049BB133111EB)
        return z ^ (z >> np.uint64(31))


def uniform(seeds: np.ndarray, stream: int, counter: np.ndarray | int, n: int) -> np.ndarray:
    """U[0, 1) draws of shape (len(seeds), n), one row per env."""
    seeds = np.asarray(seeds, dtype=np.uint64)
    counter = np.broadcast_to(np.asarray(counter, dtype=np.uint64), seeds.shape)
    with np.errstate(over="ignore"):
        key = _splitmix64(seeds * np.uint64(0xD1B54A32D192ED03) + np.uint64(stream))
        key = _splitmix64(key ^ (counter * np.uint64(0x8CB92BA72F3D8DD7)))
        idx = np.arange(n, dtype=np.uint64)[None, :]
        bits = _splitmix64(key[:, None] + idx * _GOLDEN)
    return (bits >> np.uint64(11)).astype(np.float64) * (1.0 / (1 << 53))


def normal(seeds: np.ndarray, stream: int, counter: np.ndarray | int, n: int) -> np.ndarray:
    """Standard normal draws of shape (len(seeds), n) (Box-Muller on two uniform blocks)."""
    u = uniform(seeds, stream, counter, 2 * n)
    u1 = np.maximum(u[:, :n], 1e-300)
    return np.sqrt(-2.0 * np.log(u1)) * np.cos(2.0 * np.pi * u[:, n:])


def between(u: np.ndarray, low, high) -> np.ndarray:
    return low + (np.asarray(high) - low) * u


def log_uniform(u: np.ndarray, low: float, high: float) -> np.ndarray:
    """Table II writes the gain scales as U[log a, log b]: the scale is exp of that."""
    return np.exp(np.log(low) + (np.log(high) - np.log(low)) * u)
