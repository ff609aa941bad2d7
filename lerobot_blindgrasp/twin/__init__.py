"""The physics twin of the gripper (`blindgrasp-twin`, docs/hardware.md): the serial emulators with MuJoCo behind
them. Importing this package imports no MuJoCo: only the twin's process loads `physics.py`."""
