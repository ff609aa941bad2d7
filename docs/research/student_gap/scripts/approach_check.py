"""Fingertip heights before first contact: teacher vs student, per object (evaluation start states, seed 1000)."""
import json
import sys

import numpy as np
import torch

from lerobot_blindgrasp import spec
from lerobot_blindgrasp.analysis.student_diagnosis import Outcomes, load_student, student_actor
from lerobot_blindgrasp.sim.env import BatchedGraspEnv, GraspEnvConfig
from lerobot_blindgrasp.sim.gym_env import start_seed
from lerobot_blindgrasp.sim.randomization import EVAL_DR
from lerobot_blindgrasp.teacher.policy import TeacherPolicy, default_teacher

torch.set_num_threads(1)
if len(sys.argv) == 3 and sys.argv[1] == "--plot":  # redraw the figure from a saved JSON
    objs = None
else:
    objs = sys.argv[1].split(",")
    student_path = sys.argv[2]
    out = sys.argv[3]
EPS = 20
sl = spec.PRIVILEGED_SLICES["fingertip_pos"]
def run(kind, name):
    env = BatchedGraspEnv(GraspEnvConfig(num_envs=EPS, objects=(name,), seed=start_seed(1000, name), dr=EVAL_DR, autoreset=False))
    if kind == "teacher":
        t = TeacherPolicy(default_teacher()); act = lambda o: t(o)
    else:
        p, pre, post = load_student(student_path); p.reset(); sa = student_actor(p, pre, post)
        act = lambda o: sa(o) - env.joint_positions()
    obs = env.reset(); H = env.max_episode_steps
    tip = np.zeros((EPS, H, 3, 3)); touch = np.zeros((EPS, H, 3)); down = np.zeros((EPS, H, 3)); objp = np.zeros((EPS, H, 3))
    ends = Outcomes(EPS, H)
    for s in range(H):
        tip[:, s] = obs["privileged"][:, sl].reshape(EPS, 3, 3); objp[:, s] = env.object_position()
        obs, _, term, trunc, info = env.step(act(obs))
        touch[:, s] = info["tip_object_force"]; down[:, s] = info["tip_object_downward"]
        if not ends.update(s, info, term, trunc): break
    env.close()
    first = np.array([np.argmax((touch[k] > 0.05).any(1)) if (touch[k] > 0.05).any() else -1 for k in range(EPS)])
    rows = []
    for k in range(EPS):
        f = first[k]
        if f < 0: rows.append(dict(first=-1)); continue
        tipk = tip[k, f]; rel = tipk[:, :2] - objp[k, f, :2]
        fing = int(np.argmax(touch[k, f]))
        rows.append(dict(first=int(f), tip_z=tipk[:, 2].round(4).tolist(), tip_r=np.linalg.norm(rel, axis=1).round(4).tolist(),
                         first_finger=fing, down=float(down[k, f, fing])))
    meanz = tip[:, :60, :, 2].mean(axis=(0, 2))
    return dict(success=ends.success.tolist(), first=rows, mean_tip_z_first60=meanz.round(4).tolist(),
                obj_xy=objp[:, 0, :2].round(4).tolist())
def plot(res, path):
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    names = list(res)
    fig, axes = plt.subplots(1, len(names), figsize=(3.2 * len(names), 3.2), sharey=True)
    for ax, name in zip(axes, names):
        for role, color in (("teacher", "tab:orange"), ("student", "tab:blue")):
            r = res[name][role]
            z = 100 * np.array(r["mean_tip_z_first60"][:40])
            ax.plot(np.arange(len(z)) * 0.05, z, color=color, label=f"{role} ({sum(r['success'])}/20)")
            f = [e["first"] for e in r["first"] if e["first"] >= 0]
            if f:
                ax.axvline(np.median(f) * 0.05, color=color, ls=":", lw=1)
        ax.set_title(name, fontsize=9); ax.set_xlabel("time (s)"); ax.legend(fontsize=7)
    axes[0].set_ylabel("mean fingertip height (cm)")
    fig.suptitle("fingertip height, mean of 20 episodes (dotted: median first contact)", fontsize=9)
    fig.tight_layout(); fig.savefig(path, dpi=110)

if objs is None:
    plot(json.load(open(sys.argv[2])), sys.argv[2].replace(".json", ".png"))
    sys.exit()
res = {}
for name in objs:
    res[name] = {k: run(k, name) for k in ("teacher", "student")}
    for k in ("teacher", "student"):
        r = res[name][k]; f = [x for x in r["first"] if x["first"] >= 0]
        print(name, k, "succ", sum(r["success"]), "first contact step", np.median([x["first"] for x in f]) if f else None,
              "tip z at contact", np.round(np.median([np.mean(x["tip_z"]) for x in f]), 4) if f else None,
              "min tip z", np.round(np.median([np.min(x["tip_z"]) for x in f]), 4) if f else None,
              "downward", np.round(np.median([x["down"] for x in f]), 2) if f else None, flush=True)
json.dump(res, open(out, "w"))
plot(res, out.replace(".json", ".png"))
