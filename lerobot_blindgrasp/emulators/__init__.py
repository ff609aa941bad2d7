"""Device emulators that speak the gripper's real wire protocols over pseudo-terminals.

The production code (dynamixel-sdk, LeRobot's `DynamixelMotorsBus`, the force-sensor reader) talks to them
unchanged. They serve the test suite and the physics twin alike, so each device has one emulator. They import
neither MuJoCo nor torch. The glove's emulated bridge serves only the tests: it is `tests/emulators/glove_sender.py`.
"""
