"""The glove bridge, emulated: datagrams of `teleoperators/manus_glove/protocol.py` at `rate_hz`, sent by the
bridge's own `GloveSender` (session id, sequence number, send time on its monotonic clock), extended here with what
only an emulated bridge does (`EmulatedBridgeSender`).

The hand is one operator's: per ergonomics channel (`CHANNELS`) an open-hand and a fist value (deg), blended by
`closure` (0 open .. 1 fist), or by `closure_fn(t)` for scripted motions. `keys` picks the names it sends:
"sdk" (the SDK enum names without side, the receiver's channels), "ros2" (the MANUS ROS 2 publisher's strings).

Faults:
- `paused`: the bridge or the glove is gone (nothing is sent).
- `stalled`: the network holds everything (datagrams are built and stamped, then queued); clearing it delivers
  the backlog in one burst before the live stream, as a switch or Wi-Fi link does after a pause.
- `garbage_every`: a malformed datagram every n frames. `reorder`: each frame is sent after its successor.
- `delay_next(n)`: the next datagram arrives n frames late. `duplicate_next(n)`: it arrives again n frames later.
- `restart()`: the bridge restarts (new session, counter from 1), from the same source address.
- `noise_deg`: each channel's sensor noise (a real glove's values never repeat bit for bit); `frozen`: the bridge
  keeps sending the last values under new numbers and stamps (the SDK's cached data after the glove's radio link
  dropped).
- `clock_offset_s`: added to every `sent` stamp: a bridge whose clock jumps (a step back or ahead within a
  session), or one that is behind (its poses leave it already old: a lagging SDK, a clogged link at connect).
"""

from __future__ import annotations

import json
import random
import secrets
import socket
import threading
import time
from pathlib import Path

from lerobot_blindgrasp.teleoperators.manus_glove.manus_bridge import CHANNELS
from lerobot_blindgrasp.teleoperators.manus_glove.protocol import GloveSender, encode

# This operator's hand (deg), by channel: open hand and fist. Spread barely changes; flexion changes a lot.
OPEN: dict[str, float] = {}
FIST: dict[str, float] = {}
for _c in CHANNELS:
    if _c.motion == "MCPSpread":
        OPEN[_c.name], FIST[_c.name] = (25.0, 15.0) if _c.finger == "Thumb" else (2.0, -3.0)
    else:
        OPEN[_c.name] = {"MCPStretch": 5.0, "PIPStretch": 3.0, "DIPStretch": 2.0}[_c.motion]
        FIST[_c.name] = {"MCPStretch": 85.0, "PIPStretch": 95.0, "DIPStretch": 60.0}[_c.motion]
FIST.update({"ThumbMCPStretch": 45.0, "ThumbPIPStretch": 50.0, "ThumbDIPStretch": 40.0})


def write_glove_calibration(fpath: Path, open_pose: dict = OPEN, fist_pose: dict = FIST) -> None:
    """A glove calibration file as `lerobot-calibrate --teleop.type=manus_glove` writes it: the two poses."""
    fpath.parent.mkdir(parents=True, exist_ok=True)
    fpath.write_text(json.dumps({"open": open_pose, "fist": fist_pose}))


def calibrated_glove(calibration_dir: Path, port: int, **config):
    """A glove teleoperator of operator "op", this hand's calibration in `calibration_dir`, listening on `port`."""
    from lerobot_blindgrasp.teleoperators.manus_glove import ManusGlove, ManusGloveConfig

    write_glove_calibration(calibration_dir / "op.json")
    return ManusGlove(ManusGloveConfig(id="op", port=port, calibration_dir=calibration_dir, **config))


class EmulatedBridgeSender(GloveSender):
    """The bridge's sender, plus the faults of `GloveEmulator`: a datagram stamped with a chosen time (a bridge clock
    that jumps or lags), sent later or not at all (the network), and a restart from the same source address."""

    def pack(self, ergonomics: dict[str, float], sent: float) -> bytes:
        self.seq += 1
        return encode(self.session, self.seq, sent, ergonomics, self.side)

    def send_raw(self, datagram: bytes) -> None:
        self._sock.sendto(datagram, self.addr)

    def restart(self) -> None:
        """A restarted bridge: a new session, counting from 1 again."""
        self.session, self.seq = secrets.token_hex(8), 0


