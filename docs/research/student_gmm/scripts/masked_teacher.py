"""The shipped teacher with the object's position hidden until a fingertip touches it.

While no tip is in contact, the teacher's privileged observation says the object lies at the claw's centre
(object_pos x, y = 0 and object_planar_distance = 0); once a tip touches it, the teacher sees the true position.
Its approach then no longer depends on anything the blind student cannot observe. No retraining: this measures how
much the teacher needs the position before contact.

    python masked_teacher.py eval OBJECTS OUT.json            teacher, masked and not, same start states
    python masked_teacher.py collect <blindgrasp-collect-demos arguments>    demos of the masked teacher
"""
import json
import sys

import numpy as np
import torch
from episodes import successes

from lerobot_blindgrasp import spec
from lerobot_blindgrasp.sim import objects
from lerobot_blindgrasp.teacher.policy import TeacherPolicy

POS, DXY = spec.PRIVILEGED_SLICES["object_pos"], spec.PRIVILEGED_SLICES["object_planar_distance"]
CONTACT = spec.PRIVILEGED_SLICES["fingertip_contact_force"]
TOUCH_N = 3.0  # a tip counts as touching above this contact-force norm (N): the observation noise is ~0.5-1 N


def mask_before_contact(obs: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
    priv = obs["privileged"].copy()
    tips = np.linalg.norm(priv[:, CONTACT].reshape(len(priv), spec.NUM_FORCES, 3), axis=-1)
    blind = (tips < TOUCH_N).all(axis=1)
    priv[blind, POS.start:POS.start + 2] = 0.0
    priv[blind, DXY] = 0.0
    return {**obs, "privileged": priv}


class MaskedTeacher(TeacherPolicy):
    def __call__(self, obs, stochastic: bool = False):
        return super().__call__(mask_before_contact(obs), stochastic=stochastic)


def run(teacher, name: str) -> list[bool]:
    return successes(name, lambda t, obs, env: teacher(obs))


if __name__ == "__main__" and sys.argv[1] == "eval":
    from lerobot_blindgrasp.teacher.policy import default_teacher

    torch.set_num_threads(1)
    names, out = objects.resolve_objects(sys.argv[2]), sys.argv[3]
    plain, masked = TeacherPolicy(default_teacher()), MaskedTeacher(default_teacher())
    res = {}
    for name in names:
        res[name] = {"teacher": run(plain, name), "masked": run(masked, name)}
        print(name, "teacher", sum(res[name]["teacher"]), "masked until contact", sum(res[name]["masked"]), flush=True)
    json.dump(res, open(out, "w"), indent=1)

if __name__ == "__main__" and sys.argv[1] == "collect":
    # blindgrasp-collect-demos with the masked teacher: its arguments follow "collect".
    import lerobot_blindgrasp.teacher.policy as teacher_policy
    from lerobot_blindgrasp.demos.collect import main

    teacher_policy.TeacherPolicy = MaskedTeacher
    main(sys.argv[2:])
