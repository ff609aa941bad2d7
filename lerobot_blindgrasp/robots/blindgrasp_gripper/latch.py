"""The safety latch: any failure while connected turns the torque off on every servo that answers, closes both ports
and raises one error that says so. `SafetyLatch.guard(what)` wraps every call of the gripper that touches the
hardware and names the failure (`errors.py`); reconnecting is the operator's decision. While armed, the process is
guarded too: `atexit`, an uncaught exception before Python reports it (a script's cleanup can fail before its
disconnect), and SIGTERM/SIGHUP unwinding like Ctrl-C (`signals.py`).
"""

from __future__ import annotations

import atexit
import logging
import sys
import weakref
from collections.abc import Callable
from contextlib import contextmanager

from lerobot_blindgrasp import compat
from lerobot_blindgrasp.hardware.consistency import ConsistencyError
from lerobot_blindgrasp.hardware.dynamixel.bus import PortLostError
from lerobot_blindgrasp.hardware.force_board.reader import ForceStreamError, ForceTareError
from lerobot_blindgrasp.hardware.loop_timing import LoopOverrunError
from lerobot_blindgrasp.hardware.plausibility import ImplausibleReadingError
from lerobot_blindgrasp.hardware.ports import PortAccessError, PortInUseError
from lerobot_blindgrasp.hardware.servo_diagnostics import ServoHealthError, ServoStallError
from lerobot_blindgrasp.hardware.servo_registers import (
    FirmwareTooOldError,
    ProtectionNotKeptError,
    ServoFaultError,
    ServoStateChangedError,
)

from . import signals
from .errors import (
    ForceSensorError,
    GripperBusError,
    GripperConsistencyError,
    GripperFirmwareError,
    GripperHardwareError,
    GripperHealthError,
    GripperPortAccessError,
    GripperPortBusyError,
    GripperProtectionError,
    GripperReadingError,
    GripperSafetyStop,
    GripperStallError,
    GripperStateError,
    GripperTimingError,
)

logger = logging.getLogger(__name__)

# What the latched stop raises for a failure below it: (cause, named error or None to keep the type, prefix).
_NAMED_STOPS = (
    (GripperSafetyStop, None, ""),
    (PortInUseError, GripperPortBusyError, ""),
    (PortAccessError, GripperPortAccessError, ""),
    (ImplausibleReadingError, GripperReadingError, "Stopped while {what}: "),
    (LoopOverrunError, GripperTimingError, ""),
    (ForceTareError, None, ""),
    (PortLostError, GripperBusError, "Dynamixel port lost while {what}: "),
    (ForceStreamError, ForceSensorError, "Force sensor failure while {what}: "),
    (FirmwareTooOldError, GripperFirmwareError, ""),
    (ProtectionNotKeptError, GripperProtectionError, ""),
    (ServoFaultError, GripperHardwareError, ""),
    (ServoStateChangedError, GripperStateError, ""),
    (ServoStallError, GripperStallError, ""),
    (ServoHealthError, GripperHealthError, ""),
    (ConsistencyError, GripperConsistencyError, "Inputs disagree: "),
)

_connected: weakref.WeakSet = weakref.WeakSet()  # latches of grippers to stop on an uncaught exception
_chained_hook = None  # the excepthook ours replaced


def _stop_then_report(exc_type, exc, tb) -> None:
    for latch in list(_connected):
        if latch.bus.is_connected:
            logger.error("%s ends the program with %s still connected (the script's cleanup did not reach its "
                         "disconnect): turning the torque off now.", exc_type.__name__, latch.name)  # fmt: skip
            latch.stop()
    (_chained_hook or sys.__excepthook__)(exc_type, exc, tb)


def _guard(latch) -> None:
    global _chained_hook
    _connected.add(latch)
    if sys.excepthook is not _stop_then_report:
        _chained_hook = compat.set_excepthook(_stop_then_report)


