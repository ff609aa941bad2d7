"""The Table V rows as named entries: which teacher, which demos, and whether a student is distilled.

Every preset runs the same rows at its own sizes: the student rows share the preset's demo budget (episodes per
object and rollout cap), student size and steps or epochs, and seed, and every row is evaluated on the preset's
eval start states. What differs between rows is only what the paper varies (Sec. IV-A):
- w/o stochastic teacher: demos from the teacher's mean action, still curated;
- w/o curation: the stochastic teacher's 100-step episodes kept without any selection;
- w/o r_i: a teacher trained without the contact-rewarding terms (`teacher.CONTACT_REWARD_TERMS`; why reach
  stays is written there), its demos kept without selection as the paper's are;
- RL w/ o_t: PPO whose actor and critic see only the 12-d student observation, evaluated as it is.
"""

from __future__ import annotations

from dataclasses import dataclass

from lerobot_blindgrasp.presets.teacher import Variant


@dataclass(frozen=True, kw_only=True)
class Ablation:
    name: str  # folder and flag name
    label: str  # the paper's column title
    teacher: str  # key of TEACHERS: which teacher this row trains or uses
    stochastic_demos: bool = True
    curated_demos: bool = True
    student: bool = True  # False: the teacher itself is the row's policy (RL w/ o_t)


# The teachers the rows need, by folder name, and the training switches that make each.
TEACHERS: dict[str, Variant] = {
    "teacher": Variant(),
    "teacher_no_ri": Variant(no_incentive=True),
    "rl_with_ot": Variant(student_obs=True),
}

TABLE_V: dict[str, Ablation] = {
    a.name: a
    for a in (
        Ablation(name="proposed", label="Student (Proposed)", teacher="teacher"),
        Ablation(name="wo_stochastic_teacher", label="Student w/o Stochastic Teacher", teacher="teacher",
                 stochastic_demos=False),
        Ablation(name="wo_curation", label="Student w/o Curation", teacher="teacher", curated_demos=False),
        Ablation(name="wo_r_i", label="Student w/o r_i", teacher="teacher_no_ri", curated_demos=False),
        Ablation(name="rl_w_o_t", label="RL w/ o_t", teacher="rl_with_ot", student=False),
    )
}
