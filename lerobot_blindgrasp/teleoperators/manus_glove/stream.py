"""The glove's local network stream: one UDP datagram per glove frame, UTF-8 JSON.

A small bridge next to the vendor's SDK (MANUS Core SDK, or its ROS 2 `manus_data_publisher`) sends, for one hand:

    {"proto": "blindgrasp-glove/1", "seq": 1234, "t": 1732412345.123, "side": "right",
     "ergonomics": {"ThumbMCPSpread": 12.1, "ThumbMCPStretch": 20.4, ..., "PinkyDIPStretch": 3.0}}

- `ergonomics`: the SDK's ergonomics data, keyed by its type names (ThumbMCPSpread, ThumbMCPStretch,
  ThumbPIPStretch, ThumbDIPStretch, then {Index,Middle,Ring,Pinky}{Spread,MCPStretch,PIPStretch,DIPStretch}),
  in degrees as the SDK reports them. Only the keys the retargeting uses are required.
- `seq`: uint32 counter of the bridge; a datagram a few counts older than the newest one, arriving right after it,
  was reordered on the way and is ignored. A larger step back is a restarted bridge (its counter starts again at
  0) and is accepted.
- `t`: sender wall time (s), informational; staleness is judged on the receiver's clock.
- `side`: "left" | "right"; datagrams for the other hand are ignored (two gloves may share a port).

One glove per teleoperator: the receiver binds to one sender, the configured `sender` address or else the first that
sends a valid datagram for its hand, and drops every other sender's datagrams (counted in `foreign`, warned once
per address). A second bridge, or anyone else on the port, cannot take over the teleoperation. Changing the sender
(a bridge restarted on a new source port, another machine) takes a reconnect, which binds afresh.

UDP fits a 60-120 Hz pose stream: the newest datagram wins, a lost one is replaced 10 ms later, and the sender
needs no connection state. The default destination is 127.0.0.1:50120 (same machine as the bridge).
"""

from __future__ import annotations

import json
import logging
import math
import socket
import time
from dataclasses import dataclass

from lerobot_blindgrasp.hardware.streams import LatestFrameStream

logger = logging.getLogger(__name__)

PROTO = "blindgrasp-glove/1"
MAX_ABS_DEG = 360.0
# UDP on one host or a LAN reorders by a few datagrams within milliseconds; anything else going backwards is a
# restarted bridge.
REORDER_WINDOW = 16
REORDER_MAX_S = 0.1


@dataclass(frozen=True)
class GloveFrame:
    seq: int
    side: str
    ergonomics: dict[str, float]
    received: float  # receiver monotonic time


def encode(seq: int, ergonomics: dict[str, float], side: str = "right", t: float | None = None) -> bytes:
    stamp = time.time() if t is None else t
    msg = {"proto": PROTO, "seq": seq, "t": stamp, "side": side, "ergonomics": ergonomics}
    return json.dumps(msg).encode()


def _number(value) -> float:
    # JSON also yields bools, strings, lists, NaN, Infinity and integers too large for a float.
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise ValueError(f"not a number: {value!r:.40}")
    try:
        out = float(value)
    except OverflowError as e:
        raise ValueError("number too large") from e
    if not math.isfinite(out):
        raise ValueError(f"non-finite number {out}")
    return out


def decode(datagram: bytes, required: set[str]) -> tuple[int, str, dict[str, float]]:
    """Raises ValueError on anything that is not a complete, sane message of this protocol."""
    try:
        msg = json.loads(datagram.decode("utf-8"))
    except (UnicodeDecodeError, ValueError, RecursionError) as e:
        raise ValueError(f"not JSON: {e}") from e
    if not isinstance(msg, dict) or msg.get("proto") != PROTO:
        raise ValueError("not a blindgrasp-glove/1 message")
    ergo = msg.get("ergonomics")
    if not isinstance(ergo, dict) or not required <= ergo.keys():
        raise ValueError(f"ergonomics lacks {sorted(required - set(ergo if isinstance(ergo, dict) else {}))}")
    values = {k: _number(ergo[k]) for k in required}
    if any(abs(v) > MAX_ABS_DEG for v in values.values()):
        raise ValueError("ergonomics value out of range")
    seq = msg.get("seq")
    if isinstance(seq, bool) or not isinstance(seq, int) or not 0 <= seq < 2**32:
        raise ValueError(f"seq {seq!r:.40} is not a uint32")
    side = msg.get("side", "right")
    if side not in ("left", "right"):
        raise ValueError(f"side {side!r:.40}")
    return seq, side, values


