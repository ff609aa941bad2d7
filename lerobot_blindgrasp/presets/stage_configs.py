"""The pipeline's config types: a `Preset` is one config per stage of the main job and its deviations from the
paper, keyed by what they concern ("teacher", "demos", "student.size", ...; `derive` restates only those it changes).
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace

from lerobot_blindgrasp.presets import ablations
from lerobot_blindgrasp.presets.ablations import TEACHERS
from lerobot_blindgrasp.presets.student import DaggerStage, StudentStage
from lerobot_blindgrasp.presets.teacher_configs import TeacherPreset, Variant, reads_blind_group


@dataclass(frozen=True, kw_only=True)
class TeacherStage:
    settings: TeacherPreset  # PPO settings and reward (presets.teacher.TEACHER_PRESETS)
    shipped: bool = False  # True: use a shipped teacher (trained with `settings`), train nothing
    # Which shipped teacher: a folder under the repository's models/; None: the default one (teacher.policy).
    shipped_folder: str | None = None
    iterations: int | None = None  # None: settings.max_iterations
    num_envs: int | None = None  # None: settings.num_envs


@dataclass(frozen=True, kw_only=True)
class DemoStage:
    episodes_per_object: int
    max_rollouts_per_object: int
    num_envs: int
    # Below this many curated episodes the pipeline trains on the uncurated set instead, and says so.
    min_curated_episodes: int
    # Beyond the paper (0: the paper): every joint reading off by +-this (rad) while rolling out.
    joint_calibration_rad: float = 0.0
    # Beyond the paper (): more curated episodes of the objects the student trails on, ((object, episodes), ...),
    # each its own collection on its own start states, merged with the main set.
    extra_episodes: tuple[tuple[str, int], ...] = ()

    def __post_init__(self):
        for name, n in self.extra_episodes:
            if n < 1:
                raise ValueError(f"extra_episodes: {name} needs at least one episode, not {n}")
        names = [name for name, _ in self.extra_episodes]
        if len(set(names)) != len(names):
            raise ValueError(f"extra_episodes names an object twice: {names}")


@dataclass(frozen=True, kw_only=True)
class EvalStage:
    episodes_per_object: int  # student and teacher alike: paired episode by episode on the same start states
    task: str = "all"  # lerobot-eval --env.task and the teacher eval's objects
    # The paired comparison is the deterministic teacher's; the stochastic one costs as much again.
    teacher_modes: tuple[str, ...] = ("deterministic", "stochastic")
    async_envs: bool = False  # lerobot-eval worker processes: worth it only with many cores
    # lerobot-eval's video: a new frame every N steps, on the first `render_episodes` (the rest one a second)
    render_stride: int = 1
    render_episodes: int = 10


@dataclass(frozen=True, kw_only=True)
class Preset:
    name: str
    teacher: TeacherStage
    demos: DemoStage
    student: StudentStage
    evaluation: EvalStage
    # beyond the teacher settings' own, keyed by what they concern (module docstring)
    deviations: dict[str, str] = field(default_factory=dict)
    # DAgger-style relabelling after the first student (beyond the paper); None: the paper's offline recipe.
    dagger: DaggerStage | None = None
    # What the Table V teacher ablations train with their switch flipped: a recipe without scripted-grasp cloning
    # (ablations.py says why). None: `teacher` itself, which then must have no cloning.
    ablation_teacher: TeacherStage | None = None

    def __post_init__(self):
        t = self.teacher_stage(TEACHERS["rl_with_ot"])
        if t.shipped or ablations.has_scripted_cloning(t.settings):
            raise ValueError(
                f"preset {self.name!r}: the Table V teacher ablations would train on "
                f"{t.settings.name!r}{' (shipped)' if t.shipped else ''}, which clones scripted grasps "
                "or is not trained; give it an ablation_teacher without cloning"
            )

    def teacher_stage(self, variant: Variant = Variant()) -> TeacherStage:
        """The stage that makes a teacher with `variant`'s switches: the preset's own teacher for the plain one,
        the ablation teacher for a Table V teacher ablation."""
        return (self.ablation_teacher or self.teacher) if ablations.is_teacher_ablation(variant) else self.teacher

    @property
    def student_recipe(self) -> str:
        """Which recipe makes the student, in the words every report and card uses."""
        beyond = []
        if (d := self.dagger) is not None:
            which = "per object" if d.objects == "all" else f"of {d.objects.replace(',', ', ')}"
            beyond.append(
                f"{d.rounds} round(s) of DAgger-style relabelling ({d.episodes_per_object} student "
                f"episodes {which} labelled by the teacher's mean action, {d.steps} fine-tuning steps "
                "on the aggregate)"
            )
        if self.student.policy_flags:
            errors = ", ".join(f.removeprefix("--policy.augment_") for f in self.student.policy_flags)
            beyond.append(f"training-time sensor errors ({errors})")
        imitation = "offline imitation of curated stochastic-teacher demos"
        if self.blind_teacher:
            imitation += (
                " from a teacher whose actor approaches blind (it sees nothing of the object until a "
                "fingertip reads a force, as the student)"
            )
        if self.demos.joint_calibration_rad:
            imitation += f", rolled out with every joint reading off by +-{self.demos.joint_calibration_rad:g} rad"
        if self.demos.extra_episodes:
            imitation += ", with " + ", ".join(
                f"{n} more curated episodes of {name}" for name, n in self.demos.extra_episodes
            )
        if not (self.blind_teacher or self.demos.joint_calibration_rad or self.demos.extra_episodes or beyond):
            return f"the paper's: {imitation}"
        return f"beyond the paper: the paper's {imitation}" + "".join(f"; then {b}" for b in beyond)

    @property
    def blind_teacher(self) -> bool:
        """Whether the teacher's actor reads the blind-approach group (teacher/blind_approach.py)."""
        return reads_blind_group(self.teacher.settings.runner.get("obs_groups", {}))

    @property
    def all_deviations(self) -> tuple[str, ...]:
        return self.teacher.settings.deviations + tuple(self.deviations.values())


def derive(base: Preset, name: str, deviations: dict[str, str | None] | None = None, **changes) -> Preset:
    """`base` renamed, with `changes`, stating its own deviation text for every key in `deviations` (None drops
    an inherited one); every other inherited deviation stays word for word."""
    own = {**base.deviations, **(deviations or {})}
    return replace(base, name=name, deviations={k: v for k, v in own.items() if v is not None}, **changes)
