"""LeRobot's `DynamixelMotorsBus` with the bus-level behaviour the gripper's safety depends on (retries on every
transaction, raw registers, an exclusive port, a clean line for every try, stray replies refused, an unplugged
adapter as one `PortLostError`, a handshake that names what is wrong, block reads, a confirmed torque-off). It
overrides only LeRobot's and the SDK's own sub-classing points; their retry loops are reused.
"""

from __future__ import annotations

import logging
import select
import termios
import time

from dynamixel_sdk import COMM_RX_CORRUPT, COMM_SUCCESS, PortHandler
from dynamixel_sdk import port_handler as dxl_port_handler
from dynamixel_sdk.protocol2_packet_handler import (
    PKT_ERROR,
    PKT_ID,
    PKT_INSTRUCTION,
    PKT_LENGTH_H,
    PKT_LENGTH_L,
    Protocol2PacketHandler,
)
from dynamixel_sdk.robotis_def import INST_STATUS
from lerobot.motors import Motor, MotorCalibration
from lerobot.motors.dynamixel import DynamixelMotorsBus
from lerobot.motors.motors_bus import get_address

from lerobot_blindgrasp.hardware.ports import PortAccessError, PortInUseError, open_exclusive
from lerobot_blindgrasp.hardware.xm430 import EXTRA_REGISTERS, MODEL

logger = logging.getLogger(__name__)

_OS_ERRORS = (OSError, termios.error)  # serial.SerialException subclasses OSError; termios.error does not
READ_IDLE_S = 0.001  # longest wait for a reply's next byte between two polls of the SDK (its timeout: >= 2 ms)
ALERT_BIT = 0x80  # status-packet error byte: "hardware error, see Hardware_Error_Status"; the instruction worked


class PortLostError(ConnectionError):
    """The serial adapter stopped working (unplugged, USB reset, driver gone)."""


class FlushingPortHandler(PortHandler):
    """dynamixel-sdk's port, with `clearPort()` (called before every instruction packet) also dropping the input, so
    a late reply of a failed try is never parsed as the next try's answer (the SDK matches replies by ID only), and
    a vanished adapter's OS errors raised as one `PortLostError`."""

    def setupPort(self, cflag_baud):
        # The SDK's own setupPort with the exclusive lock (it also runs on every baud-rate change).
        if self.is_open:
            self.closePort()
        self.ser = open_exclusive(self.port_name, self.baudrate, "Dynamixel bus", timeout=0)
        self.is_open = True
        self.ser.reset_input_buffer()
        self.tx_time_per_byte = (1000.0 / self.baudrate) * 10.0
        return True

    def _lost(self, what: str, e: BaseException) -> PortLostError:
        return PortLostError(f"serial port '{self.port_name}' failed on {what} (USB adapter unplugged?): {e}")

    # After a failed receive (bad CRC, timeout, garbage) the rest of the transaction may still be on its way: the
    # other servos of a sync-read burst keep answering, each after its Return_Delay_Time (up to 0.5 ms by default),
    # so "no byte waiting right now" does not mean "quiet". The next clear therefore drops input until the line has
    # been silent for QUIET_S, several reply gaps long. Successful transactions never pay this wait.
    QUIET_S = 0.01
    MAX_DRAIN_S = 0.1
    line_dirty = False  # set by LineWatchingPacketHandler when a receive failed

    def clearPort(self):
        try:
            self.ser.flush()
            if self.line_dirty:
                self.line_dirty = False
                deadline = time.monotonic() + self.MAX_DRAIN_S
                quiet_since = time.monotonic()
                while time.monotonic() - quiet_since < self.QUIET_S and time.monotonic() < deadline:
                    if self.ser.in_waiting:
                        self.ser.reset_input_buffer()
                        quiet_since = time.monotonic()
                    time.sleep(self.QUIET_S / 10)
            self.ser.reset_input_buffer()
        except _OS_ERRORS as e:
            raise self._lost("flush", e) from e

    def readPort(self, length):
        try:
            data = self.ser.read(length)
            if not data:
                # The SDK calls this in a loop until its reply timeout: wait for a byte (at most READ_IDLE_S) instead
                # of spinning, so a control thread at a real-time priority leaves the CPU to the kernel's tty work
                # at normal priority, which is what delivers the reply.
                select.select([self.ser.fileno()], [], [], READ_IDLE_S)
            return data
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


