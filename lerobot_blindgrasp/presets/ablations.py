"""The Table V rows as named entries: which teacher, which demos, whether a student is distilled, and why (`doc`).

Every row of a preset shares its demo budget, student, seed and eval start states; only what the paper varies
(Sec. IV-A) differs. The rows that change the teacher (w/o r_i, RL w/ o_t) train it with one switch flipped on the
preset's ablation teacher (`Preset.ablation_teacher`), which clones no scripted grasps: the scripts read the
object's pose and make contact by design, which those two rows must lack. `has_scripted_cloning` is the check.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass

from lerobot_blindgrasp.presets import teacher
from lerobot_blindgrasp.presets.teacher_configs import TeacherPreset, Variant


@dataclass(frozen=True, kw_only=True)
class Ablation:
    name: str  # folder and flag name
    label: str  # the paper's column title
    teacher: str  # key of TEACHERS: which teacher this row trains or uses
    stochastic_demos: bool = True
    curated_demos: bool = True
    student: bool = True  # False: the teacher itself is the row's policy (RL w/ o_t)
    doc: str = ""


# The teachers the rows need, by folder name, and the switches that make each (none: the preset's own teacher).
TEACHERS: dict[str, Variant] = {
    "teacher": Variant(),
    "teacher_no_ri": Variant(no_incentive=True),
    "rl_with_ot": Variant(student_obs=True),
}


def is_teacher_ablation(variant: Variant) -> bool:
    return variant != Variant()


def _stages(settings: TeacherPreset) -> list[TeacherPreset]:
    """The preset and every preset its staged recipe trains before it (`TeacherPreset.stages`)."""
    return [settings, *(teacher.TEACHER_PRESETS[name] for name, _ in settings.stages)]


def _scripted_demos(settings: TeacherPreset) -> dict | None:
    """The scripted-demos entry that cloning adds to a runner config (`ScriptedDemos.runner_cfg`), if any."""
    return settings.runner["algorithm"].get("scripted_demos")


def has_scripted_cloning(settings: TeacherPreset) -> bool:
    """Whether training with `settings` clones scripted grasps at any stage: the PPO algorithm is replaced or
    carries a scripted-demos entry, here or in a preset it continues."""
    return any(
        s.runner["algorithm"]["class_name"] != "PPO" or _scripted_demos(s) is not None for s in _stages(settings)
    )


def cloning_start(settings: TeacherPreset) -> int | None:
    """The first iteration at which `settings` (or a stage it continues) clones scripted grasps; None: never.
    The iterations before it are plain PPO with the first stage's reward and sizes."""
    starts = [d["start_iteration"] for s in _stages(settings) if (d := _scripted_demos(s)) is not None]
    return min(starts) if starts else None


def teacher_words(preset: str, variant: Variant | dict | None, last_iteration: int | None) -> str:
    """A teacher recipe in the words the registry and the Table V report share: preset, switches, iterations, and
    whether it clones scripted grasps (unknown for a preset this version no longer has)."""
    switches = variant if isinstance(variant, dict) else asdict(variant or Variant())
    flags = [f"--{f}=true" for f, on in switches.items() if on]
    what = " ".join([f"`{preset}`", *flags])
    if last_iteration is not None:
        what += f", iterations 0..{last_iteration}"
    if preset not in teacher.TEACHER_PRESETS:
        return what + " (a preset this version does not have)"
    clones = has_scripted_cloning(teacher.TEACHER_PRESETS[preset])
    return what + (", PPO with scripted-grasp cloning" if clones else ", PPO only (no cloning)")


TABLE_V: dict[str, Ablation] = {
    a.name: a
    for a in (
        Ablation(
            name="proposed",
            label="Student (Proposed)",
            teacher="teacher",
            doc="curated demos of the stochastic teacher, distilled into the student. The teacher is the "
            "preset's own: in quick the shipped one (the cpu recipe plus scripted-grasp cloning), in cpu that "
            "recipe trained from scratch, in paper Table III's PPO",
        ),
        Ablation(
            name="wo_stochastic_teacher",
            label="Student w/o Stochastic Teacher",
            teacher="teacher",
            stochastic_demos=False,
            doc="demos from the proposed teacher's mean action, still curated",
        ),
        Ablation(
            name="wo_curation",
            label="Student w/o Curation",
            teacher="teacher",
            curated_demos=False,
            doc="the proposed teacher's stochastic 100-step episodes kept whole, without any selection",
        ),
        Ablation(
            name="wo_r_i",
            label="Student w/o r_i",
            teacher="teacher_no_ri",
            curated_demos=False,
            doc="a teacher trained on the preset's ablation teacher without any term that pays for fingertip "
            "contact: the incentive r_i and, in the cpu/quick presets, touch (it pays for tips pressing on the "
            "object just as r_i pays for tips reading force, so keeping it would leave r_i's signal in). Reach "
            "stays: it pays for closing the tip-object distance and is blind to force, and without it PPO at "
            "2-core scale learns to keep still, which would ablate exploration rather than the force incentive the "
            "paper removes (the paper preset has neither shaping term). No scripted-grasp cloning, which would "
            "hand it contact-making grasps. Its demos are kept without selection, as the paper's are "
            "(teacher.CONTACT_REWARD_TERMS)",
        ),
        Ablation(
            name="rl_w_o_t",
            label="RL w/ o_t",
            teacher="rl_with_ot",
            student=False,
            doc="PPO on the preset's ablation teacher whose actor and critic see only the 12-d student "
            "observation, evaluated as it is; no scripted-grasp cloning, whose script reads the object's pose",
        ),
    )
}
