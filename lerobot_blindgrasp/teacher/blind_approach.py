"""The blind-approach teacher's actor input (group `privileged_blind`): the privileged vector with the object's
pose, velocities and planar distance read as 0 until a load cell has read above `TOUCH_N` (for more than
`reveal_delay_steps`), and optionally the fingertip poses from the measured joints. A teacher steering by what the
student cannot see asks it for actions it cannot infer; the critic still reads everything.
"""

from __future__ import annotations

import numpy as np

from lerobot_blindgrasp import spec
from lerobot_blindgrasp.presets.teacher_configs import BLIND_GROUP as GROUP
from lerobot_blindgrasp.presets.teacher_configs import ActorInput, reads_blind_group  # noqa: F401  (re-exported)

HIDDEN = ("object_pos", "object_quat", "object_linvel", "object_angvel", "object_planar_distance")
TOUCH_N = 2.0  # 4 sigma of the load cells' 0.5 N noise (spec.FORCE_NOISE_STD_N): above it, a touch
_UNIAXIAL = spec.PRIVILEGED_SLICES["uniaxial_force"]
_PREVIOUS_ACTION = spec.PRIVILEGED_SLICES["previous_action"]
_JOINTS = spec.PRIVILEGED_SLICES["joint_pos"]
_TIP_POS = spec.PRIVILEGED_SLICES["fingertip_pos"]
_TIP_QUAT = spec.PRIVILEGED_SLICES["fingertip_quat"]
_HIDDEN_COLUMNS = np.concatenate([np.arange(spec.PRIVILEGED_DIM)[spec.PRIVILEGED_SLICES[n]] for n in HIDDEN])


def first_steps(priv: np.ndarray) -> np.ndarray:
    """(n,) bool: the rows that are one of an episode's first two observations (previous action exactly 0)."""
    return (priv[:, _PREVIOUS_ACTION] == 0.0).all(axis=1)


class MeasuredKinematics:
    """Fingertip site poses in the world frame, as the env's framepos/framequat sensors give them, from the joint
    angles of a privileged vector, with MuJoCo's own kinematics (a numpy chain would be a second finger model)."""

    def __init__(self):
        import mujoco

        from lerobot_blindgrasp.sim import gripper, objects

        self._mj = mujoco
        # Any object will do: only the fingers' kinematic chain is read.
        obj = objects.object_mjcf(
            objects.get_object("sphere_small"), gripper.OBJECT_CONTYPE, gripper.OBJECT_CONAFFINITY
        )
        self._m = gripper.compile_model(obj)
        self._d = mujoco.MjData(self._m)
        self._sites = [mujoco.mj_name2id(self._m, mujoco.mjtObj.mjOBJ_SITE, f"{f}_tipsite") for f in spec.FINGERS]
        self._bodies = [int(self._m.site_bodyid[s]) for s in self._sites]

    def __call__(self, priv: np.ndarray) -> np.ndarray:
        """`priv` with its fingertip_pos and fingertip_quat replaced by the kinematics of its joint_pos (a copy)."""
        out = np.array(priv, copy=True)
        pos = np.empty((len(priv), len(self._sites), 3))
        quat = np.empty((len(priv), len(self._sites), 4))
        for i, q in enumerate(priv[:, _JOINTS]):
            self._d.qpos[: spec.NUM_JOINTS] = q
            self._mj.mj_kinematics(self._m, self._d)
            for k, (s, b) in enumerate(zip(self._sites, self._bodies)):
                pos[i, k] = self._d.site_xpos[s]
                # as MuJoCo's framequat sensor computes it (same sign): the body's orientation times the site's own
                self._mj.mju_mulQuat(quat[i, k], self._d.xquat[b], self._m.site_quat[s])
        out[:, _TIP_POS] = pos.reshape(len(priv), -1)
        out[:, _TIP_QUAT] = quat.reshape(len(priv), -1)
        return out


class BlindGroup:
    """GROUP for one batch of envs under one `ActorInput`, called on each step's observation dict. It keeps per-env
    touch counts; an episode starts where the privileged previous action is exactly 0 on all joints (the env zeroes
    it on reset), so no loop needs to tell it of resets."""

    def __init__(self, actor_input: ActorInput = ActorInput()):
        self.actor_input = actor_input
        self._kinematics = MeasuredKinematics() if actor_input.fingertips_from_joints else None
        self._touching: np.ndarray | None = None  # consecutive control steps with a touch, per env
        self._last: tuple[np.ndarray, np.ndarray] | None = None  # (privileged in, GROUP out) of the last step

    def mask(self, priv: np.ndarray) -> np.ndarray:
        """The GROUP rows of one step's privileged rows (advances the per-env touch counts once per step)."""
        if self._last is not None and np.array_equal(priv, self._last[0]):
            return self._last[1].copy()  # the same step asked for twice (e.g. mean and sample): count it once
        if self._touching is None or len(self._touching) != len(priv):
            self._touching = np.zeros(len(priv), dtype=int)  # a new batch of envs
        self._touching[first_steps(priv)] = 0
        touched = (priv[:, _UNIAXIAL] >= TOUCH_N).any(axis=1)
        self._touching = np.where(touched, self._touching + 1, 0)
        out = np.array(priv, copy=True)
        out[np.ix_(self._touching <= self.actor_input.reveal_delay_steps, _HIDDEN_COLUMNS)] = 0.0
        if self._kinematics is not None:
            out = self._kinematics(out)
        self._last = (np.array(priv, copy=True), out)
        return out.copy()

    def __call__(self, obs: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
        """`obs` plus the GROUP entry computed from its "privileged" one."""
        return {**obs, GROUP: self.mask(obs["privileged"])}
