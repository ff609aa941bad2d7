"""What a broken or hostile sender puts on a line, as hypothesis strategies: the fuzz tests of every decoder share
them (status packets, force frames, glove datagrams, calibration files)."""

from __future__ import annotations

from hypothesis import settings
from hypothesis import strategies as st

FAST = settings(max_examples=100, deadline=None)
INT32 = st.integers(-(2**31), 2**31 - 1)
json_values = st.recursive(
    st.none() | st.booleans() | st.integers() | st.floats() | st.text(max_size=8),
    lambda children: st.lists(children, max_size=4) | st.dictionaries(st.text(max_size=8), children, max_size=4),
    max_leaves=12,
)


def chunks(parts: list[bytes], cuts: list[int]) -> bytes:
    """`parts` joined, the first ones cut to `cuts` bytes (-1: whole): truncated messages between whole ones."""
    return b"".join(p[: c if c >= 0 else len(p)] for p, c in zip(parts, cuts + [-1] * len(parts)))
