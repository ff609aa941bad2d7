"""Bus traffic while no control loop runs, so that the servos' bus watchdog stays armed and never trips.

Between trials the gripper holds its start pose with the torque on while a person places the object and presses
ENTER, and while the fingertips are tared (`tare_s`, longer than the 200 ms watchdog). The servos' Bus_Watchdog(98)
is what stops them when this host dies, so it stays armed through those waits; the host keeps it fed instead: one
state check (`hardware/servo_registers.py`, one sync read) every `KEEPALIVE_S`. Each check is also a real check: a servo that
reset or changed a setting during the wait is caught before the next trial, not at its first step.

Disarming the watchdog during the waits (Bus_Watchdog 0) was the other choice; it would leave a host that dies during
a wait with nine servos holding a pose with nobody watching, and a trip needs a clear-and-rearm that a dead host
cannot do anyway. Feeding it keeps the one defence that works without the host.
"""

from __future__ import annotations

from collections.abc import Callable
from concurrent.futures import ThreadPoolExecutor

from lerobot_blindgrasp import spec

# A quarter of the default watchdog (200 ms): the loop's own period, so the bus sees the traffic it sees in a trial.
KEEPALIVE_S = spec.CONTROL_DT


def feeding_the_bus[T](work: Callable[[], T], feed: Callable[[], None]) -> T:
    """`work` (one that touches no servo, e.g. the force tare) in a worker thread while this thread calls `feed` (one
    servo state check) every `KEEPALIVE_S`: every bus packet stays on the caller's thread, and the work's own error
    comes back here."""
    with ThreadPoolExecutor(max_workers=1, thread_name_prefix="force-tare") as pool:
        task = pool.submit(work)
        while True:
            try:
                return task.result(timeout=KEEPALIVE_S)
            except TimeoutError:
                feed()
