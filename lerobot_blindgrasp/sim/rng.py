"""Counter-based random numbers over the env axis, on the envs' device. Every draw is a pure function of (env seed,
stream, counter, index), so env i of a batch and a single env with its seed see the same randomness whatever the
batch size, reset order or device. The mixer is SplitMix64 (Steele et al., 2014) on int64 tensors (torch has no
uint64): +, * and ^ wrap to the unsigned bits, and right shifts are made logical by masking."""

from __future__ import annotations

import numpy as np
import torch


def _signed(x: int) -> int:
    """A 64-bit constant as the int64 with the same bits."""
    return x - (1 << 64) if x >= 1 << 63 else x


_GOLDEN = _signed(0x9E3779B97F4A7C15)
_MIX1 = _signed(0xBF58476D1CE4E5B9)
_MIX2 = _signed(0x94D049BB133111EB)
_SEED_MUL = _signed(0xD1B54A32D192ED03)
_COUNTER_MUL = _signed(0x8CB92BA72F3D8DD7)

# Streams: one per kind of draw, so that adding a draw of one kind never shifts another.
STREAM_DR = 1  # per-env physics parameters, drawn once
STREAM_RESET = 2  # joint offsets and object position, per episode
STREAM_OBS_NOISE = 3  # per step
STREAM_PUSH = 4  # external force schedule, per push
# 5: retired (a training-only start-state draw); kept unused so that no other stream changes number
STREAM_SENSOR = 6  # sensor errors beyond Table II (force bias signs, joint calibration signs), drawn once
STREAM_HOLD_PUSH = 7  # direction of the push during the hold, per episode
STREAM_JITTER = 8  # how late each control step's command reaches the servos, per step


def _shr(x: torch.Tensor, k: int) -> torch.Tensor:
    """Logical right shift of 64-bit words held as int64."""
    return (x >> k) & ((1 << (64 - k)) - 1)


def _splitmix64(x: torch.Tensor) -> torch.Tensor:
    # in place on one new tensor: a per-step draw is tens of whole-batch ops, and fresh memory for each costs more
    # on a CPU than the op itself
    z = x + _GOLDEN
    for shift, mul in ((30, _MIX1), (27, _MIX2), (31, None)):
        z ^= torch.bitwise_right_shift(z, shift).bitwise_and_((1 << (64 - shift)) - 1)
        if mul is not None:
            z *= mul
    return z


def as_words(x, device: torch.device | str | None = None) -> torch.Tensor:
    """Seeds or counters as int64 words: a uint64 array keeps its bits; a tensor stays on its device."""
    if isinstance(x, torch.Tensor):
        return x.to(device=device or x.device, dtype=torch.int64)
    a = np.asarray(x)
    if a.dtype == np.uint64:
        a = a.view(np.int64)
    return torch.as_tensor(a.astype(np.int64, copy=False), device=device)


def stream_key(seeds, stream: int) -> torch.Tensor:
    """The per-env key of one stream: what every draw of that stream starts from (an env may keep it)."""
    return _splitmix64(as_words(seeds) * _SEED_MUL + stream)


_OFFSETS: dict[tuple[int, torch.device], torch.Tensor] = {}


def _offsets(n: int, device: torch.device) -> torch.Tensor:
    """index x golden ratio for draws of n numbers, made once per (n, device)."""
    if (n, device) not in _OFFSETS:
        _OFFSETS[n, device] = torch.arange(n, dtype=torch.int64, device=device)[None, :] * _GOLDEN
    return _OFFSETS[n, device]


def uniform(seeds, stream: int, counter, n: int, key: torch.Tensor | None = None) -> torch.Tensor:
    """U[0, 1) float64 draws (len(seeds), n), one row per env, on the seeds' device; `key`: their kept `stream_key`."""
    key = stream_key(seeds, stream) if key is None else key
    counter = as_words(counter, key.device)
    key = _splitmix64(key ^ (counter * _COUNTER_MUL))
    bits = _splitmix64(key[:, None] + _offsets(n, key.device))
    return _shr(bits, 11).to(torch.float64).mul_(1.0 / (1 << 53))


def normal(seeds, stream: int, counter, n: int, key: torch.Tensor | None = None) -> torch.Tensor:
    """Standard normal draws of shape (len(seeds), n) (Box-Muller on two uniform blocks)."""
    u = uniform(seeds, stream, counter, 2 * n, key)
    radius = u[:, :n].clamp_min(1e-300).log_().mul_(-2.0).sqrt_()
    return radius.mul_(u[:, n:].mul(2.0 * np.pi).cos_())


def between(u: torch.Tensor, low, high) -> torch.Tensor:
    return low + (torch.as_tensor(high, dtype=u.dtype, device=u.device) - low) * u


def log_uniform(u: torch.Tensor, low: float, high: float) -> torch.Tensor:
    """Table II writes the gain scales as U[log a, log b]: the scale is exp of that."""
    return torch.exp(np.log(low) + (np.log(high) - np.log(low)) * u)
