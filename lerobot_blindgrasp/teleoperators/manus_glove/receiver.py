"""The glove receiver: the newest pose for one hand from one bridge's UDP datagrams (`protocol.py`), ordered and
aged by the bridge's own `seq` and `sent` clock, not by arrival; the rules and their counters (`late`, `stale`,
`retired`, `clock_steps`, `foreign`) are docs/glove.md's "Time by the bridge's clock".
"""

from __future__ import annotations

import ipaddress
import logging
import socket
import struct
import sys
import time
from collections import deque
from dataclasses import dataclass

from lerobot_blindgrasp.hardware.streams import LatestFrameStream

from .protocol import DatagramError, GloveDatagram, decode

logger = logging.getLogger(__name__)

# Linux's SO_TIMESTAMPNS (asm-generic/socket.h; not named by Python's socket module): the kernel's arrival stamp,
# so time spent in the socket buffer while this process waits for a CPU is not taken for queueing on the network.
_SO_TIMESTAMPNS = 35
_TIMESPEC = struct.Struct("@ll")
# Upward drift allowed to the clock-offset estimate (s per s): 1000 ppm, over ten times a quartz clock's rate error.
OFFSET_LEAK = 1e-3
RETIRED_SESSIONS = 16  # earlier session ids remembered, to drop their late datagrams
# A loopback bridge's `sent` may lead this host's receive stamp by scheduling noise only; more is another clock.
SHARED_CLOCK_SLACK_S = 0.005
WALL_STEP_S = 0.01  # a change of (wall - monotonic) between two reads beyond this is a step of the wall clock
# A busy host can preempt this thread between its two clock reads, which would look like a step of the wall clock;
# a pair read further apart than this is read again.
CLOCK_PAIR_GAP_S = 0.001


def _clock_pair() -> tuple[float, float]:
    """(monotonic, wall) at one instant: the wall clock read between two monotonic reads, close together."""
    for _ in range(3):
        before, wall, after = time.monotonic(), time.time(), time.monotonic()
        if after - before <= CLOCK_PAIR_GAP_S:
            break
    return (before + after) / 2, wall


@dataclass(frozen=True)
class GloveFrame:
    session: str
    seq: int
    side: str
    ergonomics: dict[str, float]
    sent_local: float  # the bridge's send time mapped to this host's monotonic clock (<= its arrival)


