"""Analytic redundancy: inputs that see the same physics must agree, checked at every current read (the health
block). A disagreement physics forbids is an ERROR (`ConsistencyError`); one it allows but that usually means a
failing input is a WARN, logged when it starts and when it ends. The three checks (force without effort, effort
without force, command without motion) and their tolerances: docs/hardware.md, "Consistency".
"""

from __future__ import annotations

import logging
import math
from dataclasses import dataclass, field

import numpy as np

from lerobot_blindgrasp import spec
from lerobot_blindgrasp.hardware import xm430

logger = logging.getLogger(__name__)

# Finger geometry of the sim model (ROBEL chain3xh; `sim/gripper.py`, tests/robots/test_hazards_consistency.py keeps them equal):
LINK_J11_J12 = 0.068  # m
TIP_CAPSULE_START = 0.033  # m below J12, along the distal axis
TIP_CAPSULE_RADIUS = 0.011
TIP_CAPSULE_END = 0.084 - TIP_CAPSULE_RADIUS
# The elastic tips' friction coefficient in the sim model: the friction cone's half-angle 45 deg.
TIP_FRICTION = 1.0

KT_NM_PER_A = xm430.STALL_TORQUE_NM / xm430.STALL_CURRENT_A  # the stall line, through the origin
NO_LOAD_CURRENT_A = 0.12  # XM430-W350 at 12 V (e-Manual, Specifications): what the gear train's friction costs
HOLD_ALLOWANCE_NM = KT_NM_PER_A * NO_LOAD_CURRENT_A
KP_NM_PER_RAD = 15.0  # the XM430's P loop at Position_P_Gain 800 (the sim's servo model)
KP_SOFTEST = 0.3  # the twin's draw (Table II) scales kp down to this
PERSIST = 2  # current reads in a row (every health_every_n periods: 0.2 s at 20 Hz and 4)
TOUCH_N = 0.5  # below this a tip touches nothing: the tare's at-rest envelope is 1 N, the cell's noise 14 mN
PRESSING_FRACTION = 0.5  # of the current limit
PRESSING_ERROR_RAD = 0.05
STUCK_ERROR_RAD = 0.25  # the P loop is at ~the stall torque at 0.27 rad (nominal kp); the step bound is 0.3
STUCK_PROGRESS_RAD = 0.02  # 13 ticks: a joint moving at 1/20 of its no-load speed covers 0.24 rad in 0.2 s


class ConsistencyError(RuntimeError):
    """Two inputs that see the same physics disagree beyond what physics allows."""


