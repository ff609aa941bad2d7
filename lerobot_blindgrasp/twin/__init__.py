"""The physics twin of the gripper (`blindgrasp-twin`): the package's serial emulators on pseudo-terminals with
MuJoCo behind them, and an operator socket that places and judges each trial (docs/hardware.md). Importing this
package imports no MuJoCo: only the twin's process loads `physics.py`.
"""
