"""The XM430-W350's control table as the emulated firmware keeps it (ROBOTIS e-Manual, "Control Table of EEPROM
Area" and "of RAM Area"): addresses, sizes, access, factory values, and the checks the firmware makes on a write.

Indirect_Address/Indirect_Data (168..661) are not kept: nothing on the host addresses them."""

from __future__ import annotations

from dynamixel_sdk import protocol2_packet_handler as p2

# name: (address, size, signed, access) ; access "ro" | "eeprom" | "ram"
CONTROL_TABLE: dict[str, tuple[int, int, bool, str]] = {
    "Model_Number": (0, 2, False, "ro"),
    "Model_Information": (2, 4, False, "ro"),
    "Firmware_Version": (6, 1, False, "ro"),
    "ID": (7, 1, False, "eeprom"),
    "Baud_Rate": (8, 1, False, "eeprom"),
    "Return_Delay_Time": (9, 1, False, "eeprom"),
    "Drive_Mode": (10, 1, False, "eeprom"),
    "Operating_Mode": (11, 1, False, "eeprom"),
    "Secondary_ID": (12, 1, False, "eeprom"),
    "Protocol_Type": (13, 1, False, "eeprom"),
    "Homing_Offset": (20, 4, True, "eeprom"),
    "Moving_Threshold": (24, 4, False, "eeprom"),
    "Temperature_Limit": (31, 1, False, "eeprom"),
    "Max_Voltage_Limit": (32, 2, False, "eeprom"),
    "Min_Voltage_Limit": (34, 2, False, "eeprom"),
    "PWM_Limit": (36, 2, False, "eeprom"),
    "Current_Limit": (38, 2, False, "eeprom"),
    "Acceleration_Limit": (40, 4, False, "eeprom"),
    "Velocity_Limit": (44, 4, False, "eeprom"),
    "Max_Position_Limit": (48, 4, False, "eeprom"),
    "Min_Position_Limit": (52, 4, False, "eeprom"),
    "Startup_Configuration": (60, 1, False, "eeprom"),  # firmware v45 and later
    "Shutdown": (63, 1, False, "eeprom"),
    "Torque_Enable": (64, 1, False, "ram"),
    "LED": (65, 1, False, "ram"),
    "Status_Return_Level": (68, 1, False, "ram"),
    "Registered_Instruction": (69, 1, False, "ro"),
    "Hardware_Error_Status": (70, 1, False, "ro"),
    "Velocity_I_Gain": (76, 2, False, "ram"),
    "Velocity_P_Gain": (78, 2, False, "ram"),
    "Position_D_Gain": (80, 2, False, "ram"),
    "Position_I_Gain": (82, 2, False, "ram"),
    "Position_P_Gain": (84, 2, False, "ram"),
    "Feedforward_2nd_Gain": (88, 2, False, "ram"),
    "Feedforward_1st_Gain": (90, 2, False, "ram"),
    "Bus_Watchdog": (98, 1, False, "ram"),
    "Goal_PWM": (100, 2, True, "ram"),
    "Goal_Current": (102, 2, True, "ram"),
    "Goal_Velocity": (104, 4, True, "ram"),
    "Profile_Acceleration": (108, 4, False, "ram"),
    "Profile_Velocity": (112, 4, False, "ram"),
    "Goal_Position": (116, 4, True, "ram"),
    "Realtime_Tick": (120, 2, False, "ro"),
    "Moving": (122, 1, False, "ro"),
    "Moving_Status": (123, 1, False, "ro"),
    "Present_PWM": (124, 2, True, "ro"),
    "Present_Current": (126, 2, True, "ro"),
    "Present_Velocity": (128, 4, True, "ro"),
    "Present_Position": (132, 4, True, "ro"),
    "Velocity_Trajectory": (136, 4, True, "ro"),
    "Position_Trajectory": (140, 4, True, "ro"),
    "Present_Input_Voltage": (144, 2, False, "ro"),
    "Present_Temperature": (146, 1, False, "ro"),
    "Backup_Ready": (147, 1, False, "ro"),  # firmware v45 and later
}
TABLE_SIZE = 148
EEPROM_END = 64  # addresses below are EEPROM: kept over a reboot, locked while the torque is on
XM430_W350_MODEL = 1020
BAUD_REGISTER = {9600: 0, 57600: 1, 115200: 2, 1_000_000: 3, 2_000_000: 4, 3_000_000: 5, 4_000_000: 6}

# Hardware_Error_Status bits (e-Manual, XM430 "Hardware Error Status(70)").
HW_INPUT_VOLTAGE, HW_OVERHEATING, HW_OVERLOAD = 0x01, 0x04, 0x20
STARTUP_TORQUE_ON, STARTUP_RAM_RESTORE = 0x01, 0x02  # Startup_Configuration(60) bits

DEFAULTS = {
    "Model_Number": XM430_W350_MODEL,
    "Firmware_Version": 46,
    "Baud_Rate": 3,
    "Return_Delay_Time": 250,
    "Operating_Mode": 3,
    "Secondary_ID": 255,
    "Protocol_Type": 2,
    "Moving_Threshold": 10,
    "Temperature_Limit": 80,
    "Max_Voltage_Limit": 160,
    "Min_Voltage_Limit": 95,
    "PWM_Limit": 885,
    "Current_Limit": 1193,
    "Acceleration_Limit": 32767,
    "Velocity_Limit": 200,
    "Max_Position_Limit": 4095,
    "Min_Position_Limit": 0,
    "Shutdown": 52,
    "Status_Return_Level": 2,
    "Velocity_I_Gain": 1920,
    "Velocity_P_Gain": 100,
    "Position_P_Gain": 800,
    "Goal_PWM": 885,
    "Goal_Current": 1193,
    "Present_Input_Voltage": 120,
    "Present_Temperature": 35,
}


# The e-Manual's range of the registers the firmware range-checks on a write.
RANGES = {"Torque_Enable": (0, 1), "Bus_Watchdog": (0, 127), "Current_Limit": (0, 1193), "Min_Position_Limit": (0, 4095),
          "Max_Position_Limit": (0, 4095), "Homing_Offset": (-1_044_479, 1_044_479)}  # fmt: skip
OPERATING_MODES = (0, 1, 3, 4, 5, 16)


def write_error(servo, staged, names: list[str]) -> int:
    """The status error code the firmware answers a write with (0: accepted), `staged` holding the registers as
    they would be after it."""
    for name in names:
        value = staged.get(name)
        lo, hi = RANGES.get(name, (value, value))
        if not lo <= value <= hi or (name == "Operating_Mode" and value not in OPERATING_MODES):
            return p2.ERRNUM_DATA_RANGE
        if name == "Startup_Configuration" and value & ~(STARTUP_TORQUE_ON | STARTUP_RAM_RESTORE):
            return p2.ERRNUM_DATA_RANGE
        if name.startswith("Goal_") and servo.get("Bus_Watchdog") == 255:
            return p2.ERRNUM_DATA_RANGE  # goal registers are read-only after a watchdog stop
        if name == "Goal_Current" and abs(value) > servo.get("Current_Limit"):
            return p2.ERRNUM_DATA_LIMIT
        if name == "Goal_Position" and servo.get("Operating_Mode") == 3:
            if not servo.get("Min_Position_Limit") <= value <= servo.get("Max_Position_Limit"):
                return p2.ERRNUM_DATA_LIMIT
    return 0
