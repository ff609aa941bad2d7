"""A control loop's time on a PC doing other work: SCHED_FIFO for the control thread (`set_realtime_priority`;
threads started afterwards inherit it), memory that does not page (`lock_memory`: mlockall through libc, which
Python's os module lacks), and no garbage collection inside a trial (`GcPause`). The setters never raise: a refusal
is a warning saying how to allow it, and the loop's own overrun check (`loop_timing.py`) still stops a slow loop.
"""

from __future__ import annotations

import ctypes
import ctypes.util
import errno
import gc
import logging
import os
import resource

logger = logging.getLogger(__name__)

# <sys/mman.h>
MCL_CURRENT, MCL_FUTURE = 1, 2

RTPRIO_HELP = (
    "allow it with `ulimit -r {p}` in the shell that runs the loop, after a line '<user> - rtprio {p}' in "
    "/etc/security/limits.conf (log in again), or give the Python binary CAP_SYS_NICE "
    "(`sudo setcap cap_sys_nice+ep $(readlink -f $(which python))`)"
)
MEMLOCK_HELP = (
    "allow it with a line '<user> - memlock unlimited' in /etc/security/limits.conf (log in again; `ulimit -l` "
    "then says unlimited), or give the Python binary CAP_IPC_LOCK"
)


def set_realtime_priority(priority: int, pid: int = 0) -> str:
    """SCHED_FIFO at `priority` (1-99) for thread `pid` (0: the calling thread); 0 leaves the scheduling alone.
    Returns what it got, in words; a refusal is logged as a warning that says how to allow it."""
    if priority <= 0:
        return "off"
    top = os.sched_get_priority_max(os.SCHED_FIFO)
    if priority > top:
        raise ValueError(f"realtime_priority must be in [0, {top}], got {priority}")
    try:
        os.sched_setscheduler(pid, os.SCHED_FIFO, os.sched_param(priority))
    except PermissionError:
        limit = resource.getrlimit(resource.RLIMIT_RTPRIO)[0]
        msg = (
            f"real-time priority {priority} (SCHED_FIFO) not permitted: this user's RLIMIT_RTPRIO is {limit} and "
            f"the process lacks CAP_SYS_NICE; the loop runs at normal priority. To {RTPRIO_HELP.format(p=priority)}."
        )
        logger.warning(msg)
        return f"not permitted (RLIMIT_RTPRIO {limit})"
    return f"SCHED_FIFO {priority}"


def _libc():
    return ctypes.CDLL(ctypes.util.find_library("c") or "libc.so.6", use_errno=True)


def lock_memory(flags: int = MCL_CURRENT | MCL_FUTURE) -> str:
    """mlockall(`flags`): returns what it got, in words; a refusal is logged as a warning that says how to allow it."""
    if _libc().mlockall(ctypes.c_int(flags)) == 0:
        return "locked"
    err = ctypes.get_errno()
    soft = resource.getrlimit(resource.RLIMIT_MEMLOCK)[0]
    limit = "unlimited" if soft == resource.RLIM_INFINITY else f"{soft // 1024} KiB"
    why = "over RLIMIT_MEMLOCK" if err in (errno.ENOMEM, errno.EPERM) else os.strerror(err)
    msg = (
        f"mlockall failed ({errno.errorcode.get(err, err)}: {why}; RLIMIT_MEMLOCK is {limit}): the loop's memory "
        f"may be paged out. To {MEMLOCK_HELP}."
    )
    logger.warning(msg)
    return f"not locked ({errno.errorcode.get(err, err)}, RLIMIT_MEMLOCK {limit})"


def prepare_host(config) -> dict[str, str]:
    """The control thread's setup from a robot config's `realtime_priority` and `lock_memory`; what it got."""
    priority, lock = config.realtime_priority, config.lock_memory
    got = {"scheduling": set_realtime_priority(priority), "memory": lock_memory() if lock else "off"}
    if priority > 0 or lock:
        logger.info("Control thread: scheduling %s, memory %s.", got["scheduling"], got["memory"])
    return got


class GcPause:
    """Python's cyclic garbage collector kept out of a trial: a full collection with torch and a policy loaded takes
    hundreds of ms with the GIL held (the force reader and the bus watchdog's feed wait too). `pause` freezes what
    exists (gc.freeze) and turns collection off; `resume` turns it on and collects the young generations only."""

    def __init__(self):
        self.paused = False
        self._was_enabled = True

    def pause(self) -> None:
        if self.paused:
            return
        self._was_enabled = gc.isenabled()
        gc.freeze()
        gc.disable()
        self.paused = True

    def resume(self) -> None:
        if not self.paused:
            return
        self.paused = False
        if self._was_enabled:
            gc.enable()
        gc.collect(1)  # the objects made during the pause are all young: with the collector off none was promoted