def free_udp_port() -> int:
    """A free UDP port below Linux's default ephemeral range (32768-60999), where no socket's automatic bind (every
    sender's source port, in any test process) can take it between this check and the test's own bind."""
    rng = random.Random()
    for _ in range(1000):
        port = rng.randrange(20000, 32768)
        with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
            try:
                s.bind(("127.0.0.1", port))
            except OSError:
                continue
        return port
    raise RuntimeError("no free UDP port in 20000-32767")


class GloveEmulator:
    def __init__(self, port: int, *, host: str = "127.0.0.1", rate_hz: float = 90.0, side: str = "right",
                 keys: str = "sdk"):  # fmt: skip
        self.addr = (host, port)
        self.period = 1.0 / rate_hz
        self.keys = keys
        self.closure = 0.0
        self.closure_fn = None  # t (s since start) -> closure
        self.spread_offset_deg = 0.0  # added to every spread channel
        self.paused = False
        self.stalled = False
        self.garbage_every = 0
        self.reorder = False
        self.clock_offset_s = 0.0
        self.noise_deg = 0.0
        self.frozen = False
        self._rng = random.Random(0)
        self._last_pose: dict[str, float] | None = None
        # A fixed source address, like a bridge's.
        self.sender = EmulatedBridgeSender(host, port, side, source_host=host)
        self._later: list[tuple[int, bytes]] = []  # (frames to wait, datagram)
        self._delay_next: list[tuple[int, bool]] = []  # (n, keep the original on time)
        self._backlog: list[bytes] = []
        self._lock = threading.Lock()
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, name="glove-emulator", daemon=True)
        self._t0 = time.monotonic()

    @property
    def source(self) -> tuple[str, int]:
        """The address its datagrams come from."""
        return self.sender.source

    @property
    def seq(self) -> int:
        return self.sender.seq

    def pose(self, closure: float) -> dict[str, float]:
        out = {}
        for c in CHANNELS:
            v = OPEN[c.name] + closure * (FIST[c.name] - OPEN[c.name])
            out[c.ros2 if self.keys == "ros2" else c.name] = v + (self.spread_offset_deg if c.motion == "MCPSpread"
                                                                   else 0.0)  # fmt: skip
        return out

    def delay_next(self, frames: int) -> None:
        with self._lock:
            self._delay_next.append((frames, False))

    def duplicate_next(self, frames: int) -> None:
        with self._lock:
            self._delay_next.append((frames, True))

    def restart(self) -> None:
        with self._lock:
            self.sender.restart()

    def start(self) -> GloveEmulator:
        self._thread.start()
        return self

    def stop(self) -> None:
        self._stop.set()
        self._thread.join(timeout=1.0)
        self.sender.close()

    def __enter__(self):
        return self.start()

    def __exit__(self, *exc):
        self.stop()

    def _run(self) -> None:
        held = None
        while not self._stop.wait(self.period):
            if self.paused:
                continue
            with self._lock:
                datagram = self.sender.pack(self._glove(), sent=time.monotonic() + self.clock_offset_s)
                out = self._network(datagram)
            if self.reorder:
                if held is None:
                    held, out = out, []
                else:
                    out, held = out + held, None
            for d in out:
                self.sender.send_raw(d)

    def _glove(self) -> dict[str, float]:
        """What the glove reports now: the hand's pose and its sensor noise, or, frozen, the last report again."""
        if self.frozen and self._last_pose is not None:
            return self._last_pose
        closure = self.closure_fn(time.monotonic() - self._t0) if self.closure_fn else self.closure
        pose = {k: v + self._rng.gauss(0.0, self.noise_deg) if self.noise_deg else v
                for k, v in self.pose(closure).items()}  # fmt: skip
        self._last_pose = pose
        return pose

    def _network(self, datagram: bytes) -> list[bytes]:
        """What leaves the network now, given this frame's datagram."""
        out = []
        if self.garbage_every and self.sender.seq % self.garbage_every == 0:
            out.append(b'{"proto": "blindgrasp-glove/2", "seq": ')
        if self._delay_next:
            frames, duplicate = self._delay_next.pop(0)
            self._later.append((frames, datagram))
            if duplicate:
                out.append(datagram)
        else:
            out.append(datagram)
        self._later = [(n - 1, d) for n, d in self._later]
        out += [d for n, d in self._later if n <= 0]
        self._later = [(n, d) for n, d in self._later if n > 0]
        if self.stalled:
            self._backlog += out
            return []
        out, self._backlog = self._backlog + out, []
        return out
