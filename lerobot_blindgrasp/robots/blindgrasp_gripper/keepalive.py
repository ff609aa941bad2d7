"""Bus traffic while no control loop runs, so that the servos' bus watchdog stays armed and never trips.

Between trials the gripper holds its start pose with the torque on while a person places the object and presses
ENTER, and while the fingertips are tared (`tare_s`, longer than the 200 ms watchdog). The servos' Bus_Watchdog(98)
is what stops them when this host dies, so it stays armed through those waits; the host keeps it fed instead: one
state check (`servo_checks.py`, one sync read) every `KEEPALIVE_S`. Each check is also a real check: a servo that
reset or changed a setting during the wait is caught before the next trial, not at its first step.

Disarming the watchdog during the waits (Bus_Watchdog 0) was the other choice; it would leave a host that dies during
a wait with nine servos holding a pose with nobody watching, and a trip needs a clear-and-rearm that a dead host
cannot do anyway. Feeding it keeps the one defence that works without the host.
"""

from __future__ import annotations

from concurrent.futures import ThreadPoolExecutor

from lerobot.utils.decorators import check_if_not_connected

from lerobot_blindgrasp import spec

# A quarter of the default watchdog (200 ms): the loop's own period, so the bus sees the traffic it sees in a trial.
KEEPALIVE_S = spec.CONTROL_DT


class BusKeepAlive:
    """Mixed into `BlindgraspGripper`: needs its `_safety`, `_check_servo_state`, `force` and `config`."""

    @check_if_not_connected
    def keep_alive(self) -> None:
        """One servo state check outside the control loop (a wait for the operator): call it every `KEEPALIVE_S`."""
        with self._safety("keeping the bus alive while waiting"):
            self._check_servo_state()

    def _tare_keeping_bus_alive(self):
        """The force tare (force port only) in a worker thread while this thread feeds the servo bus: every bus
        packet stays on the caller's thread, and the tare's own error comes back here."""
        with ThreadPoolExecutor(max_workers=1, thread_name_prefix="force-tare") as pool:
            tare = pool.submit(self.force.tare, self.config.force_sensor.tare_s)
            while True:
                try:
                    return tare.result(timeout=KEEPALIVE_S)
                except TimeoutError:
                    self._check_servo_state()