def _unguard(latch) -> None:
    global _chained_hook
    _connected.discard(latch)
    if not _connected and sys.excepthook is _stop_then_report:
        compat.set_excepthook(_chained_hook or sys.__excepthook__)
        _chained_hook = None


class SafetyLatch:
    """The latched stop of one gripper: its servo `bus` (torque off on `servo_ids`, then closed) and its `force`
    reader (closed). `on_torque_off` drops what the gripper expects of torqued servos, `on_close` undoes what its
    connect installed, `report` gives the session's margins for the log; `name` names the gripper in messages."""

    def __init__(self, name: str, bus, force, servo_ids, *, on_torque_off: Callable[[], None],
                 on_close: Callable[[], None], report: Callable[[], str]):  # fmt: skip
        self.name, self.bus, self.force, self.servo_ids = name, bus, force, list(servo_ids)
        self._on_torque_off, self._on_close, self._report = on_torque_off, on_close, report
        self._atexit = None
        self.stopped_while: str | None = None  # what the gripper was doing when a fault stopped it, until re-armed

    @contextmanager
    def guard(self, what: str):
        try:
            yield
        except BaseException as e:
            if getattr(e, "torque_off_handled", False):
                raise  # an inner guard already stopped the gripper and wrote the message
            was_open = self.bus.is_connected
            self.stopped_while = what
            unconfirmed = self.stop()
            if not was_open:
                note = "The bus port was not open, so no torque was enabled by this process."
            elif unconfirmed:
                note = f"Torque-off NOT confirmed by servo IDs {unconfirmed}: cut the servo power."
            else:
                note = "Torque is off on all servos."
            err = self._named_stop(e, what, note)
            if err is None:  # KeyboardInterrupt, a programming error: the original exception, torque off
                logger.error("%s while %s. %s", type(e).__name__, what, note)
                e.torque_off_handled = True
                raise
            err.torque_off_handled = True
            err.torque_off_confirmed = was_open and not unconfirmed
            raise err from e

    def _named_stop(self, e: BaseException, what: str, note: str) -> BaseException | None:
        named = next(((stop, prefix) for cause, stop, prefix in _NAMED_STOPS if isinstance(e, cause)), None)
        if named is not None:
            stop, prefix = named
            return (stop or type(e))(f"{prefix.format(what=what)}{e} {note}")
        if isinstance(e, (ConnectionError, RuntimeError, OSError)):
            tries = self.bus.tries
            return GripperBusError(f"Dynamixel bus failure while {what} (each transaction tried {tries} times): {e} "
                                   f"{note}")  # fmt: skip
        return None

    def stop(self) -> list[int]:
        """Latched stop: torque off on every servo (returns the IDs that did not confirm it), then close both ports."""
        logger.info("%s %s", self.name, self._report())  # the margins of the consistency checks, per session
        unconfirmed = list(self.servo_ids)
        with signals.deferred():  # a second Ctrl-C or SIGTERM must not cut the torque-off short
            if self.bus.is_connected:
                try:
                    self._on_torque_off()
                    unconfirmed = self.bus.torque_off_everywhere()
                finally:
                    self.close()
            else:
                self.close()
        return unconfirmed

    def close(self) -> None:
        if self.bus.is_connected:
            self.bus.disconnect(disable_torque=False)  # the torque-off, when wanted, was stop's
        self.force.disconnect()
        signals.uninstall(self)
        self._on_close()
        _unguard(self)
        if self._atexit is not None:
            atexit.unregister(self._atexit)
            self._atexit = None

    def arm(self) -> None:
        """While connected: stop at interpreter exit and before an uncaught exception is reported; SIGTERM and SIGHUP
        unwind like Ctrl-C."""
        ref = weakref.ref(self)
        self.stopped_while = None

        def _at_exit():
            latch = ref()
            if latch is not None and latch.bus.is_connected:
                latch.stop()

        self._atexit = _at_exit
        atexit.register(_at_exit)
        _guard(self)
        signals.install_termination_handlers(self)
