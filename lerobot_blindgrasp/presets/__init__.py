"""The one preset registry: every preset of every command, as data, and the types they are made of.

    PRESETS["quick"].demos.episodes_per_object    # pipeline presets (blindgrasp-pipeline --preset=NAME)
    TEACHER_PRESETS["paper"].runner               # teacher presets (blindgrasp-train-teacher --preset=NAME): Table III
    SIZES["paper"]                                # student sizes (lerobot-train --policy.size=NAME): Table IV
    GLOVE_PRESETS["glove"]                        # students on glove recordings (blindgrasp-train-glove --preset=NAME)
    TABLE_V["wo_r_i"]                             # the ablation rows (Table V)
    REGISTRY["teacher"]["cpu"], get("cpu", kind="teacher")

Where each lives: the types beside the data that uses them (`stage_configs.py` and `student.py` for the pipeline,
`teacher_configs.py` for the teacher, `glove.py`), the data in `pipeline.py`, `teacher.py`, `ablations.py` and
`glove.py`. The robustness sweep's presets live with the sweep, in the lab (`lab/robustness/factors.py`). The student sizes are the policy's own table (the policy, a LeRobot
plugin, never imports this registry); the registry names it. Nothing else restates a number, and a preset holds
settings: what a recipe measured lives in the model cards and docs/.

- `paper` is exactly the paper's tables; `cpu` the largest that is useful on a 2-core machine; `quick` the paper's
  student recipe on the shipped teacher (minutes); `smoke` CI plumbing.
- Every recipe beyond the paper is a named preset that says so in its deviations, and in every report and card
  (`Preset.student_recipe`).
"""

from __future__ import annotations

from lerobot_blindgrasp.policies.blindgrasp_transformer.configuration_blindgrasp_transformer import SIZES
from lerobot_blindgrasp.presets.ablations import TABLE_V, TEACHERS, Ablation
from lerobot_blindgrasp.presets.glove import GLOVE_PRESETS, GlovePreset
from lerobot_blindgrasp.presets.pipeline import (
    ABLATION_TEACHER,
    PRESETS,
    SHIPPED_BLIND_TEACHER,
    SHIPPED_TEACHER_ITERATIONS,
    SHIPPED_TEACHER_PRESET,
)
from lerobot_blindgrasp.presets.stage_configs import DemoStage, EvalStage, Preset, TeacherStage, derive
from lerobot_blindgrasp.presets.student import DaggerStage, Schedule, StudentStage, dataset_frames, schedule
from lerobot_blindgrasp.presets.teacher import TEACHER_PRESETS
from lerobot_blindgrasp.presets.teacher_configs import ActorInput, ScriptedDemos, TeacherPreset, Variant

__all__ = [
    "ABLATION_TEACHER",
    "GLOVE_PRESETS",
    "PRESETS",
    "REGISTRY",
    "SHIPPED_BLIND_TEACHER",
    "SHIPPED_TEACHER_ITERATIONS",
    "SHIPPED_TEACHER_PRESET",
    "SIZES",
    "TABLE_V",
    "TEACHERS",
    "TEACHER_PRESETS",
    "Ablation",
    "ActorInput",
    "DaggerStage",
    "DemoStage",
    "EvalStage",
    "GlovePreset",
    "Preset",
    "Schedule",
    "ScriptedDemos",
    "StudentStage",
    "TeacherPreset",
    "TeacherStage",
    "Variant",
    "dataset_frames",
    "derive",
    "get",
    "schedule",
]

# Every kind of preset, by the command (or flag) that takes its names.
REGISTRY: dict[str, dict] = {
    "pipeline": PRESETS,
    "teacher": TEACHER_PRESETS,
    "student_size": SIZES,
    "glove": GLOVE_PRESETS,
    "table_v": TABLE_V,
}


def get(name: str, kind: str = "pipeline"):
    """The `kind` preset called `name`; a ValueError that lists the names there are."""
    if kind not in REGISTRY:
        raise ValueError(f"unknown kind of preset {kind!r}; choose from {', '.join(REGISTRY)}")
    try:
        return REGISTRY[kind][name]
    except KeyError:
        raise ValueError(f"unknown preset {name!r} ({kind}); choose from {', '.join(REGISTRY[kind])}") from None


def _check_teacher_stages() -> None:
    """A staged teacher recipe lists its predecessors as they themselves are staged: the last stage's own stages are
    this preset's earlier ones, and each stage stops at an iteration within that preset's own length."""
    for p in TEACHER_PRESETS.values():
        if not p.stages:
            continue
        *earlier, (last, stop) = p.stages
        prior = TEACHER_PRESETS[last]
        if list(prior.stages) != earlier or not 0 < stop <= prior.max_iterations < p.max_iterations + 1:
            raise ValueError(f"teacher preset {p.name!r}: its stages {p.stages} disagree with {last!r}'s")


_check_teacher_stages()
