"""The glove datagram (`blindgrasp-glove/2`): one UDP datagram per glove frame, UTF-8 JSON, from a bridge next to
the MANUS SDK. docs/glove.md, "The datagram", defines each field and what is checked:

    {"proto": "blindgrasp-glove/2", "session": "9f1c2a7d03b4e8aa", "seq": 1234, "sent": 81234.5678,
     "side": "right", "ergonomics": {"ThumbMCPSpread": 25.0, "IndexMCPSpread": 2.0, "IndexMCPStretch": 5.0, ...}}

`sent` is the bridge machine's system-wide monotonic clock, never wall time (which NTP may step). The sender's end
(`encode`, `GloveSender`) lives in the one-file `manus_bridge.py`, so sender and receiver share one definition.
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass

from .manus_bridge import PROTO, SESSION_RE, SIDES, GloveSender, canonical, encode

__all__ = ["MAX_ABS_DEG", "PROTO", "DatagramError", "GloveDatagram", "GloveSender", "decode", "encode"]
MAX_ABS_DEG = 360.0


class DatagramError(ValueError):
    """A datagram that is not a complete, sane message of this protocol. `missing`: the required channels it
    lacks, when that is the reason."""

    def __init__(self, reason: str, missing: frozenset[str] = frozenset()):
        super().__init__(reason)
        self.missing = missing


@dataclass(frozen=True)
class GloveDatagram:
    session: str
    seq: int
    sent: float  # sender's monotonic clock (s)
    side: str
    ergonomics: dict[str, float]  # by channel name (manus_bridge.CHANNELS), the required channels only


def _number(value) -> float:
    # JSON also yields bools, strings, lists, NaN, Infinity and integers too large for a float.
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise DatagramError(f"not a number: {value!r:.40}")
    try:
        out = float(value)
    except OverflowError as e:
        raise DatagramError("number too large") from e
    if not math.isfinite(out):
        raise DatagramError(f"non-finite number {out}")
    return out


def _header(msg: dict) -> tuple[str, int, float, str]:
    side = msg.get("side")
    if side not in SIDES:
        raise DatagramError(f"side {side!r:.40} is not 'left' or 'right'")
    session = msg.get("session")
    if not isinstance(session, str) or not SESSION_RE.fullmatch(session):
        raise DatagramError(f"session {session!r:.40} is not 1-64 characters of [0-9A-Za-z_-]")
    seq = msg.get("seq")
    if isinstance(seq, bool) or not isinstance(seq, int) or not 0 <= seq < 2**32:
        raise DatagramError(f"seq {seq!r:.40} is not a uint32")
    try:
        sent = _number(msg.get("sent"))
    except DatagramError as e:
        raise DatagramError(f"sent (the bridge's send time): {e}") from None
    return session, seq, sent, side


def decode(datagram: bytes, required: set[str]) -> GloveDatagram:
    """Raises DatagramError on anything that is not a complete, sane message of this protocol."""
    try:
        msg = json.loads(datagram.decode("utf-8"))
    except (UnicodeDecodeError, ValueError, RecursionError) as e:
        raise DatagramError(f"not JSON: {e}") from e
    proto = msg.get("proto") if isinstance(msg, dict) else None
    if proto == "blindgrasp-glove/1":  # ordered by arrival, the fault version 2 fixes: refused, with why
        raise DatagramError("protocol blindgrasp-glove/1 (no session, no sender clock): update the bridge to "
                            f"{PROTO} (blindgrasp-glove-bridge, docs/glove.md)")  # fmt: skip
    if proto != PROTO:
        raise DatagramError(f"not a {PROTO} message")
    session, seq, sent, side = _header(msg)
    ergo = msg.get("ergonomics")
    if not isinstance(ergo, dict):
        raise DatagramError("ergonomics is not an object")
    by_channel, problems = canonical(ergo, side)
    if problems:
        raise DatagramError("; ".join(problems[:3]))
    missing = frozenset(required - by_channel.keys())
    if missing:
        raise DatagramError(f"ergonomics lacks {sorted(missing)}", missing)
    values = {k: _number(by_channel[k]) for k in required}
    if any(abs(v) > MAX_ABS_DEG for v in values.values()):
        raise DatagramError("ergonomics value out of range")
    return GloveDatagram(session, seq, sent, side, values)
