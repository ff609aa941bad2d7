"""A teacher that cannot see a joint calibration offset, so that its corrections are ones a blind student can copy.

Why (robustness.md, "Fourth side-by-side"): demos collected under a +-0.05 rad calibration offset did not harden the
student. The teacher corrects for the offset from the fingertips' true poses, which the student never observes, so
in the student's inputs the corrections look like label noise. Here the teacher's actor loses that channel: its
fingertip positions and orientations are replaced by the kinematics of the *measured* joint angles (where the tips
would be if the calibration were right), which is all the student could ever compute. PPO then fine-tunes it under
every joint off by +-CAL rad (DomainRandomization.joint_calibration_rad, sign per env and joint), so that its grasp
works whatever the offset. The object reveal is delayed_reveal.py's (DELAY steps after the touch).

    python calib_blind.py train OUT_DIR START.pt ITERATIONS CAL DELAY     PPO fine-tune under +-CAL rad
    python calib_blind.py eval TEACHER CAL DELAY OBJECTS OUT.json          the teacher under +-CAL rad
    python calib_blind.py collect CAL DELAY <blindgrasp-collect-demos arguments>   demos under +-CAL rad
"""

# Recorded experiment code: it patches the package's stateless mask of commit 1409010, which the package has since
# replaced by this very recipe (teacher preset cpu_bc_calib_blind and blindgrasp-collect-demos --joint_calibration_rad). Re-run it as recorded from that commit (`git checkout 1409010`).
from lerobot_blindgrasp.teacher import blind_approach as _pkg  # noqa: E402

if not hasattr(_pkg, "with_blind_group"):
    raise SystemExit(f"{__file__} ran at commit 1409010; the package now does this: teacher preset cpu_bc_calib_blind and blindgrasp-collect-demos --joint_calibration_rad")

import dataclasses
import sys
from pathlib import Path

import numpy as np
import torch

sys.path.insert(0, str(Path(__file__).resolve().parents[2] / "delayed_reveal" / "scripts"))
sys.path.insert(0, str(Path(__file__).resolve().parents[2] / "student_gmm" / "scripts"))
import delayed_reveal  # noqa: E402
from episodes import every_object  # noqa: E402

from lerobot_blindgrasp import spec  # noqa: E402
from lerobot_blindgrasp.sim import objects, randomization  # noqa: E402

_POS, _QUAT, _Q = (spec.PRIVILEGED_SLICES[n] for n in ("fingertip_pos", "fingertip_quat", "joint_pos"))


class MeasuredKinematics:
    """Fingertip site poses (world frame, as the env's framepos/framequat sensors) from the measured joint angles."""

    def __init__(self):
        import mujoco

        from lerobot_blindgrasp.sim import gripper

        obj = objects.get_object("sphere_small")
        self.mj = mujoco
        self.m = gripper.compile_model(objects.object_mjcf(obj, gripper.OBJECT_CONTYPE, gripper.OBJECT_CONAFFINITY))
        self.d = mujoco.MjData(self.m)
        self.sites = [mujoco.mj_name2id(self.m, mujoco.mjtObj.mjOBJ_SITE, f"{f}_tipsite") for f in spec.FINGERS]
        self.quat = np.zeros(4)

    def __call__(self, priv: np.ndarray) -> np.ndarray:
        out = np.array(priv, copy=True)
        for i in range(len(priv)):
            self.d.qpos[: spec.NUM_JOINTS] = priv[i, _Q]
            self.mj.mj_kinematics(self.m, self.d)
            pos, quat = [], []
            for s in self.sites:
                # as MuJoCo's framequat sensor computes it (same sign): body orientation times the site's own
                self.mj.mju_mulQuat(self.quat, self.d.xquat[self.m.site_bodyid[s]], self.m.site_quat[s])
                pos.append(self.d.site_xpos[s].copy())
                quat.append(self.quat.copy())
            out[i, _POS] = np.concatenate(pos)
            out[i, _QUAT] = np.concatenate(quat)
        return out


def install(delay: int):
    """delayed_reveal's mask, then the fingertip poses from the measured joints, for every caller."""
    from lerobot_blindgrasp.teacher import blind_approach, vecenv

    m, fk = delayed_reveal.DelayedMask(delay), MeasuredKinematics()

    def with_blind_group(obs):
        return {**obs, blind_approach.GROUP: fk(m.mask(obs["privileged"]))}

    blind_approach.with_blind_group = with_blind_group
    vecenv.with_blind_group = with_blind_group


def with_offset(cal: float) -> None:
    """Every env built from here on (training, demos) draws a +-cal rad offset on every joint."""
    randomization.PAPER_DR = dataclasses.replace(randomization.PAPER_DR, joint_calibration_rad=cal)
    randomization.EVAL_DR = dataclasses.replace(randomization.EVAL_DR, joint_calibration_rad=cal)


if __name__ == "__main__":
    cmd = sys.argv[1]
    if cmd == "train":
        out, start, its, cal, delay = Path(sys.argv[2]), Path(sys.argv[3]), int(sys.argv[4]), float(sys.argv[5]), int(sys.argv[6])
        with_offset(cal)
        delayed_reveal.install = install
        delayed_reveal.train(out, start, its, delay, sys.argv[7:])
    elif cmd == "eval":
        from lerobot_blindgrasp.teacher.policy import TeacherPolicy

        folder, cal, delay, which, out = sys.argv[2], float(sys.argv[3]), int(sys.argv[4]), sys.argv[5], sys.argv[6]
        torch.set_num_threads(1)
        install(delay)
        every_object(which, TeacherPolicy(folder), out, dr=dataclasses.replace(randomization.EVAL_DR, joint_calibration_rad=cal))
    elif cmd == "collect":
        from lerobot_blindgrasp.demos.collect import main

        with_offset(float(sys.argv[2]))
        install(int(sys.argv[3]))
        main(sys.argv[4:])
