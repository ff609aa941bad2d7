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

from lerobot_blindgrasp.hardware.xm430 import WATCHDOG_TRIPPED

CHECKED = (
    "Torque_Enable",
    "Position_P_Gain",
    "Position_I_Gain",
    "Position_D_Gain",
    "Bus_Watchdog",
    "Goal_Current",
)
BLOCK = ("Torque_Enable", "Goal_Current")  # first and last register of the block read (40 bytes per servo)
READ = (*CHECKED, "Hardware_Error_Status")


@dataclass(frozen=True)
class ServoReport:
    hardware_error: dict[str, int]  # joint -> Hardware_Error_Status bits
    changed: dict[str, list[str]]  # joint -> "register value (set expected)" for every register that moved
    watchdog_tripped: list[str]  # joints whose bus watchdog stopped them (torque still on, goals refused)


def compare(state: dict[str, dict[str, int]], expected: dict[str, int]) -> ServoReport:
    """What the block read (`RetryingDynamixelBus.read_block(*BLOCK, READ)`) says against what was set."""
    hw = {j: s["Hardware_Error_Status"] for j, s in state.items() if s["Hardware_Error_Status"]}
    changed: dict[str, list[str]] = {}
    tripped = []
    for j, s in state.items():
        for name, want in expected.items():
            got = s[name]
            if name == "Bus_Watchdog" and want and got == WATCHDOG_TRIPPED and s["Torque_Enable"] == 1:
                tripped.append(j)
            elif got != want:
                changed.setdefault(j, []).append(f"{name} {got} (set {want})")
    return ServoReport(hw, changed, tripped)
