"""The blind-approach teacher with its actor's object inputs hidden for the whole episode, not only before a touch.

How much does it rely on the object's pose after contact? Same start states as lerobot-eval (--seed=1000).

    python always_masked.py models/teacher_cpu_bc_blind all OUT.json
"""
import sys
from pathlib import Path

import numpy as np
import torch

sys.path.insert(0, str(Path(__file__).resolve().parents[2] / "student_gmm" / "scripts"))
from episodes import every_object  # noqa: E402  (the shared episode loop of the student_gmm scripts)

from lerobot_blindgrasp.teacher import blind_approach  # noqa: E402
from lerobot_blindgrasp.teacher.policy import TeacherPolicy  # noqa: E402


def main(folder: str, which: str, out: str) -> None:
    torch.set_num_threads(1)
    teacher = TeacherPolicy(folder)

    def act(obs):
        hidden = np.array(obs["privileged"], copy=True)
        hidden[:, blind_approach._HIDDEN_COLUMNS] = 0.0  # the mask's columns, whatever the load cells read
        return teacher({**obs, blind_approach.GROUP: hidden})

    every_object(which, act, out)

if __name__ == "__main__":
    main(*sys.argv[1:4])
