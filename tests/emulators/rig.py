"""A complete emulated gripper: the servo bus, the force sensor and how the servos are mounted on the fingers.

The mounting (shaft ticks at the sim's q = 0 and the sign of each servo) is the package's one emulated layout
(`emulators/mount.py`, the physics twin's too): calibration has to discover it. `hand_move` moves joints like
an operator does with the torque off.
"""

from __future__ import annotations

import numpy as np

from emulators.faults import FaultyBus, FaultyForceBoard
from lerobot_blindgrasp import spec
from lerobot_blindgrasp.emulators.mount import MOUNT_SIGN, MOUNT_ZERO, q_for_shaft, shaft_for_q

__all__ = ["LATENCY_TIMER_MS", "MOUNT_SIGN", "GripperRig"]
# Reply timeout for clients of the emulators (see BlindgraspGripperConfig.latency_timer_ms): 2 x 150 + 2 = 302 ms,
# the twin's. A real servo answers within its Return_Delay_Time (0.5 ms), whatever the host does; an emulated one is a
# thread of the test process, so it waits for the CPU and for the GIL whenever the machine is busy, and a thread
# holding the GIL that the OS preempts stalls every other one. On 2 loaded cores such a stall outlasted 122 ms.
LATENCY_TIMER_MS = 150


class GripperRig:
    def __init__(self, force_fn=None, **force_kwargs):
        self.ids = list(spec.SERVO_IDS)
        self.dxl = FaultyBus(self.ids, initial_shaft=dict(zip(self.ids, MOUNT_ZERO)))
        self.force = FaultyForceBoard(force_fn=force_fn, **force_kwargs)

    def start(self) -> GripperRig:
        self.dxl.start()
        self.force.start()
        return self

    def stop(self) -> None:
        self.dxl.stop()
        self.force.stop()

    def __enter__(self):
        return self.start()

    def __exit__(self, *exc):
        self.stop()

    def servo(self, joint: str):
        return self.dxl.servos[self.ids[spec.JOINT_NAMES.index(joint)]]

    def hand_move(self, q) -> None:
        """Put the joints at q (rad, sim convention) by hand."""
        for k, i in enumerate(self.ids):
            self.dxl.servos[i].shaft = float(shaft_for_q(q[k], k))

    def true_q(self) -> np.ndarray:
        """Joint angles from the physical shaft positions (ground truth for the tests)."""
        return q_for_shaft([self.dxl.servos[i].shaft for i in self.ids])

    def place_object(self, contact_q: float = 0.2, stiffness_n_per_rad: float = 100.0, max_n: float = 25.0):
        """A rigid object at the claw centre: each proximal joint (J*1) stops at `contact_q` when closing, and its
        fingertip load cell reads the squeeze, stiffness x (contact_q - commanded q), like a P-controlled servo
        pressing on a rigid body (saturating at the servo's torque)."""
        self.contact_q = contact_q
        for f in range(spec.NUM_FORCES):
            k = 3 * f + 1
            servo = self.dxl.servos[self.ids[k]]
            servo.obstacle = (float(shaft_for_q(contact_q, k)), -int(MOUNT_SIGN[k]))

        def forces() -> np.ndarray:
            out = np.zeros(spec.NUM_FORCES)
            for f in range(spec.NUM_FORCES):
                k = 3 * f + 1
                servo = self.dxl.servos[self.ids[k]]
                if not servo.get("Torque_Enable"):
                    continue
                shaft_goal = servo.position_for(servo.get("Goal_Position"))
                q_goal = float(q_for_shaft(shaft_goal, k))
                out[f] = min(max_n, max(0.0, stiffness_n_per_rad * (contact_q - q_goal)))
            return out

        self.force.force_fn = forces

    def remove_object(self) -> None:
        for servo in self.dxl.servos.values():
            servo.obstacle = None
        self.force.force_fn = None

    def calibration_inputs(self, positive_q: float = 0.3):
        """An `input` replacement that plays the operator of `BlindgraspGripper.calibrate`."""

        def operator(prompt: str = "") -> str:
            if "calibrate again" in prompt:
                return "c"
            if "REFERENCE" in prompt:
                self.hand_move(np.zeros(spec.NUM_JOINTS))
            elif "POSITIVE" in prompt:
                self.hand_move(np.full(spec.NUM_JOINTS, positive_q))
            return ""

        return operator

    def robot_config(self, calibration_dir, **overrides):
        from lerobot_blindgrasp.robots.blindgrasp_gripper import BlindgraspGripperConfig, ForceSensorConfig

        fs = ForceSensorConfig(port=self.force.port, scale_n_per_count=self.force.scale.tolist(), tare_s=0.2)
        # A shared, loaded CI host can stall the emulator thread for longer than the real 34 ms reply window.
        overrides.setdefault("latency_timer_ms", LATENCY_TIMER_MS)
        return BlindgraspGripperConfig(
            id="rig", port=self.dxl.port, calibration_dir=calibration_dir, force_sensor=fs, **overrides
        )
