"""Process signals while the gripper is connected. SIGTERM and SIGHUP kill a Python process outright by default (no
`finally`, no `atexit`: nine servos left torqued); while connected, one that still has its default action raises
`SystemExit(128 + signum)` instead, which unwinds like Ctrl-C (a handler someone installed is left alone).
`deferred()` holds a second Ctrl-C or SIGTERM until the torque-off it interrupts is done.
"""

from __future__ import annotations

import logging
import signal
import threading
from contextlib import contextmanager

from lerobot_blindgrasp import compat

logger = logging.getLogger(__name__)

TERMINATION_SIGNALS = tuple(getattr(signal, n) for n in ("SIGTERM", "SIGHUP") if hasattr(signal, n))
_DEFERRED_SIGNALS = (signal.SIGINT, *TERMINATION_SIGNALS)
_owners: set[int] = set()  # ids of the connected robots that asked for the handlers
_exiting = False


def _on_termination(signum, frame):
    global _exiting
    if _exiting:  # the cleanup of the first one is running: let it finish
        logger.warning("%s received again; still stopping.", signal.Signals(signum).name)
        return
    _exiting = True
    logger.warning("%s received: stopping; the cleanup turns the gripper torque off.", signal.Signals(signum).name)
    raise SystemExit(128 + signum)


def _in_main_thread() -> bool:
    return threading.current_thread() is threading.main_thread()


def install_termination_handlers(owner: object) -> None:
    global _exiting
    if not _in_main_thread():
        return
    if not _owners:
        _exiting = False
    _owners.add(id(owner))
    for sig in TERMINATION_SIGNALS:
        if signal.getsignal(sig) is signal.SIG_DFL:
            compat.set_signal_handler(sig, _on_termination)


def uninstall(owner: object) -> None:
    _owners.discard(id(owner))
    if _owners or not _in_main_thread():
        return
    for sig in TERMINATION_SIGNALS:
        if signal.getsignal(sig) is _on_termination:
            compat.set_signal_handler(sig, signal.SIG_DFL)


@contextmanager
def deferred():
    """Hold SIGINT/SIGTERM/SIGHUP until the block ends, then deliver the first one that came."""
    if not _in_main_thread():
        yield
        return
    pending: list[int] = []
    previous = {}
    for sig in _DEFERRED_SIGNALS:
        previous[sig] = compat.set_signal_handler(sig, lambda signum, frame: pending.append(signum))
    try:
        yield
    finally:
        for sig, handler in previous.items():
            compat.set_signal_handler(sig, handler if handler is not None else signal.SIG_DFL)
        if pending:
            signal.raise_signal(pending[0])