class GloveReceiver(LatestFrameStream[GloveFrame]):
    """Background UDP listener keeping the newest valid frame for one hand (`LatestFrameStream`). Staleness is the
    teleoperator's call (hold the target, then stop), so `stale_timeout_s` is its hold timeout."""

    name = "Glove"
    lost_hint = "socket closed"

    def __init__(
        self,
        host: str,
        port: int,
        side: str,
        required: set[str],
        stale_timeout_s: float = 0.15,
        *,
        sender: tuple[str, int] | None = None,
        frozen_frames: int = 0,
    ):
        super().__init__(f"udp://{host}:{port}", stale_timeout_s, frozen_frames)
        self.host, self.port, self.side, self.required = host, port, side, required
        self.sender = sender  # the configured sender, or None: bind to the first valid one
        self.bound: tuple[str, int] | None = None
        self.rejected = 0
        self.foreign = 0  # valid datagrams from another sender than the bound one, dropped
        self._warned: set[tuple[str, int]] = set()
        self._sock: socket.socket | None = None

    @property
    def is_open(self) -> bool:
        return self._sock is not None

    def open(self) -> None:
        self.start()

    def close(self) -> None:
        self.stop()

    def _open(self) -> None:
        sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        try:
            sock.bind((self.host, self.port))
        except OSError as e:
            sock.close()
            raise ConnectionError(f"Cannot listen for the glove on udp://{self.host}:{self.port}: {e}") from e
        sock.settimeout(0.05)
        self._sock = sock
        self.bound = self.sender  # each connection binds afresh
        self._warned.clear()

    def _receive(self) -> list[GloveFrame]:
        try:
            datagram, addr = self._sock.recvfrom(65536)
        except TimeoutError:
            return []
        try:
            seq, side, ergo = decode(datagram, self.required)
        except Exception as e:  # whatever arrives, the listener must keep listening
            self.rejected += 1
            logger.debug("glove datagram rejected: %s", e)
            return []
        if side != self.side:
            return []
        addr = (addr[0], addr[1])
        if self.bound is None:
            self.bound = addr
            logger.info("Glove receiver bound to the bridge at %s:%d.", *addr)
        elif addr != self.bound:
            self.foreign += 1
            if addr not in self._warned:
                self._warned.add(addr)
                logger.warning(
                    "Dropping glove datagrams from %s:%d: this teleoperator is bound to %s:%d. Another bridge or "
                    "sender on the port? Reconnect to change the sender.", *addr, *self.bound
                )
            return []
        return [GloveFrame(seq, side, ergo, time.monotonic())]

    def _close(self) -> None:
        if self._sock is not None:
            self._sock.close()
            self._sock = None

    def _content(self, frame: GloveFrame) -> tuple:
        return (tuple(frame.ergonomics[k] for k in sorted(frame.ergonomics)),)

    def _content_names(self) -> list[str]:
        return ["ergonomics"]

    def _keep(self, frame: GloveFrame, now: float) -> bool:
        last = self._latest
        if last is not None and frame.seq == last.seq:  # a duplicate datagram
            self.counter_faults += 1
            return False
        # A little older than what we have, just after it: reordered on the way. Further back: a restarted bridge.
        return not (last is not None and 0 < (last.seq - frame.seq) % 2**32 <= REORDER_WINDOW
                    and now - last.received < REORDER_MAX_S)  # fmt: skip
