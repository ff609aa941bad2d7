"""Bus traffic while no control loop runs (a tare, an operator placing the object): a servo state check every
`KEEPALIVE_S` keeps the servos' Bus_Watchdog armed without tripping it and catches a servo that reset meanwhile.
Disarming it instead would leave a host that dies in a wait with nine torqued servos and nobody watching.
"""

from __future__ import annotations

from collections.abc import Callable
from concurrent.futures import ThreadPoolExecutor

from lerobot_blindgrasp import spec

# A quarter of the default watchdog (200 ms): the loop's own period, so the bus sees the traffic it sees in a trial.
KEEPALIVE_S = spec.CONTROL_DT


def feeding_the_bus[T](work: Callable[[], T], feed: Callable[[], None]) -> T:
    """`work` (touching no servo) in a worker thread while this thread calls `feed` every `KEEPALIVE_S`: every bus
    packet stays on the caller's thread, and the work's own error comes back here."""
    with ThreadPoolExecutor(max_workers=1, thread_name_prefix="force-tare") as pool:
        task = pool.submit(work)
        while True:
            try:
                return task.result(timeout=KEEPALIVE_S)
            except TimeoutError:
                feed()