class LineWatchingPacketHandler(Protocol2PacketHandler):
    """The SDK's protocol-2 packet handler, telling the port when a receive failed (every read path ends here), so
    the next try first waits for the abandoned replies to end (`FlushingPortHandler.clearPort`)."""

    def rxPacket(self, port, fast_option):
        rxpacket, result = super().rxPacket(port, fast_option)
        if result != COMM_SUCCESS:
            port.line_dirty = True
        return rxpacket, result

    def readRx(self, port, dxl_id, length):
        """The SDK's readRx matches a reply by ID only and slices `length` bytes out of whatever came: a late status
        packet of an earlier write (no data) or block read (40 bytes) would be decoded as this read's value. Here
        the reply must be a status packet carrying exactly `length` data bytes, or it is a corrupt reply."""
        while True:
            rxpacket, result = self.rxPacket(port, False)
            if result != COMM_SUCCESS or rxpacket[PKT_ID] == dxl_id:
                break
        if result != COMM_SUCCESS:
            return [], result, 0
        carried = (rxpacket[PKT_LENGTH_L] | rxpacket[PKT_LENGTH_H] << 8) - 4  # INST, ERR, CRC_L, CRC_H
        if rxpacket[PKT_INSTRUCTION] != INST_STATUS or carried != length:
            port.line_dirty = True
            return [], COMM_RX_CORRUPT, 0
        data = list(rxpacket[PKT_ERROR + 1 : PKT_ERROR + 1 + length])
        return data, result, rxpacket[PKT_ERROR]


