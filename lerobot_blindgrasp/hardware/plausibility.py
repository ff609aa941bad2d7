"""The one gate every servo position reading passes before anything uses it. A reading can be wrong and still arrive
with a valid CRC (a stray reply, a glitching encoder), so it is trusted only if physically possible: in the encoder's
range, reachable at no-load speed from the trusted estimate, and (torque on) between the estimate and the goal; with
no estimate or the torque off, once a second reading confirms it. Anything else is read again, then
`ImplausibleReadingError`. A rejected reading never becomes the estimate the robot centres its step bound on.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from lerobot_blindgrasp.hardware.xm430 import TICKS_PER_REV


class ImplausibleReadingError(RuntimeError):
    """Servo position readings that stayed physically impossible after the re-reads."""


@dataclass
class PositionGate:
    speed_ticks_s: float  # the fastest a joint can move on its own (the servo's no-load speed)
    margin_ticks: float  # encoder noise, backlash and timestamp jitter
    backdrive_ticks: float = 0.0  # how far a load can push a torqued servo back past the goal band
    rereads: int = 2
    lo: int = 0  # the encoder's range, calibrated ticks
    hi: int = TICKS_PER_REV - 1
    estimate: np.ndarray | None = None  # the last trusted reading (ticks), None until one is confirmed
    estimate_t: float = 0.0
    goal: np.ndarray | None = None  # the goal the servos hold (ticks) while the torque is on, else None
    rejected: int = 0  # implausible readings seen so far (each was read again)
    last_problem: str = field(default="", repr=False)

    def forget(self) -> None:
        """Drop the estimate: from now on a reading needs a confirming second one (torque off, reconnect)."""
        self.estimate = self.goal = None

    def _problem(self, ticks: np.ndarray, ref: np.ndarray | None, dt: float, names, goal=None) -> str:
        out = [f"{n} {int(t)}" for n, t in zip(names, ticks) if not self.lo <= t <= self.hi]
        if out:
            return f"outside the encoder range {self.lo}..{self.hi}: " + ", ".join(out)
        if ref is None:
            return ""
        bound = self.speed_ticks_s * max(dt, 0.0) + self.margin_ticks
        jump = np.abs(ticks - ref)
        out = [f"{n} {int(d)} ticks" for n, d in zip(names, jump) if d > bound]
        if out:
            return f"moved farther than possible in {dt * 1e3:.0f} ms (<= {bound:.0f} ticks): " + ", ".join(out)
        if goal is not None:
            slack = self.margin_ticks + self.backdrive_ticks
            low, high = np.minimum(ref, goal) - slack, np.maximum(ref, goal) + slack
            out = [f"{n} {int(t)} (estimate {int(r)}, goal {int(g)})"
                   for n, t, r, g, a, b in zip(names, ticks, ref, goal, low, high) if not a <= t <= b]  # fmt: skip
            if out:
                return "moved away from both the estimate and the goal: " + ", ".join(out)
        return ""

    def read(self, read_ticks: Callable[[], np.ndarray], names, *, free: bool) -> np.ndarray:
        """A trusted reading (ticks). `free`: the torque is off, so the joints may be moved by hand faster than the
        servos could: a reading that disagrees with the estimate is then trusted once a second one confirms it."""
        previous: tuple[np.ndarray, float] | None = None
        for _attempt in range(1 + self.rereads):
            # The servos sample somewhere inside the transaction: time it from its start, and bound the motion by
            # the end of this one minus the start of the trusted one (the longest the joints could have moved).
            start = time.monotonic()
            ticks = np.asarray(read_ticks(), dtype=np.float64)
            now = time.monotonic()
            goal = None if free else self.goal
            problem = self._problem(ticks, self.estimate, now - self.estimate_t, names, goal)
            if problem and (free or self.estimate is None) and previous is not None:
                problem = self._problem(ticks, previous[0], now - previous[1], names)
            elif not problem and self.estimate is None:
                problem = "unconfirmed" if previous is None else self._problem(ticks, previous[0], now - previous[1],
                                                                                names)  # fmt: skip
            if not problem:
                self.estimate, self.estimate_t = ticks, start
                return ticks
            if problem != "unconfirmed":
                self.rejected += 1
                self.last_problem = problem
            if self._problem(ticks, None, 0.0, names) == "":
                previous = (ticks, start)  # in range: may confirm the next one
        raise ImplausibleReadingError(
            f"Servo position readings stayed physically implausible after {self.rereads} re-reads "
            f"({self.last_problem}). A servo encoder or the bus is failing: check the cabling and the servo."
        )