class GloveReceiver(LatestFrameStream[GloveFrame]):
    """Background UDP listener keeping the newest valid pose for one hand (`LatestFrameStream`). Staleness is the
    teleoperator's call (hold the target, then stop), so `stale_timeout_s` is its hold timeout."""

    name = "Glove"
    lost_hint = "socket closed"

    def __init__(self, host: str, port: int, side: str, required: set[str], stale_timeout_s: float = 0.15, *,
                 sender: tuple[str, int] | None = None, frozen_frames: int = 0,
                 max_latency_s: float = 0.1):  # fmt: skip
        super().__init__(f"udp://{host}:{port}", stale_timeout_s, frozen_frames)
        self.host, self.port, self.side, self.required = host, port, side, required
        self.sender = sender  # the configured sender, or None: bind to the first valid one
        self.max_latency_s = max_latency_s
        self.bound: tuple[str, int] | None = None
        self._sock: socket.socket | None = None
        self._stamped = False  # the kernel stamps arrivals (SO_TIMESTAMPNS)
        self._reset()

    def _reset(self) -> None:
        self._frames_at_open = self.frames  # the base class counts kept frames over all connections
        self.received = self.rejected = self.foreign = self.other_side = 0
        self.late = self.stale = self.retired = self.restarts = self.clock_steps = 0
        self.last_reject: str | None = None
        self._warned_senders: set[tuple[str, int]] = set()
        self._warned_missing: set[frozenset[str]] = set()
        self._warned_behind: set[str] = set()
        self.session: str | None = None
        self._retired: deque[str] = deque(maxlen=RETIRED_SESSIONS)
        self._seq = 0
        self._sent = float("-inf")
        self._offset: float | None = None  # arrival - sent, minimum so far (leaking upwards)
        self._offset_at = 0.0
        self._stale_run, self._stale_max = 0, 0.0
        self._shared_clock = False  # the bound sender is on this machine: its `sent` is our monotonic clock
        self._wall_skew: float | None = None  # wall - monotonic at the last read

    @property
    def is_open(self) -> bool:
        return self._sock is not None

    def _open(self) -> None:
        sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        try:
            sock.bind((self.host, self.port))
        except OSError as e:
            sock.close()
            raise ConnectionError(f"Cannot listen for the glove on udp://{self.host}:{self.port}: {e}") from e
        sock.settimeout(0.05)
        self._stamped = False
        if sys.platform == "linux":
            try:
                sock.setsockopt(socket.SOL_SOCKET, _SO_TIMESTAMPNS, 1)
                self._stamped = True
            except OSError:
                pass
        self._sock = sock
        self._reset()  # each connection binds afresh, to any session
        self._bind(self.sender)

    def _close(self) -> None:
        if self._sock is not None:
            self._sock.close()
            self._sock = None

    # --- receive thread -------------------------------------------------------------------------------------
    def _read(self) -> tuple[bytes, tuple, float]:
        """(datagram, source address, arrival on this host's monotonic clock)."""
        if not self._stamped:
            datagram, addr = self._sock.recvfrom(65536)
            return datagram, addr, time.monotonic()
        datagram, ancillary, _, addr = self._sock.recvmsg(65536, socket.CMSG_SPACE(_TIMESPEC.size))
        mono, wall = _clock_pair()
        skew, last = wall - mono, self._wall_skew
        self._wall_skew = skew
        if last is not None and abs(skew - last) > WALL_STEP_S:
            return datagram, addr, mono  # the wall clock stepped: the kernel's stamp may be on either side of it
        for level, kind, raw in ancillary:
            if level == socket.SOL_SOCKET and kind == _SO_TIMESTAMPNS and len(raw) >= _TIMESPEC.size:
                sec, nsec = _TIMESPEC.unpack(raw[: _TIMESPEC.size])
                waited = wall - (sec + nsec * 1e-9)  # both on the wall clock; bounded in case it was stepped
                return datagram, addr, mono - min(max(waited, 0.0), 5.0)
        return datagram, addr, mono

    def _receive(self) -> list[GloveFrame]:
        try:
            datagram, addr, arrival = self._read()
        except TimeoutError:
            return []
        self.received += 1
        try:
            d = decode(datagram, self.required)
        except Exception as e:  # whatever arrives, the listener must keep listening
            self._reject(e, addr)
            return []
        if d.side != self.side:
            self.other_side += 1
            return []
        if not self._from_bound_sender((addr[0], addr[1])):
            return []
        frame = self._order_and_age(d, arrival)
        return [] if frame is None else [frame]

    def _reject(self, e: Exception, addr) -> None:
        self.rejected += 1
        self.last_reject = str(e)[:200]
        missing = e.missing if isinstance(e, DatagramError) else frozenset()
        if missing and missing not in self._warned_missing:
            self._warned_missing.add(missing)
            logger.warning(
                "Glove datagrams from %s:%d lack the channels %s that the retargeting needs, so they are dropped. "
                "Both the MANUS SDK's names and the ROS 2 publisher's are accepted (docs/glove.md); a publisher "
                "that skips a channel (some copies drop IndexMCPSpread) needs the fix in docs/glove.md, or, for a "
                "spread, --teleop.spread_gain 0 for that finger.",
                addr[0], addr[1], sorted(missing),
            )  # fmt: skip
        else:
            logger.debug("glove datagram rejected: %s", e)

    def _bind(self, addr: tuple[str, int] | None) -> None:
        self.bound = addr
        try:
            self._shared_clock = addr is not None and ipaddress.ip_address(addr[0]).is_loopback
        except ValueError:  # a host name: not known to be this machine
            self._shared_clock = False

    def _from_bound_sender(self, addr: tuple[str, int]) -> bool:
        if self.bound is None:
            self._bind(addr)
            logger.info("Glove receiver bound to the bridge at %s:%d.", *addr)
        elif addr != self.bound:
            self.foreign += 1
            if addr not in self._warned_senders:
                self._warned_senders.add(addr)
                logger.warning("Dropping glove datagrams from %s:%d: this teleoperator is bound to %s:%d. "
                               "Another bridge or sender on the port? Reconnect to change the sender.",
                               *addr, *self.bound)  # fmt: skip
            return False
        return True

    def _order_and_age(self, d: GloveDatagram, arrival: float) -> GloveFrame | None:
        if d.session != self.session:
            if d.session in self._retired or d.sent <= self._sent:
                self.retired += 1
                self._warn_behind(d)
                return None
            self._new_session(d.session)
        if d.seq <= self._seq:
            self.late += 1  # reordered, delayed or duplicated: older than the pose already used
            return None
        if d.sent < self._sent:
            self._clock_stepped(d)
            return None
        sample = arrival - d.sent
        if self._shared_clock and sample < -SHARED_CLOCK_SLACK_S:
            self._shared_clock = False
            logger.warning("The glove bridge on this machine stamps `sent` %.3f s after its datagrams arrive: not "
                           "this machine's monotonic clock; ageing its poses by an estimated offset.", -sample)  # fmt: skip
        if self._shared_clock:
            self._offset, self._offset_at = 0.0, arrival
        else:
            leaked = sample if self._offset is None else self._offset + OFFSET_LEAK * (arrival - self._offset_at)
            self._offset, self._offset_at = min(leaked, sample), arrival
        queued = sample - self._offset
        # The sequence moves on even for a stale datagram: anything older than it is older still.
        self._seq, self._sent = d.seq, d.sent
        if queued > self.max_latency_s:
            self.stale += 1
            self._stale_run += 1
            self._stale_max = max(self._stale_max, queued)
            return None
        if self._stale_run:
            logger.warning(
                "Dropped %d glove datagrams that arrived up to %.0f ms late by the bridge's clock (limit %.0f ms): "
                "a network pause, whose backlog is not replayed. Following live data again.",
                self._stale_run, self._stale_max * 1e3, self.max_latency_s * 1e3,
            )  # fmt: skip
            self._stale_run, self._stale_max = 0, 0.0
        return GloveFrame(d.session, d.seq, d.side, d.ergonomics, d.sent + self._offset)

    def _clock_stepped(self, d: GloveDatagram) -> None:
        if not self.clock_steps:
            logger.warning(
                "The glove bridge's clock stepped back %.3f s within session %s (seq %d after %d): its `sent` is not "
                "a monotonic clock, so its poses cannot be aged. Dropping them until it is past the old time; fix "
                "the bridge (docs/glove.md), then reconnect.", self._sent - d.sent, d.session, d.seq, self._seq,
            )  # fmt: skip
        self.clock_steps += 1

    def _warn_behind(self, d: GloveDatagram) -> None:
        if d.session in self._retired or d.session in self._warned_behind:
            return
        self._warned_behind.add(d.session)
        logger.warning(
            "Dropping glove datagrams of bridge session %s: they were sent %.3f s before the newest pose used (by "
            "the bridge's clock), so they are late ones of an older bridge. If the bridge's machine rebooted, or "
            "its `sent` is not the system's monotonic clock, reconnect the teleoperator.", d.session,
            self._sent - d.sent,
        )  # fmt: skip

    def _new_session(self, session: str) -> None:
        if self.session is not None:
            self.restarts += 1
            self._retired.append(self.session)
            logger.warning("Glove bridge restarted (session %s -> %s, its counter starts again): following the "
                           "new session; late datagrams of the old one are dropped.", self.session,
                           session)  # fmt: skip
        # self._sent stays: the restarted bridge's clock is the same machine's, and it must move on from there.
        self.session, self._seq, self._offset = session, 0, None

    # --- readers --------------------------------------------------------------------------------------------
    def latest(self) -> tuple[GloveFrame, float]:
        """(newest pose, its age in s): the larger of its age by the bridge's clock and since its arrival."""
        frame, arrival_age = super().latest()
        return frame, max(arrival_age, time.monotonic() - frame.sent_local)

    def diagnosis(self) -> str:
        """What arrived and why it was not used, for the operator."""
        if not self.received:
            return ("no datagram arrived: is the bridge running (manus_bridge.py, docs/glove.md) and "
                    f"sending to {self.host}:{self.port}? A bridge on another machine needs --teleop.host and an "
                    "open firewall port")  # fmt: skip
        parts = [f"{self.received} datagrams arrived, {self.frames - self._frames_at_open} used"]
        if self.rejected:
            parts.append(f"{self.rejected} rejected (last: {self.last_reject})")
        if self.other_side:
            other = "left" if self.side == "right" else "right"
            parts.append(
                f"{self.other_side} for the {other} hand (this teleoperator is --teleop.side={self.side})"
            )
        if self.foreign:
            parts.append(f"{self.foreign} from another sender than the bound {self.bound[0]}:{self.bound[1]}")
        for count, what in ((self.late, "late or duplicated"), (self.stale, f"queued > {self.max_latency_s} s"),
                            (self.retired, "from an older bridge session"),
                            (self.clock_steps, "after the bridge's clock stepped back")):  # fmt: skip
            if count:
                parts.append(f"{count} {what}")
        return "; ".join(parts)

    def _content(self, frame: GloveFrame) -> tuple:
        return (tuple(frame.ergonomics[k] for k in sorted(frame.ergonomics)),)

    def _content_names(self) -> list[str]:
        return ["ergonomics"]
