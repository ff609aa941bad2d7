"""The safety latch: any failure while connected turns the torque off on every servo that answers, closes both ports
and raises one error that says so.

`SafetyLatch._safety(what)` wraps every call that touches the hardware (connect, configure, get_observation,
send_action, tares, health checks). Its causes: a bus error after the retries, a lost port, a servo hardware
error, a servo that reset or lost its settings, an implausible reading, force overload, stale or frozen force data,
a sustained loop overrun, a servo near a limit, an exception, Ctrl-C or SIGTERM/SIGHUP inside a call. Reconnecting
is an explicit decision of the operator.

Outside the calls, the process itself is guarded: `atexit` stops a gripper left connected, and so does an uncaught
exception before Python reports it (`sys.excepthook`). The second matters when a script's cleanup fails before its
disconnect: lerobot-record's `finally` runs `dataset.finalize()` before `robot.disconnect()`, so a full disk there
skips the disconnect, and an interpreter that cannot exit (a thread that never ends) would never reach `atexit`.
"""

from __future__ import annotations

import atexit
import logging
import sys
import weakref
from contextlib import contextmanager

from lerobot_blindgrasp import compat
from lerobot_blindgrasp.hardware.dynamixel.bus import PortLostError
from lerobot_blindgrasp.hardware.force_board.reader import ForceStreamError, ForceTareError
from lerobot_blindgrasp.hardware.ports import PortAccessError, PortInUseError

from . import signals
from .errors import (
    ForceSensorError,
    GripperBusError,
    GripperPortAccessError,
    GripperPortBusyError,
    GripperReadingError,
    GripperSafetyStop,
    GripperTimingError,
)
from .plausibility import ImplausibleReadingError
from .timing import LoopOverrunError

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
)

_connected: weakref.WeakSet = weakref.WeakSet()  # grippers to stop on an uncaught exception
_chained_hook = None  # the excepthook ours replaced


def _stop_then_report(exc_type, exc, tb) -> None:
    for robot in list(_connected):
        if robot.is_connected:
            logger.error("%s ends the program with %s still connected (the script's cleanup did not reach its "
                         "disconnect): turning the torque off now.", exc_type.__name__, robot)  # fmt: skip
            robot._stop()
    (_chained_hook or sys.__excepthook__)(exc_type, exc, tb)


def _guard(robot) -> None:
    global _chained_hook
    _connected.add(robot)
    if sys.excepthook is not _stop_then_report:
        _chained_hook = compat.set_excepthook(_stop_then_report)


def _unguard(robot) -> None:
    global _chained_hook
    _connected.discard(robot)
    if not _connected and sys.excepthook is _stop_then_report:
        compat.set_excepthook(_chained_hook or sys.__excepthook__)
        _chained_hook = None


class SafetyLatch:
    """Mixin of `BlindgraspGripper` (it holds `bus`, `force`, `gate`, `expected`, `config`): the latched stop."""

    @contextmanager
    def _safety(self, what: str):
        try:
            yield
        except BaseException as e:
            if getattr(e, "torque_off_handled", False):
                raise  # an inner _safety already stopped the gripper and wrote the message
            was_open = self.bus.is_connected
            unconfirmed = self._stop()
            if not was_open:
                note = "The bus port was not open, so no torque was enabled by this process."
            elif unconfirmed:
                note = f"Torque-off NOT confirmed by servo IDs {unconfirmed}: cut the servo power."
            else:
                note = "Torque is off on all servos."
            err = self._named_stop(e, what, note)
            if (
                err is None
            ):  # KeyboardInterrupt, programming errors: keep the original exception, the torque is off
                logger.error("%s while %s. %s", type(e).__name__, what, note)
                e.torque_off_handled = True
                raise
            err.torque_off_handled = True
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

    def _torque_off_all(self) -> list[int]:
        """Torque off on every servo; returns the IDs that did not confirm it."""
        self.expected = {}
        self.gate.forget()
        return self.bus.torque_off_everywhere()

    def _stop(self) -> list[int]:
        """Latched stop: torque off, then close both ports."""
        logger.info("%s %s", self, self.consistency.report())  # the margins of the consistency checks, per session
        unconfirmed = list(self.config.servo_ids)
        with signals.deferred():  # a second Ctrl-C or SIGTERM must not cut the torque-off short
            if self.bus.is_connected:
                try:
                    unconfirmed = self._torque_off_all()
                finally:
                    self._close()
            else:
                self._close()
        return unconfirmed

    def _close(self) -> None:
        if self.bus.is_connected:
            self.bus.disconnect(disable_torque=False)  # the torque-off, when wanted, was _stop's
        self.force.disconnect()
        signals.uninstall(self)
        self.episodes.uninstall()
        _unguard(self)
        if self._atexit is not None:
            atexit.unregister(self._atexit)
            self._atexit = None

    def _guard_process(self) -> None:
        """While connected: stop at interpreter exit and before an uncaught exception is reported."""
        ref = weakref.ref(self)

        def _at_exit():
            robot = ref()
            if robot is not None and robot.is_connected:
                robot._stop()

        self._atexit = _at_exit
        atexit.register(_at_exit)
        _guard(self)

    def __exit__(self, exc_type, exc_value, traceback) -> None:
        # After a latched safety stop the robot is already disconnected: LeRobot's __exit__ would raise
        # DeviceNotConnectedError and hide the fault that stopped it. Let that fault propagate instead.
        if self.is_connected:
            self.disconnect()
