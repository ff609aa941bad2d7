"""Fingertip sensing from MuJoCo sensor data: uniaxial force, 3-axis contact force, 6-D wrench, tip poses.

The `contact` sensor (reduce="netforce") reports, in the world frame, the net force the fingertip geom exerts on
what it touches; the force *on* the tip is its negative. The load cell's z axis points from the distal joint to the
tip, so a push on the tip end (compression, what a uniaxial cell under the tip measures) is

    f_uni = -(F_on_tip . z) = F_reported . z        (positive in compression)

That is the true force. What the policy sees goes through the sensor pipeline shared with the real gripper,
`lerobot_blindgrasp.hardware.force.reading` (re-exported here as `reading`): true force + noise, then the 0.1 N deadband.
"""

from __future__ import annotations

from dataclasses import dataclass

import mujoco
import numpy as np
import torch

from lerobot_blindgrasp import spec
from lerobot_blindgrasp.hardware.force import reading  # noqa: F401  (the env reads its fingertip sensing from this module)

PER_TIP = ("contact", "objcontact", "force", "torque", "pos", "quat", "zaxis", "objdist")


@dataclass(frozen=True)
class SensorIndex:
    """Column indices into `sensordata` for each (finger, reading), as (n_fingers, dim) integer tensors on the
    device of the sensordata they index."""

    cols: dict[str, torch.Tensor]

    @classmethod
    def from_model(cls, m: mujoco.MjModel, device: torch.device | str = "cpu") -> SensorIndex:
        cols = {}
        for kind in PER_TIP:
            rows = []
            for f in spec.FINGERS:
                s = m.sensor(f"{f}_{kind}")
                rows.append(np.arange(s.adr[0], s.adr[0] + s.dim[0]))
            cols[kind] = torch.as_tensor(np.stack(rows), device=device)
        return cls(cols)

    def read(self, sensordata: torch.Tensor, kind: str) -> torch.Tensor:
        """(n_envs, n_fingers, dim) copy of one reading for all envs."""
        return sensordata[:, self.cols[kind]]


def quat_to_mat(q: torch.Tensor) -> torch.Tensor:
    """wxyz quaternions (..., 4) to rotation matrices (..., 3, 3)."""
    w, x, y, z = q.unbind(-1)
    return torch.stack(
        [
            torch.stack([1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)], -1),
            torch.stack([2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)], -1),
            torch.stack([2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)], -1),
        ],
        -2,
    )


def uniaxial_force(contact_reported: torch.Tensor, zaxis: torch.Tensor) -> torch.Tensor:
    """(n, 3 tips) true compressive force along each tip's z axis (before noise and deadband)."""
    return (contact_reported * zaxis).sum(-1)


def contact_force_tip_frame(contact_reported: torch.Tensor, tip_quat: torch.Tensor) -> torch.Tensor:
    """(n, 3 tips, 3) force on each tip, in the tip (load-cell) frame: minus R^T f, R's columns the tip axes."""
    rot = quat_to_mat(tip_quat)
    return -(rot * contact_reported[..., :, None]).sum(-2)
