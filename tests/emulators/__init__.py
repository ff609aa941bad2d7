"""Device emulators that speak the gripper's real wire protocols over pseudo-terminals and UDP.

They stand in for hardware in the tests of `tests/robots/`, `tests/hardware/` and `tests/teleoperators/`: the
production code (dynamixel-sdk, LeRobot's `DynamixelMotorsBus`, our force-sensor reader and glove receiver) talks
to them unchanged.
"""
