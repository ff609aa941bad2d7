"""Success rates with their 95 % Wilson score interval, the way every recorded number is reported: it stays inside
[0, 1] and keeps its width at 0/n and n/n (per-object rates are often 0/20 or 20/20).
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Mapping, Sequence

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


def mcnemar_exact_p(only_a: int, only_b: int) -> float:
    """Two-sided exact McNemar p-value for two policies run on the same start states: `only_a` start states that A
    solved and B did not, `only_b` the reverse. Under "no difference" each is a fair coin, so p is the two-sided
    binomial tail of min(only_a, only_b) of only_a + only_b at 1/2 (with math.comb: scipy is not a dependency)."""
    if only_a < 0 or only_b < 0:
        raise ValueError(f"need non-negative counts, got {only_a} and {only_b}")
    n = only_a + only_b
    if n == 0:
        return 1.0
    tail = sum(math.comb(n, k) for k in range(min(only_a, only_b) + 1)) / 2**n
    return min(1.0, 2 * tail)


def paired_verdict(p: float, alpha: float = 0.05) -> str:
    """How a report reads a paired p-value, in words that cannot be mistaken for the other verdict."""
    if p < alpha:
        return f"below {alpha:g}: the two differ beyond the luck of these start states"
    return f"not below {alpha:g}: no difference beyond the luck of these start states"


def paired_counts(a: Iterable, b: Iterable) -> dict[str, int]:
    """Episodes on the same start states, in order: both succeed, only A, only B, neither."""
    a, b = [bool(x) for x in a], [bool(x) for x in b]
    if len(a) != len(b):
        raise ValueError(f"paired episodes need equal counts, got {len(a)} and {len(b)}")
    pairs = list(zip(a, b, strict=True))
    return {
        "both": sum(x and y for x, y in pairs),
        "a_only": sum(x and not y for x, y in pairs),
        "b_only": sum(y and not x for x, y in pairs),
        "neither": sum(not x and not y for x, y in pairs),
    }


def paired_difference(a: Mapping[str, Sequence], b: Mapping[str, Sequence], keys: Iterable[str]) -> dict:
    """B against A on the same start states, pooled over `keys` (a key missing from a side has no episodes there):
    `paired_counts`, plus `n` episodes, `a_successes`, `b_successes`, `diff_pp` (B minus A, in percentage points)
    and the exact McNemar `p`. ValueError when the two sides do not hold the same number of episodes."""
    keys = list(keys)
    pa = [bool(x) for k in keys for x in a.get(k, [])]
    pb = [bool(x) for k in keys for x in b.get(k, [])]
    p = paired_counts(pa, pb)
    return {
        **p,
        "n": len(pa),
        "a_successes": sum(pa),
        "b_successes": sum(pb),
        "diff_pp": 100 * (sum(pb) - sum(pa)) / max(1, len(pa)),
        "p": mcnemar_exact_p(p["a_only"], p["b_only"]),
    }
