"""The per-period check that every servo still holds what `configure()` set.

A brown-out or reset of one servo turns its torque off and restores its RAM defaults without raising any error bit,
so the control loop would go on with a limp finger. One sync read of the contiguous control-table block
Torque_Enable(64) .. Goal_Current(102-103) per control period covers, on all nine servos at once:
- Torque_Enable: a reset or anyone else's torque-off reads 0;
- Hardware_Error_Status: the firmware's own fault bits;
- Position P/I/D gains, Bus_Watchdog and Goal_Current (the torque limit in current-based position mode): RAM
  registers that a reset puts back to factory values;
- Bus_Watchdog also reads 255 (-1) once the servo's watchdog has stopped it after a pause in the bus traffic.
The EEPROM limits (Operating_Mode, Current_Limit, Min/Max_Position_Limit, Drive_Mode, Homing_Offset) need no
per-period read: the firmware refuses EEPROM writes while the torque is on, and the torque is checked here.
"""

from __future__ import annotations

from dataclasses import dataclass

from lerobot.motors.motors_bus import get_address

from lerobot_blindgrasp.xm430 import WATCHDOG_TRIPPED
CHECKED = ("Torque_Enable", "Position_P_Gain", "Position_I_Gain", "Position_D_Gain", "Bus_Watchdog", "Goal_Current")
BLOCK = ("Torque_Enable", "Goal_Current")  # first and last register of the block read


@dataclass(frozen=True)
class ServoReport:
    hardware_error: dict[str, int]  # joint -> Hardware_Error_Status bits
    changed: dict[str, list[str]]  # joint -> "register value (set expected)" for every register that moved
    watchdog_tripped: list[str]  # joints whose bus watchdog stopped them (torque still on, goals refused)


class ServoStateReader:
    """Reads the block through LeRobot's retrying `_sync_read` (one transaction) and compares it."""

    def __init__(self, bus, model: str, joints: list[str]):
        self.bus, self.joints = bus, joints
        table = bus.model_ctrl_table
        self.addr = {n: get_address(table, model, n) for n in (*CHECKED, "Hardware_Error_Status")}
        first, _ = self.addr[BLOCK[0]]
        last, size = self.addr[BLOCK[1]]
        self.start, self.length = first, last + size - first
        self.expected: dict[str, int] = {}

    def read(self, num_retry: int) -> dict[str, dict[str, int]]:
        ids = [self.bus.motors[j].id for j in self.joints]
        self.bus._sync_read(self.start, self.length, ids, num_retry=num_retry,
                            err_msg=f"Failed to sync read the servo state block on {ids=} after {num_retry + 1} tries.")  # fmt: skip
        reader = self.bus.sync_reader
        return {
            j: {name: reader.getData(self.bus.motors[j].id, addr, size) for name, (addr, size) in self.addr.items()}
            for j in self.joints
        }

    def check(self, num_retry: int) -> ServoReport:
        state = self.read(num_retry)
        hw = {j: s["Hardware_Error_Status"] for j, s in state.items() if s["Hardware_Error_Status"]}
        changed: dict[str, list[str]] = {}
        tripped = []
        for j, s in state.items():
            for name, want in self.expected.items():
                got = s[name]
                if name == "Bus_Watchdog" and want and got == WATCHDOG_TRIPPED and s["Torque_Enable"] == 1:
                    tripped.append(j)
                elif got != want:
                    changed.setdefault(j, []).append(f"{name} {got} (set {want})")
        return ServoReport(hw, changed, tripped)
