"""Fingertip sensing from MuJoCo sensor data: uniaxial force, contact force, 6-D wrench, tip poses.

The `contact` sensor (netforce, world frame) reports the force the tip exerts; the load cell's z axis points from
the distal joint to the tip, so the true uniaxial force is f_uni = F_reported . z (positive in compression). The
policy sees it through `hardware.force.reading`, shared with the real gripper."""

from __future__ import annotations

from dataclasses import dataclass

import mujoco
import numpy as np
import torch

from lerobot_blindgrasp import spec

PER_TIP = ("contact", "objcontact", "force", "torque", "pos", "quat", "zaxis", "objdist")


@dataclass(frozen=True)
class SensorIndex:
    """`sensordata` columns of each (finger, reading), (n_fingers, dim) on its device. `block`: (first column,
    columns per finger) when the fingers' readings share one layout, so that a reading is a view, not a gather."""

    cols: dict[str, torch.Tensor]
    block: tuple[int, int] | None = None
    spans: dict[str, tuple[int, int]] | None = None  # kind -> (offset in a finger's block, dim)

    @classmethod
    def from_model(cls, m: mujoco.MjModel, device: torch.device | str = "cpu") -> SensorIndex:
        cols = {}
        for kind in PER_TIP:
            rows = []
            for f in spec.FINGERS:
                s = m.sensor(f"{f}_{kind}")
                rows.append(np.arange(s.adr[0], s.adr[0] + s.dim[0]))
            cols[kind] = np.stack(rows)
        first = min(int(c[0, 0]) for c in cols.values())
        width = sum(c.shape[1] for c in cols.values())
        regular = all(((c - c[:1]) == np.arange(len(c))[:, None] * width).all() for c in cols.values())
        block = (first, width) if regular and first + len(spec.FINGERS) * width <= m.nsensordata else None
        spans = {k: (int(c[0, 0]) - first, c.shape[1]) for k, c in cols.items()}
        return cls({k: torch.as_tensor(c, device=device) for k, c in cols.items()}, block, spans)

    def read(self, sensordata: torch.Tensor, kind: str) -> torch.Tensor:
        """(n_envs, n_fingers, dim) of one reading for all envs: a view of `sensordata` where the layout allows
        (clone it to keep it past the next physics step), else a copy."""
        if self.block is None:
            return sensordata[:, self.cols[kind]]
        (first, width), (off, dim) = self.block, self.spans[kind]
        tips = sensordata[:, first : first + len(spec.FINGERS) * width].unflatten(1, (len(spec.FINGERS), width))
        return tips[:, :, off : off + dim]


# quat_to_mat's nine entries R_k = C_k (p[A_k] + S_k p[B_k]) (+ 1 on the diagonal) from the pairwise products
# p = q_i q_j (wxyz, index 4 i + j): the textbook formula, rounding identically, in a few whole-tensor ops.
_A = [10, 6, 7, 6, 5, 11, 7, 11, 5]  # yy xy xz / xy xx yz / xz yz xx
_B = [15, 3, 2, 3, 15, 1, 2, 1, 10]  # zz wz wy / wz zz wx / wy wx yy
_S = [1.0, -1.0, 1.0, 1.0, 1.0, -1.0, -1.0, 1.0, 1.0]
_C = [-2.0, 2.0, 2.0, 2.0, -2.0, 2.0, 2.0, 2.0, -2.0]
_ROT: dict[torch.device, tuple[torch.Tensor, ...]] = {}


def quat_to_mat(q: torch.Tensor) -> torch.Tensor:
    """wxyz quaternions (..., 4) to rotation matrices (..., 3, 3)."""
    if q.device not in _ROT:
        _ROT[q.device] = tuple(
            torch.tensor(v, device=q.device) for v in (_A, _B, _S, _C, [i in (0, 4, 8) for i in range(9)])
        )
    a, b, s, c, diagonal = _ROT[q.device]
    p = (q[..., :, None] * q[..., None, :]).flatten(-2)
    r = c * (p.index_select(-1, a) + s * p.index_select(-1, b))
    return torch.where(diagonal, r + 1.0, r).unflatten(-1, (3, 3))


def sum_short(x: torch.Tensor, dim: int) -> torch.Tensor:
    """`x.sum(dim)` over a short axis (2 or 3 entries), bit for bit: torch adds a short axis in order, starting
    from +0 (which turns a sum of -0s into +0), and so does this. As whole-tensor adds it costs a fraction of a
    reduction over a strided axis at the env's sizes, where a step makes several."""
    first, *rest = x.unbind(dim)
    out = first + 0.0
    for part in rest:
        out += part
    return out


def uniaxial_force(contact_reported: torch.Tensor, zaxis: torch.Tensor) -> torch.Tensor:
    """(n, 3 tips) true compressive force along each tip's z axis (before noise and deadband)."""
    return sum_short(contact_reported * zaxis, -1)


def contact_force_tip_frame(contact_reported: torch.Tensor, tip_quat: torch.Tensor) -> torch.Tensor:
    """(n, 3 tips, 3) force on each tip, in the tip (load-cell) frame: minus R^T f, R's columns the tip axes."""
    rot = quat_to_mat(tip_quat)
    return -sum_short(rot * contact_reported[..., :, None], -2)
