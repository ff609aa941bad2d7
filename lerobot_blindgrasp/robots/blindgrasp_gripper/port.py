"""dynamixel-sdk's serial port, with two changes the robot's safety depends on.

1. Every transmission starts on an empty input buffer. The SDK calls `clearPort()` right before it writes each
   instruction packet, including every retry of LeRobot's retry loops, but its `clearPort()` only drains the
   *output*. A reply that arrived late for a failed try (or the rest of a sync-read burst that was abandoned at
   the first bad packet) then stays on the line and is parsed as the answer to the next try; the SDK matches status
   packets by ID only. Discarding the input in `clearPort()` makes each try independent.
2. Operating-system errors of a vanished adapter (pyserial's `SerialException`, a bare `OSError`, or
   `termios.error`, which is not even an `OSError`) come out as one `PortLostError`, so the robot reports a lost
   port instead of a raw termios traceback.
"""

from __future__ import annotations

import termios

from dynamixel_sdk import PortHandler

_OS_ERRORS = (OSError, termios.error)  # serial.SerialException subclasses OSError


class PortLostError(ConnectionError):
    """The serial adapter stopped working (unplugged, USB reset, driver gone)."""


class FlushingPortHandler(PortHandler):
    def _lost(self, what: str, e: BaseException) -> PortLostError:
        return PortLostError(f"serial port '{self.port_name}' failed on {what} (USB adapter unplugged?): {e}")

    def clearPort(self):
        try:
            self.ser.reset_input_buffer()
            self.ser.flush()
        except _OS_ERRORS as e:
            raise self._lost("flush", e) from e

    def readPort(self, length):
        try:
            return self.ser.read(length)
        except _OS_ERRORS as e:
            raise self._lost("read", e) from e

    def writePort(self, packet):
        try:
            return self.ser.write(packet)
        except _OS_ERRORS as e:
            raise self._lost("write", e) from e

    def getBytesAvailable(self):
        try:
            return self.ser.in_waiting
        except _OS_ERRORS as e:
            raise self._lost("poll", e) from e

    def closePort(self):
        # Closing a dead adapter must not raise: it runs in the cleanup of every fault.
        try:
            if self.ser is not None:
                self.ser.close()
        except _OS_ERRORS:
            pass
        self.is_open = False


def use_flushing_port(bus) -> None:
    """Give a (not yet connected) `DynamixelMotorsBus` the port above; its group readers/writers share it."""
    port = FlushingPortHandler(bus.port)
    port.baudrate = bus.port_handler.baudrate
    bus.port_handler = port
    bus.sync_reader.port = port
    bus.sync_writer.port = port