def _outline(u: np.ndarray, b: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Points of the tip capsule's outline in the finger's plane and their outward normals: its two sides, and the
    half circles of its end caps."""
    perp = np.array([-u[1], u[0]])
    s = np.linspace(TIP_CAPSULE_START, TIP_CAPSULE_END, 17)
    side_n = np.concatenate([np.tile(perp, (len(s), 1)), np.tile(-perp, (len(s), 1))])
    side_c = b + np.concatenate([s, s])[:, None] * u
    ang = np.linspace(-np.pi / 2, np.pi / 2, 37)[:, None]
    cap = np.cos(ang) * u + np.sin(ang) * perp  # normals around +u
    normals = np.concatenate([side_n, cap, -cap])
    centres = np.concatenate([side_c, np.tile(b + TIP_CAPSULE_END * u, (len(cap), 1)),
                              np.tile(b + TIP_CAPSULE_START * u, (len(cap), 1))])  # fmt: skip
    return centres + TIP_CAPSULE_RADIUS * normals, normals


def _lever_table(q12: np.ndarray) -> np.ndarray:
    """h(q12) in m: the smallest, over contact points P on the tip capsule's outline and contact forces f inside the
    friction cone at P (in the finger's plane), of max(|moment about J11|, |moment about J12|) per unit of f's
    compressive component along the distal axis (what the cell reads)."""
    th = np.linspace(0.0, 2 * np.pi, 720, endpoint=False)
    f = np.stack([np.cos(th), np.sin(th)], axis=1)  # (720, 2): unit directions of the force on the tip
    b = np.array([0.0, -LINK_J11_J12])  # J12; J11 is the origin and the proximal link points down
    out = np.empty(len(q12))
    for k, q in enumerate(q12):
        u = np.array([math.sin(q), -math.cos(q)])  # the distal axis, along which the cell reads
        p, normal = _outline(u, b)
        usable = ((-normal @ f.T) >= math.cos(math.atan(TIP_FRICTION))) & (f @ u < 0)  # pushes, in the cone
        push = np.maximum(-(f @ u), 1e-12)
        m_a = np.abs(np.outer(p[:, 0], f[:, 1]) - np.outer(p[:, 1], f[:, 0]))  # |(P - A) x f|
        pb = p - b
        m_b = np.abs(np.outer(pb[:, 0], f[:, 1]) - np.outer(pb[:, 1], f[:, 0]))
        out[k] = float(np.where(usable, np.maximum(m_a, m_b) / push, np.inf).min())
    return out


_Q12 = np.linspace(0.0, 1.9, 77)
_H = _lever_table(_Q12)


def lever_m(q12: float) -> float:
    """The least moment arm (m) through which a distal-axis tip force loads J11 or J12 (symmetric in q12)."""
    return float(np.interp(abs(q12), _Q12, _H))


@dataclass
class _Run:
    count: int = 0
    since: float | None = None


@dataclass
class ConsistencyMonitor:
    kp_nm_per_rad: float = KP_NM_PER_RAD
    worst: dict[str, float] = field(default_factory=dict)  # check -> max(measured / tolerance) while not firing
    warnings: int = 0
    _runs: dict = field(default_factory=dict)
    _warned: dict = field(default_factory=dict)  # finger -> when its WARN started
    _last_ratio: dict = field(default_factory=dict)  # finger -> its force ratio at the last read
    _last_q: np.ndarray | None = None

    @classmethod
    def at_p_gain(cls, position_p_gain: int) -> ConsistencyMonitor:
        """The monitor of servos at this Position_P_Gain (the sim's kp is the XM430's at the factory 800)."""
        return cls(KP_NM_PER_RAD * position_p_gain / 800)

    def reset(self) -> None:
        self._runs.clear()
        self._warned.clear()
        self._last_ratio.clear()
        self._last_q = None

    def _note(self, check: str, ratio: float) -> None:
        self.worst[check] = max(self.worst.get(check, 0.0), ratio)

    def _persist(self, key: tuple, bad: bool, now: float) -> int:
        run = self._runs.setdefault(key, _Run())
        if not bad:
            run.count, run.since = 0, None
            return 0
        run.count += 1
        run.since = now if run.since is None else run.since
        return run.count

    def assess(self, now, q, goal, forces, current_units, limit_units) -> None:
        """One current read: q and goal in rad (goal None with the torque off), forces in N, Present_Current in
        register units (signed, the calibrated joint frame), the current limit in units. Raises ConsistencyError."""
        q, forces, amps = np.array(q, float), np.asarray(forces, float), np.asarray(current_units, float)
        amps = amps * xm430.CURRENT_UNIT_A
        if goal is None or not limit_units:
            self.reset()
            return
        error = np.asarray(goal, float) - q
        limit_a = limit_units * xm430.CURRENT_UNIT_A
        # How far each joint moved toward its goal since the last read (none known at the first: not moving).
        progress = np.zeros_like(q) if self._last_q is None else (q - self._last_q) * np.sign(error)
        for f, finger in enumerate(spec.FINGERS):
            self._force_checks(now, finger, f, q, error, progress, forces[f], amps, limit_a)
        self._motion_check(now, error, progress, amps, limit_a)
        self._last_q = q

    def _force_checks(self, now, finger, f, q, error, progress, force, amps, limit_a) -> None:
        j11, j12 = 3 * f + 1, 3 * f + 2
        needed = max(force, 0.0) * lever_m(q[j12])
        held = KT_NM_PER_A * max(abs(amps[j11]), abs(amps[j12])) + HOLD_ALLOWANCE_NM
        ratio = needed / held
        if self._persist(("phantom", finger), ratio > 1.0, now) >= PERSIST:
            raise ConsistencyError(
                f"{finger}_tip reads {force:.1f} N, which needs >= {needed:.2f} N m at {spec.JOINT_NAMES[j11]} or "
                f"{spec.JOINT_NAMES[j12]} (q12 {q[j12]:.2f} rad, lever >= {lever_m(q[j12]) * 1e3:.1f} mm), but their "
                f"currents ({amps[j11]:.2f} A, {amps[j12]:.2f} A) hold at most {held:.2f} N m, for {PERSIST} current "
                "reads in a row: the load cell reads a force that is not there (a drifting, swapped or shorted cell)."
            )
        self._note("force without effort", ratio)
        # What stops is the ratio over PERSIST reads in a row: its margin is the smaller of the last two.
        self._note("force without effort (2 reads)", min(ratio, self._last_ratio.get(finger, 0.0)))
        self._last_ratio[finger] = ratio
        joints = range(3 * f, 3 * f + 3)
        pressing = [j for j in joints if abs(amps[j]) >= PRESSING_FRACTION * limit_a and abs(error[j])
                    >= PRESSING_ERROR_RAD and amps[j] * error[j] > 0 and progress[j] < STUCK_PROGRESS_RAD]  # fmt: skip
        missing = bool(pressing) and force < TOUCH_N
        if self._persist(("missing", finger), missing, now) >= PERSIST and finger not in self._warned:
            self._warned[finger] = now
            self.warnings += 1
            logger.warning("Consistency WARN %s: %s press (%s A, limit %.2f A) while %s_tip reads %.2f N: a dead "
                           "or unplugged load cell, or a contact off the tip.", finger,
                           [spec.JOINT_NAMES[j] for j in pressing], [round(float(amps[j]), 2) for j in pressing], limit_a,
                           finger, force)  # fmt: skip
        elif not missing and finger in self._warned:
            logger.warning("Consistency OK %s: its tip force agrees with its servos again (%.2f N) after %.1f s.",
                           finger, force, now - self._warned.pop(finger))  # fmt: skip

    def _motion_check(self, now, error, progress, amps, limit_a) -> None:
        for j, name in enumerate(spec.JOINT_NAMES):
            e = abs(error[j])
            asked = min(limit_a, KP_SOFTEST * self.kp_nm_per_rad * e / KT_NM_PER_A)
            along = amps[j] * math.copysign(1.0, error[j])
            still = progress[j] < STUCK_PROGRESS_RAD
            stuck = e >= STUCK_ERROR_RAD and along < 0.5 * asked and still
            run = self._persist(("stuck", name), stuck, now)
            self._note("command without motion (reads in a row)", run / (PERSIST + 1))
            if run >= PERSIST + 1 and self._last_q is not None:
                raise ConsistencyError(
                    f"{name} does not move toward its goal ({error[j]:+.2f} rad away, moved {progress[j]:+.3f} rad "
                    f"toward it since the last read) and draws {amps[j]:+.2f} A where its position loop asks >= "
                    f"{0.5 * asked:.2f} A toward the goal, for {PERSIST + 1} current reads in a row: the servo is not "
                    "driving its joint (a stripped gear, a failed motor, a current reading of the wrong sign)."
                )

    def report(self) -> str:
        worst = ", ".join(f"{k} {v:.3f}" for k, v in sorted(self.worst.items())) or "nothing measured"
        return f"consistency margins (worst measured / tolerance, < 1 passes): {worst}; {self.warnings} WARN runs"
