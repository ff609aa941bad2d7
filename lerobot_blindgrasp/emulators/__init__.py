"""Device emulators that speak the gripper's real wire protocols over pseudo-terminals and UDP.

The production code (dynamixel-sdk, LeRobot's `DynamixelMotorsBus`, the force-sensor reader and the glove
receiver) talks to them unchanged. They serve the test suite and the physics twin alike, so each device has one
emulator. They import neither MuJoCo nor torch.
"""
