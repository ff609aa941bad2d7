"""The glove SDK bridge, emulated: UDP datagrams of `teleoperators/manus_glove/stream.py` at `rate_hz`.

The hand is one operator's: per ergonomics channel an open-hand and a fist value (deg), blended by `closure`
(0 open .. 1 fist), or by `closure_fn(t)` for scripted motions. Faults: `paused` (bridge or glove gone),
`garbage_every` (a malformed datagram every n frames), `reorder` (send each frame after its successor).
"""

from __future__ import annotations

import socket
import threading
import time

from lerobot_blindgrasp.teleoperators.manus_glove.stream import encode

FINGERS = ("Thumb", "Index", "Middle", "Ring", "Pinky")
# This operator's hand (deg): open hand and fist. Spread barely changes; flexion changes a lot.
OPEN = {**{f"{f}Spread": 2.0 for f in FINGERS[1:]}, "ThumbMCPSpread": 25.0}
FIST = {**{f"{f}Spread": -3.0 for f in FINGERS[1:]}, "ThumbMCPSpread": 15.0}
for _f in FINGERS:
    OPEN.update({f"{_f}MCPStretch": 5.0, f"{_f}PIPStretch": 3.0, f"{_f}DIPStretch": 2.0})
    FIST.update({f"{_f}MCPStretch": 85.0, f"{_f}PIPStretch": 95.0, f"{_f}DIPStretch": 60.0})
FIST.update({"ThumbMCPStretch": 45.0, "ThumbPIPStretch": 50.0, "ThumbDIPStretch": 40.0})


def free_udp_port() -> int:
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


class GloveEmulator:
    def __init__(self, port: int, *, host: str = "127.0.0.1", rate_hz: float = 90.0, side: str = "right"):
        self.addr = (host, port)
        self.period = 1.0 / rate_hz
        self.side = side
        self.closure = 0.0
        self.closure_fn = None  # t (s since start) -> closure
        self.spread_offset_deg = 0.0  # added to every Spread channel
        self.paused = False
        self.garbage_every = 0
        self.reorder = False
        self.seq = 0
        self._sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self._sock.bind((host, 0))  # a fixed source address from the start, like a bridge's
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, name="glove-emulator", daemon=True)
        self._t0 = time.monotonic()

    @property
    def source(self) -> tuple[str, int]:
        """The address its datagrams come from (bound by the first send)."""
        return self._sock.getsockname()

    def pose(self, closure: float) -> dict[str, float]:
        out = {k: OPEN[k] + closure * (FIST[k] - OPEN[k]) for k in OPEN}
        for k in out:
            if k.endswith("Spread"):
                out[k] += self.spread_offset_deg
        return out

    def start(self) -> GloveEmulator:
        self._thread.start()
        return self

    def stop(self) -> None:
        self._stop.set()
        self._thread.join(timeout=1.0)
        self._sock.close()

    def __enter__(self):
        return self.start()

    def __exit__(self, *exc):
        self.stop()

    def _run(self) -> None:
        held = None
        while not self._stop.wait(self.period):
            if self.paused:
                continue
            closure = self.closure_fn(time.monotonic() - self._t0) if self.closure_fn else self.closure
            self.seq += 1
            datagram = encode(self.seq, self.pose(closure), self.side)
            if self.garbage_every and self.seq % self.garbage_every == 0:
                self._sock.sendto(b'{"proto": "blindgrasp-glove/1", "seq": ', self.addr)
            if self.reorder:
                if held is not None:
                    self._sock.sendto(datagram, self.addr)
                    self._sock.sendto(held, self.addr)
                    held = None
                else:
                    held = datagram
                continue
            self._sock.sendto(datagram, self.addr)
