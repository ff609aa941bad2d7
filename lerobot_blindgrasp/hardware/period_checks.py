"""What every control period checks, whoever calls (get_observation, or send_action alone): the servos' state block
every period (a joint the bus watchdog stopped is re-armed holding its pose), the health block every `every_n`
periods and at once at a start, and the consistency checks after a period whose health read brought currents.
Each failure raises the checking module's own error; the gripper's safety latch turns it into a named stop."""

from __future__ import annotations

import time
from collections.abc import Callable

from .consistency import ConsistencyMonitor
from .plausibility import PositionGate
from .servo_diagnostics import ServoHealth
from .servo_registers import ServoRegisters


class PeriodChecks:
    """The per-period checks of the servos on `registers.bus`; `gate` is the plausibility gate their positions pass
    (its goal follows a re-armed joint), `every_n` the health read's period in control periods, `to_rad` the
    calibration's map of a position in ticks to the joint's angle."""

    def __init__(self, registers: ServoRegisters, health: ServoHealth, consistency: ConsistencyMonitor,
                 gate: PositionGate, every_n: int, to_rad: Callable[[float], float]):  # fmt: skip
        self.registers, self.health, self.consistency, self.gate = registers, health, consistency, gate
        self.every_n, self.to_rad = every_n, to_rad
        self._countdown = 0
        self._currents: list[int] | None = None  # Present_Current of this period's health read, not yet judged

    def at_connect(self, trusted_ticks) -> None:
        """Before any write: the state block, the servos' setup (firmware, EEPROM limits, startup torque), then the
        health block at the start levels: a hot servo or a weak supply refuses the start before any torque."""
        self.state(trusted_ticks)
        self.health.reset()
        self.health.set_limits(self.registers.check_setup())
        self.check_health(start=True)

    def restore(self) -> None:
        """At configure, torque off: the servos' startup torque and no-host protection (`ServoRegisters.restore`)."""
        if (eeprom := self.registers.restore()) is not None:
            self.health.set_limits(eeprom)

    def state(self, trusted_ticks) -> None:
        """The state block; `trusted_ticks()` reads the present pose through the gate, for a re-armed joint."""
        if tripped := self.registers.check_state():
            ticks = trusted_ticks()
            joints = self.registers.joints
            self.registers.rearm_watchdog(tripped, {j: int(t) for j, t in zip(joints, ticks)})
            if self.gate.goal is not None:
                for j in tripped:
                    self.gate.goal[joints.index(j)] = ticks[joints.index(j)]

    def poll_health(self, *, start: bool) -> None:
        """Once per control period: the health block every `every_n` periods, and at once when a start is pending."""
        self._countdown -= 1
        if start or self._countdown <= 0:
            self._countdown = self.every_n
            self.check_health(start=start)

    def check_health(self, *, start: bool = False) -> None:
        limit = self.registers.expected.get("Goal_Current")
        self._currents = self.health.check(self.registers.bus, limit, start=start)

    def consistency_after(self, q, forces) -> None:
        """After a period's readings (q in rad, forces in N), when its health read brought currents."""
        currents, self._currents = self._currents, None
        if currents is None:
            return
        expected, goal = self.registers.expected, self.gate.goal
        goal_q = None if goal is None or not expected else [self.to_rad(t) for t in goal]
        self.consistency.assess(time.monotonic(), q, goal_q, forces, currents, expected.get("Goal_Current"))