class RetryingDynamixelBus(DynamixelMotorsBus):
    def __init__(
        self,
        port: str,
        motors: dict[str, Motor],
        calibration: dict[str, MotorCalibration] | None = None,
        *,
        baudrate: int,
        num_retry: int,
        latency_timer_ms: int,
    ):
        super().__init__(port, motors, calibration)
        # The e-Manual's items LeRobot's table lacks (Startup_Configuration, Backup_Ready), for this bus only.
        table = self.model_ctrl_table
        self.model_ctrl_table = {**table, MODEL: {**table[MODEL], **EXTRA_REGISTERS}}
        self.num_retry = num_retry
        self.latency_timer_ms = latency_timer_ms
        self.port_handler = FlushingPortHandler(port)
        self.port_handler.baudrate = baudrate  # the SDK opens the port at this rate: the handshake uses ours
        self.packet_handler = LineWatchingPacketHandler()
        for group in (self.sync_reader, self.sync_writer):
            group.port, group.ph = self.port_handler, self.packet_handler

    @property
    def tries(self) -> int:
        return 1 + self.num_retry

    def use_latency_timer(self) -> None:
        # The SDK sizes every reply timeout (2 x LATENCY_TIMER + 2 ms) from this module constant; there is no
        # per-port setting.
        dxl_port_handler.LATENCY_TIMER = self.latency_timer_ms

    def connect(self, handshake: bool = True) -> None:
        self.use_latency_timer()
        # LeRobot's connect wraps any OSError of the handshake (ConnectionError is one) into "Could not connect ...
        # lerobot-find-port"; the handshake runs after it so that its message names the missing servos.
        try:
            super().connect(handshake=False)
        except ConnectionError as e:  # LeRobot's "Could not connect ... wrong port?" would hide a busy port
            if isinstance(e.__cause__, (PortInUseError, PortAccessError)):
                raise e.__cause__ from None
            raise
        if handshake:
            self._handshake()

    # --- retries and raw registers by default -------------------------------------------------------------------
    def read(self, data_name, motor, *, normalize=False, num_retry=0):
        return super().read(data_name, motor, normalize=normalize, num_retry=max(num_retry, self.num_retry))

    def write(self, data_name, motor, value, *, normalize=False, num_retry=0):
        super().write(data_name, motor, value, normalize=normalize, num_retry=max(num_retry, self.num_retry))

    def sync_read(self, data_name, motors=None, *, normalize=False, num_retry=0):
        return super().sync_read(data_name, motors, normalize=normalize, num_retry=max(num_retry, self.num_retry))

    def sync_write(self, data_name, values, *, normalize=False, num_retry=0):
        super().sync_write(data_name, values, normalize=normalize, num_retry=max(num_retry, self.num_retry))

    # --- handshake and calibration ------------------------------------------------------------------------------
    def _assert_motors_exist(self) -> None:
        # Unlike LeRobot's (one `ping` per servo, no retry), a servo that answers with the alert bit is present.
        found = {m: self.read_despite_alert(m, "Model_Number") for m in self.motors}
        missing = [self.motors[m].id for m, model in found.items() if model is None]
        wrong = {
            self.motors[m].id: model
            for m, model in found.items()
            if model not in (None, self.model_number_table[self.motors[m].model])
        }
        if missing or wrong:
            models = sorted({self.model_number_table[m.model] for m in self.motors.values()})
            raise ConnectionError(
                f"Servo check failed on '{self.port}' at {self.port_handler.baudrate} bps: missing IDs {missing}, "
                f"wrong model numbers {wrong} (expected {models}, {sorted(set(self.models))}). "
                f"{self._silent_hint(missing)}Check power, cabling, IDs (two servos set to one ID answer over each "
                "other, and the other ID goes missing) and the Baud_Rate register (lerobot-setup-motors)."
            )
        self._assert_status_return_level()

    def _silent_hint(self, missing: list[int]) -> str:
        """A servo that answers PING but not READ has Status_Return_Level(68) 0 (PING always gets a reply)."""
        silent = [i for i in missing if self.ping(i, num_retry=self.num_retry) is not None]
        if not silent:
            return ""
        return (f"IDs {silent} answer PING but not READ: their Status_Return_Level(68) is 0 (a tool set it; it is "
                "RAM: power-cycle them, or write 2). ")  # fmt: skip

    def _assert_status_return_level(self) -> None:
        """Status_Return_Level(68) 1 answers READ but not WRITE: every write would time out and its retries end in
        a bus error that names no cause. Named here, before the first write."""
        levels = self.sync_read("Status_Return_Level")
        low = {self.motors[m].id: v for m, v in levels.items() if v != 2}
        if low:
            raise ConnectionError(
                f"Status_Return_Level(68) {low} (by ID): those servos do not reply to writes, so no write can be "
                "confirmed. It is RAM and a tool set it: power-cycle the servos, or write 2."
            )

    def write_calibration(self, calibration_dict: dict[str, MotorCalibration], cache: bool = True) -> None:
        # Drive_Mode (the reverse bit) is half of our calibration; LeRobot's Dynamixel bus leaves it out.
        for motor, c in calibration_dict.items():
            self.write("Drive_Mode", motor, c.drive_mode)
        super().write_calibration(calibration_dict, cache)

    # --- per-period state and the latched stop ------------------------------------------------------------------
    def read_block(self, first: str, last: str, names: tuple[str, ...]) -> dict[str, dict[str, int]]:
        """One sync read of the contiguous registers first..last on every servo; returns `names` per motor."""
        model = next(iter(self.motors.values())).model
        start, _ = get_address(self.model_ctrl_table, model, first)
        end, size = get_address(self.model_ctrl_table, model, last)
        ids = [m.id for m in self.motors.values()]
        err = f"Failed to sync read the {first}..{last} block on {ids=} after {self.tries} tries."
        self._sync_read(start, end + size - start, ids, num_retry=self.num_retry, err_msg=err)
        addrs = {n: get_address(self.model_ctrl_table, model, n) for n in names}
        get = self.sync_reader.getData
        return {motor: {n: get(m.id, a, s) for n, (a, s) in addrs.items()} for motor, m in self.motors.items()}

    def read_despite_alert(self, motor: str, data_name: str) -> int | None:
        """A unicast, retried read that also succeeds on a reply with the alert bit (a servo in hardware error
        still answers); None if the servo never answers."""
        m = self.motors[motor]
        addr, length = get_address(self.model_ctrl_table, m.model, data_name)
        value, comm, _ = self._read(addr, length, m.id, num_retry=self.num_retry, raise_on_error=False)
        return value if self._is_comm_success(comm) else None

    def torque_off_everywhere(self) -> list[int]:
        """Torque off on every servo that can hear it; returns the IDs that did not confirm it."""
        self.port_handler.is_using = False  # an interrupted transaction may have left the SDK's busy flag set
        try:  # one broadcast packet reaches every live servo at once, even if one of them is dead
            self.sync_write("Torque_Enable", 0)
        except Exception as e:
            logger.error("Broadcast torque-off failed: %s", e)
        unconfirmed = []
        for m in self.motors.values():
            addr, length = get_address(self.model_ctrl_table, m.model, "Torque_Enable")
            try:
                comm, error = self._write(addr, length, m.id, 0, num_retry=2, raise_on_error=False)
            except PortLostError:  # nothing reaches any servo any more
                comm, error = -1, 0
                self.port_handler.is_using = False
            if not (self._is_comm_success(comm) and not error & ~ALERT_BIT):
                unconfirmed.append(m.id)
        return unconfirmed
