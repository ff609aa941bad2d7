"""Success against the object's start-position spread, teacher and student on the same start states.

The student cannot see where the object lies before it touches it; the teacher can. If the student's losses come
from that, they shrink as the spread shrinks. Usage: python xy_check.py OBJECTS(comma, or "all") STUDENT_DIR OUT.json [SPREAD,SPREAD,...]
"""
import json
import sys
from dataclasses import replace

import torch
from episodes import successes

from lerobot_blindgrasp import spec
from lerobot_blindgrasp.analysis.student_diagnosis import load_student, student_actor
from lerobot_blindgrasp.sim import objects
from lerobot_blindgrasp.sim.randomization import EVAL_DR
from lerobot_blindgrasp.teacher.policy import TeacherPolicy, default_teacher

torch.set_num_threads(1)
objs, student_path, out = objects.resolve_objects(sys.argv[1]), sys.argv[2], sys.argv[3]
EPS, SEED = 20, 1000
# x the training spread, U[-3, 3] cm
SPREADS = tuple(float(x) for x in (sys.argv[4] if len(sys.argv) > 4 else "0,0.5,1").split(","))
teacher = TeacherPolicy(default_teacher())
policy, pre, post = load_student(student_path)
student = student_actor(policy, pre, post)


def run(name: str, xy_scale: float, role: str) -> list[bool]:
    dr = replace(EVAL_DR, object_xy_m=xy_scale * spec.OBJECT_XY_RANGE_M)
    policy.reset()

    def act(t, obs, env):
        return teacher(obs) if role == "teacher" else student(obs) - env.joint_positions()

    return successes(name, act, dr=dr, episodes=EPS, seed=SEED)


res = {}
for name in objs:
    res[name] = {}
    for s in SPREADS:
        res[name][str(s)] = {role: run(name, s, role) for role in ("teacher", "student")}
        r = res[name][str(s)]
        print(name, f"xy spread x{s}", "teacher", sum(r["teacher"]), "student", sum(r["student"]), flush=True)
json.dump({"student": student_path, "episodes": EPS, "seed": SEED, "success": res}, open(out, "w"), indent=1)
