"""The glove datagram: one UDP datagram per glove frame, UTF-8 JSON, from a bridge next to the MANUS SDK.

    {"proto": "blindgrasp-glove/2", "session": "9f1c2a7d03b4e8aa", "seq": 1234, "sent": 81234.5678,
     "side": "right", "ergonomics": {"ThumbMCPSpread": 25.0, "IndexMCPSpread": 2.0, "IndexMCPStretch": 5.0, ...}}

- `session`: a random id the bridge draws when it starts (1-64 characters of [0-9A-Za-z_-]). A new id is a
  restarted bridge; datagrams of an earlier id arriving later are old and dropped.
- `seq`: the bridge's frame counter in this session, from 1, +1 per datagram (uint32). The receiver keeps only
  datagrams newer than the newest it has used: a late or duplicated one never steps the pose back.
- `sent`: the bridge's send time in seconds on its machine's system-wide monotonic clock (`time.monotonic()`,
  `std::chrono::steady_clock`, CLOCK_MONOTONIC): never wall time, which NTP may step, nor a counter of the bridge
  process, which a restart would set back. The receiver ages poses by this clock (see `receiver.py`); the two
  machines' clocks need not agree, only tick at about the same rate.
- `side`: "left" | "right"; datagrams for the other hand are ignored (two gloves may share a port).
- `ergonomics`: MANUS SDK ergonomics values in degrees, keyed by the names of `names.py` (the SDK's enum names,
  with or without side, or the ROS 2 publisher's strings). Only the channels the retargeting uses are required;
  others are ignored.

Version 1 (`blindgrasp-glove/1`, no session, wall-clock `t`) is refused with a message saying so: its receiver
ordered by arrival, which is what version 2 fixes, so accepting it would keep the fault.

The bridge's end (`encode`, `GloveSender`) lives in `manus_bridge.py`, the one-file bridge a lab copies to the MANUS
machine; this module imports it from there, so sender and receiver share one definition of the datagram.
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass

from . import names
from .manus_bridge import PROTO, SESSION_RE, GloveSender, encode

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
    ergonomics: dict[str, float]  # by channel name (names.py), the required channels only


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
    if side not in names.SIDES:
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
    if proto == "blindgrasp-glove/1":
        raise DatagramError("protocol blindgrasp-glove/1 (no session, no sender clock): update the bridge to "
                            f"{PROTO} (blindgrasp-glove-bridge, docs/glove.md)")  # fmt: skip
    if proto != PROTO:
        raise DatagramError(f"not a {PROTO} message")
    session, seq, sent, side = _header(msg)
    ergo = msg.get("ergonomics")
    if not isinstance(ergo, dict):
        raise DatagramError("ergonomics is not an object")
    by_channel, problems = names.canonical(ergo, side)
    if problems:
        raise DatagramError("; ".join(problems[:3]))
    missing = frozenset(required - by_channel.keys())
    if missing:
        raise DatagramError(f"ergonomics lacks {sorted(missing)}", missing)
    values = {k: _number(by_channel[k]) for k in required}
    if any(abs(v) > MAX_ABS_DEG for v in values.values()):
        raise DatagramError("ergonomics value out of range")
    return GloveDatagram(session, seq, sent, side, values)
