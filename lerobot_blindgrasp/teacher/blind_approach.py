"""The blind-approach teacher's actor input: the privileged vector with the object's state hidden until a touch.

The student cannot see where the object stands, nor which object it is, before a fingertip touches it. A teacher
that steers its approach by those asks its student for actions that depend on what it never observes. The `cpu_bc_blind_approach` teacher's actor therefore reads the observation group
`privileged_blind`: the privileged vector with the object's pose, velocities and planar distance set to 0 while no
fingertip load cell reads above `TOUCH_N`. Its critic reads the full vector (asymmetric actor-critic).
The trigger is the student's own uniaxial reading, so the teacher learns of the object exactly when the student
could. Stateless: a lost contact hides the object again.
"""

from __future__ import annotations

import numpy as np

from lerobot_blindgrasp import spec

GROUP = "privileged_blind"  # the observation group (rsl-rl obs_groups) of the masked vector
HIDDEN = ("object_pos", "object_quat", "object_linvel", "object_angvel", "object_planar_distance")
TOUCH_N = 2.0  # 4 sigma of the load cells' 0.5 N noise (spec.FORCE_NOISE_STD_N): above it, a touch
_UNIAXIAL = spec.PRIVILEGED_SLICES["uniaxial_force"]
_HIDDEN_COLUMNS = np.concatenate([np.arange(spec.PRIVILEGED_DIM)[spec.PRIVILEGED_SLICES[n]] for n in HIDDEN])


def mask_before_touch(priv: np.ndarray) -> np.ndarray:
    """(n, PRIVILEGED_DIM) rows with the HIDDEN parts at 0 where no load cell reads above TOUCH_N (a copy)."""
    priv = np.array(priv, copy=True)
    blind = (priv[:, _UNIAXIAL] < TOUCH_N).all(axis=1)
    priv[np.ix_(blind, _HIDDEN_COLUMNS)] = 0.0
    return priv


def reads_blind_group(obs_groups: dict[str, list[str]]) -> bool:
    """Whether any model of an rsl-rl `obs_groups` config reads GROUP (only then is it worth computing)."""
    return any(GROUP in groups for groups in obs_groups.values())


def with_blind_group(obs: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
    """`obs` plus the GROUP entry computed from its "privileged" one."""
    return {**obs, GROUP: mask_before_touch(obs["privileged"])}
