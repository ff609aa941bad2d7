"""Success rates with their 95 % Wilson score interval, the way every recorded number is reported.

The Wilson interval stays inside [0, 1] and keeps sensible width at 0/n and n/n, where the normal approximation
collapses to a zero-width interval; per-object rates here are often 0/20 or 20/20.
"""

from __future__ import annotations

import math
from collections.abc import Iterable

Z95 = 1.959963984540054  # two-sided 95 % normal quantile


def wilson_interval(successes: int, n: int, z: float = Z95) -> tuple[float, float]:
    """(low, high) of the Wilson score interval for `successes` out of `n` trials; (0, 1) when n == 0."""
    if n < 0 or not 0 <= successes <= n:
        raise ValueError(f"need 0 <= successes <= n, got {successes} of {n}")
    if n == 0:
        return 0.0, 1.0
    p = successes / n
    z2 = z * z
    centre = (p + z2 / (2 * n)) / (1 + z2 / n)
    half = z * math.sqrt(p * (1 - p) / n + z2 / (4 * n * n)) / (1 + z2 / n)
    return max(0.0, centre - half), min(1.0, centre + half)


def format_rate(successes: int, n: int, digits: int = 0) -> str:
    """'65 % [43-82] (13/20)': the rate, its 95 % Wilson interval in percent, and the counts."""
    if n == 0:
        return "n/a (0 episodes)"
    lo, hi = wilson_interval(successes, n)
    return f"{100 * successes / n:.{digits}f} % [{100 * lo:.{digits}f}-{100 * hi:.{digits}f}] ({successes}/{n})"


def count(flags: Iterable) -> tuple[int, int]:
    """(successes, trials) of a sequence of booleans."""
    flags = [bool(f) for f in flags]
    return sum(flags), len(flags)
