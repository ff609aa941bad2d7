"""Teacher drives the first k control steps, then the student takes over (its context saw every step).

Success against the handover step k tells where the student loses an object: if the student finishes the
teacher's grasp once handed over after contact, what fails is the student's contact phase, not its lift or hold.
Usage: python handover_check.py OBJECTS(comma) STUDENT_DIR OUT.json [K,K,...]
"""
import json
import sys

import torch
from episodes import successes

from lerobot_blindgrasp.analysis.student_diagnosis import load_student, student_actor
from lerobot_blindgrasp.teacher.policy import TeacherPolicy, default_teacher

torch.set_num_threads(1)
objs, student_path, out = sys.argv[1].split(","), sys.argv[2], sys.argv[3]
ks = [int(k) for k in (sys.argv[4] if len(sys.argv) > 4 else "0,8,12,16,20,30,200").split(",")]
EPS, SEED = 20, 1000
teacher = TeacherPolicy(default_teacher())
policy, pre, post = load_student(student_path)
student = student_actor(policy, pre, post)


def run(name: str, k: int) -> list[bool]:
    policy.reset()

    def act(t, obs, env):
        s_delta = student(obs) - env.joint_positions()  # always: the student's context sees every step
        return teacher(obs) if t < k else s_delta

    return successes(name, act, episodes=EPS, seed=SEED)


res = {}
for name in objs:
    res[name] = {}
    for k in ks:
        res[name][k] = run(name, k)
        print(name, "handover at step", k, "success", sum(res[name][k]), "/", EPS, flush=True)
json.dump({"student": student_path, "episodes": EPS, "seed": SEED, "success": res}, open(out, "w"), indent=1)
