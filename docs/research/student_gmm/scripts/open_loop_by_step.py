"""Open-loop fit by episode step: the student's loss on its own training demos, per object, at each control step.

A student that fits an object's demos at every step but fails it in closed loop is limited by the states its own
errors lead to; one whose error on that object stays high where the others' is low cannot tell that object's
situation apart from its 12-d observation history. Usage: python open_loop_by_step.py STUDENT_DIR DEMOS_DIR OUT.json
"""
import json
import sys

import numpy as np
import torch

from lerobot_blindgrasp import spec
from lerobot_blindgrasp.analysis.student_diagnosis import episodes_by_object, load_student, windows

torch.set_num_threads(1)
student_path, demos, out = sys.argv[1:4]
policy, pre, _ = load_student(student_path)
by_object = episodes_by_object(demos)
T = 100
res = {}
with torch.no_grad():
    for name, eps in sorted(by_object.items()):
        err = np.full((len(eps), T), np.nan)
        for i, (state, action) in enumerate(eps):
            win, pad = windows(state, policy.config.n_obs_steps)
            b = pre({spec.STATE_KEY: torch.from_numpy(win), f"{spec.STATE_KEY}_is_pad": torch.from_numpy(pad),
                     spec.ACTION_KEY: torch.from_numpy(action)})
            per_sample, _ = policy.forward(b, reduction="none")
            n = min(T, len(per_sample))
            err[i, :n] = per_sample[:n].numpy()
        res[name] = np.nanmean(err, axis=0).round(5).tolist()
        print(name, "steps 0-7 %.4f  8-19 %.4f  20-39 %.4f  40-99 %.4f" % tuple(
            np.nanmean(res[name][a:b]) for a, b in ((0, 8), (8, 20), (20, 40), (40, 100))), flush=True)
json.dump({"student": student_path, "demos": demos, "mse_by_step": res}, open(out, "w"))
