"""The physics twin of the gripper (`blindgrasp-twin`): the real stack's serial ports, with MuJoCo behind them.

The Dynamixel bus and the force board are the package's own emulators (`emulators/`) on pseudo-terminals;
the twin plugs MuJoCo into them (the servo emulator's `ShaftDynamics` hook, the force board's `force_fn`) and runs
the project's gripper and object models in real time. An operator socket lets `--env.type=blindgrasp_real` run
unattended: the twin places each trial's object from (seed, object) and judges success by the sim's own rule.

Importing this package imports no MuJoCo (`physics.py` does, and only the twin's process loads it).
"""
