"""The Table V rows as named entries: which teacher, which demos, whether a student is distilled, and why.

Every preset runs the same rows at its own sizes: the student rows share the preset's demo budget (episodes per
object and rollout cap), student size and steps or epochs, and seed, and every row is evaluated on the preset's
eval start states. What differs between rows is only what the paper varies (Sec. IV-A); each row's `doc` says what.
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
    doc: str = ""


# The teachers the rows need, by folder name, and the training switches that make each.
TEACHERS: dict[str, Variant] = {
    "teacher": Variant(),
    "teacher_no_ri": Variant(no_incentive=True),
    "rl_with_ot": Variant(student_obs=True),
}

TABLE_V: dict[str, Ablation] = {
    a.name: a
    for a in (
        Ablation(name="proposed", label="Student (Proposed)", teacher="teacher",
                 doc="curated demos of the stochastic teacher, distilled into the student"),
        Ablation(name="wo_stochastic_teacher", label="Student w/o Stochastic Teacher", teacher="teacher",
                 stochastic_demos=False, doc="demos from the teacher's mean action, still curated"),
        Ablation(name="wo_curation", label="Student w/o Curation", teacher="teacher", curated_demos=False,
                 doc="the stochastic teacher's 100-step episodes kept whole, without any selection"),
        Ablation(
            name="wo_r_i", label="Student w/o r_i", teacher="teacher_no_ri", curated_demos=False,
            doc="a teacher trained without any term that pays for fingertip contact: the incentive r_i and, in "
            "the cpu/quick presets, touch (it pays for tips pressing on the object just as r_i pays for tips "
            "reading force, so keeping it would leave r_i's signal in). Reach stays: it pays for closing the "
            "tip-object distance and is blind to force, and without it PPO at 2-core scale learns to keep still "
            "(issue #3), which would ablate exploration rather than the force incentive the paper removes "
            "(the paper preset has neither shaping term). Its demos are kept without selection, as the paper's "
            "are (teacher.CONTACT_REWARD_TERMS)",
        ),
        Ablation(name="rl_w_o_t", label="RL w/ o_t", teacher="rl_with_ot", student=False,
                 doc="PPO whose actor and critic see only the 12-d student observation, evaluated as it is"),
    )
}
