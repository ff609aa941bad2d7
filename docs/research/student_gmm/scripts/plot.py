"""The figure of student_gmm.md from its JSONs: success against handover step, and open-loop error by step."""
import json
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

here = Path(__file__).resolve().parents[1]
COLORS = {"capsule_small": "tab:blue", "sphere_small": "tab:orange", "capsule_medium": "tab:green",
          "cylinder_a_small": "tab:red", "cylinder_b_small": "tab:purple"}
fig, (a, b) = plt.subplots(1, 2, figsize=(11, 3.8))
for path, style in (("handover_ctl.json", "-"), ("handover_shipped.json", ":")):
    d = json.loads((here / path).read_text())
    who = "control student" if "ctl" in path else "shipped student"
    for name, runs in d["success"].items():
        ks = sorted(runs, key=int)
        x = [min(int(k), 40) for k in ks]  # 200 (the teacher all the way) drawn at 40
        a.plot(x, [100 * np.mean(runs[k]) for k in ks], style, marker="o", ms=3, color=COLORS[name],
               label=f"{name}, {who}")
a.set_xticks([0, 8, 12, 16, 20, 30, 40], ["0", "8", "12", "16", "20", "30", "teacher"])
a.set_xlabel("teacher drives the first k steps (20 Hz), then the student")
a.set_ylabel("success (%), 20 episodes, seed 1000")
a.legend(fontsize=7)
a.set_title("where the student loses the object", fontsize=9)
d = json.loads((here / "open_loop_ctl.json").read_text())["mse_by_step"]
for name, curve in d.items():
    hard = name in ("capsule_small", "sphere_small", "capsule_medium", "cylinder_a_small", "cylinder_b_small")
    b.plot(np.arange(60), curve[:60], lw=1.6 if hard else 0.6, color=COLORS[name] if hard else "0.7",
           label=name if hard else None)
b.axhline(0.0112, color="k", ls="--", lw=0.8, label="stochastic teacher's label noise")
b.set_xlabel("episode step (20 Hz)")
b.set_ylabel("loss on its training demos (delta / 0.3)^2")
b.set_title("open-loop fit of the control student, by step (grey: the other objects)", fontsize=9)
b.legend(fontsize=7)
fig.tight_layout()
fig.savefig(here / "handover.png", dpi=80)
