"""How often do scripted grasps lift each object when they know / do not know where it lies?"""
import sys
import time

import numpy as np

from lerobot_blindgrasp.sim import gripper, objects, randomization, scripted
from lerobot_blindgrasp.sim.env import BatchedGraspEnv, GraspEnvConfig
from lerobot_blindgrasp.teacher.scripted_demos import SCRIPT_SEED

names = sys.argv[1].split(",") if len(sys.argv) > 1 else list(objects.PAPER_OBJECTS)
eps = int(sys.argv[2]) if len(sys.argv) > 2 else 30

class BlindSweep(scripted.SideGraspScript):
    """Same waypoints as the side grasp, but centred (xy=0) and opened WIDE by the start-spread so that the
    descent never lands on the object; the squeeze then sweeps it to the centre."""
    def __init__(self, q0, object_pos, specs, wide=0.035):
        import math

        from lerobot_blindgrasp import spec
        n = len(specs)
        dirs = np.array([[math.cos(p), math.sin(p)] for p in spec.FINGER_BASE_ANGLES_RAD])
        surface = np.stack([scripted.support_distance(o, dirs) for o in specs]) + gripper.TIP_CAPSULE_RADIUS
        top = np.array([o.rest_height * 2.0 for o in specs])[:, None].repeat(3, axis=1)
        grasp_z = np.maximum(object_pos[:, 2:3].repeat(3, axis=1), gripper.TIP_CAPSULE_RADIUS + 0.004)
        xy = np.zeros((n, 2))
        sp = scripted.side_pose
        self.waypoints = np.stack([np.asarray(q0, float), sp(xy, surface + self.GAP_M + wide, top + 0.015),
            sp(xy, surface + self.GAP_M + wide, grasp_z), sp(xy, surface - self.SQUEEZE_M, grasp_z),
            sp(xy, surface - self.SQUEEZE_M, grasp_z + self.LIFT_M)])
        self.t = 0
        self.segments = ((15, 0, 1), (15, 1, 2), (25, 2, 3), (30, 3, 4))

def run(kind):
    n = eps * len(names)
    env = BatchedGraspEnv(GraspEnvConfig(num_envs=n, objects=tuple(names), seed=SCRIPT_SEED, dr=randomization.EVAL_DR,
                                         autoreset=False, nthread=2))
    env.reset()
    specs = [objects.get_object(k) for k in env.object_names]
    pos = env.object_position().copy()
    if kind == "side_true_xy":
        s = scripted.SideGraspScript(env.joint_positions(), pos, specs)
    elif kind == "side_blind_xy0":
        p = pos.copy(); p[:, :2] = 0
        s = scripted.SideGraspScript(env.joint_positions(), p, specs)
    else:
        s = BlindSweep(env.joint_positions(), pos, specs)
    succ = np.zeros(n, bool)
    for t in range(env.max_episode_steps):
        _, _, term, _, info = env.step(s(env.joint_positions()))
        succ |= info["success"]
        succ &= ~term
    env.close()
    nm = np.array(env.object_names)
    return {k: succ[nm == k].mean() for k in names}

t0 = time.time()
res = {k: run(k) for k in ("side_true_xy", "side_blind_xy0", "blind_sweep")}
print(f"{eps} eps/object, EVAL_DR, seed {SCRIPT_SEED}, {time.time()-t0:.0f}s")
print("| object | side grasp, true xy | side grasp, xy=0 | blind wide sweep |\n|---|---:|---:|---:|")
for k in names:
    print(f"| {k} | " + " | ".join(f"{res[m][k]:.0%}" for m in res) + " |")
print("| all | " + " | ".join(f"{np.mean(list(res[m].values())):.1%}" for m in res) + " |")
