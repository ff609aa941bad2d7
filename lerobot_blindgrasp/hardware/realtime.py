"""A host process that keeps a control loop's time on a PC doing other work: a real-time scheduling priority for the
control thread, memory that does not page, and Python's garbage collector kept out of a trial.

Each setter says what it got and, when the kernel refuses, why and how to allow it; none raises, because the loop's
own overrun check (`loop_timing.py`) still stops a loop that cannot keep its period.

- `set_realtime_priority`: SCHED_FIFO for the calling thread (Linux: threads it starts afterwards inherit it, so call
  it before the force reader's thread and torch's worker threads start). The kernel's RT throttling
  (`/proc/sys/kernel/sched_rt_runtime_us`, 95 % by default) still leaves other processes a share of each core.
  Allowed to root, to a process with CAP_SYS_NICE, or up to the user's RLIMIT_RTPRIO (`ulimit -r`).
- `lock_memory`: mlockall(MCL_CURRENT | MCL_FUTURE) through libc (Python's os module has no mlockall). A page the
  loop needs is then never written out and read back from disk in the middle of a period. Allowed with CAP_IPC_LOCK
  or within RLIMIT_MEMLOCK (`ulimit -l`), which a torch process far exceeds at the usual 8 MiB default.
- `GcPause`: what exists at a trial's start is frozen out of the collector's reach, the collector is off during the
  trial, and the young objects are collected once at its end.
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
    """Python's cyclic garbage collector kept out of a stretch of time-critical work (a trial).

    A full collection in a host with LeRobot, torch and a policy loaded walks some 400 000 objects: hundreds of ms,
    in the middle of a period whenever the collector's thresholds say so, with the GIL held (so the force reader's
    thread waits too, and no packet keeps the servos' bus watchdog fed). So `pause` first freezes what exists
    (gc.freeze: the loaded modules, the policy and the robot, which live as long as the process, are never scanned
    again) and turns automatic collection off; `resume` turns it back on and collects the young generations only:
    the cycles made since the pause, a fraction of a ms, never a full pass. Reference counting still frees almost
    everything a period allocates; only cycles wait for the end of the trial."""

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
