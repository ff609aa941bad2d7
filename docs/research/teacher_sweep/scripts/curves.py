"""Training success per object, the sweep stage against the shipped side-grasp stage, from their TensorBoard logs.

    python docs/research/teacher_sweep/scripts/curves.py <shipped run dir> <sweep run dir> <out.png>

The shipped run's logs are at git tag teacher-experiments (docs/research/teacher_runs/shipped_from_scratch)."""
import sys
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np

from lerobot_blindgrasp.analysis.progress import _scalars
from lerobot_blindgrasp.teacher.scripted_demos import HARD_OBJECTS

runs = {"side grasp (cpu_bc_capsule, shipped)": Path(sys.argv[1]), "blind sweep (cpu_bc_sweep)": Path(sys.argv[2])}
scalars = {name: _scalars(d) for name, d in runs.items()}
fig, axes = plt.subplots(2, 4, figsize=(14, 6), sharex=True, sharey=True)
for ax, obj in zip(axes.flat, (*HARD_OBJECTS, "all")):
    for name, s in scalars.items():
        if obj == "all":
            keys = [k for k in s if k.startswith("Success/") and k.count("/") == 1 and "_" in k]
            its = sorted(set.intersection(*(set(s[k]) for k in keys)))
            y = np.array([np.mean([s[k][i] for k in keys]) for i in its])
        else:
            its = sorted(s[f"Success/{obj}"])
            y = np.array([s[f"Success/{obj}"][i] for i in its])
        its = np.array(its)
        keep = its >= 1746
        w = 10  # running mean over 10 iterations: each point is one iteration's finished episodes
        sm = np.convolve(y[keep], np.ones(w) / w, mode="valid")
        ax.plot(its[keep][w - 1:], sm, label=name)
    ax.set_title(obj)
    ax.grid(alpha=0.3)
for ax in axes[1]:
    ax.set_xlabel("PPO iteration")
for ax in axes[:, 0]:
    ax.set_ylabel("training success")
axes[0, 0].legend(fontsize=8, loc="lower right")
fig.suptitle("Second cloning stage from cpu_bc_joint it. 1745: side grasp vs blind sweep (10-it running mean)")
fig.tight_layout()
fig.savefig(sys.argv[3], dpi=110)
print("wrote", sys.argv[3])
