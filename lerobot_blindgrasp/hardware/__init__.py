"""The hardware, one home per device, shared by the sim and the real gripper: the XM430 (`xm430`) and its bus
(`dynamixel/`), the load cell (`force`) and the force board (`force_board/`), what serial devices share (`ports`,
`streams`), the host's timing (`realtime`, `loop_timing`), and the checks of the readings (`plausibility`,
`servo_registers`, `servo_diagnostics`, `consistency`, `period_checks`). Nothing here imports MuJoCo."""
