"""Device emulators that speak the gripper's real wire protocols over pseudo-terminals, for the tests and the physics
twin (one emulator per device; no MuJoCo, no torch). The glove's emulated bridge is `tests/emulators/glove_sender.py`."""
