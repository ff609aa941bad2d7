"""The one preset registry: every preset of every command, as data. `paper` is exactly the paper's tables; every
recipe beyond it is a named preset that says so in its deviations.

    PRESETS["quick"]            blindgrasp-pipeline --preset=NAME (`pipeline.py`)
    TEACHER_PRESETS["paper"]    blindgrasp-train-teacher --preset=NAME (`teacher.py`): Table III
    SIZES["paper"]              lerobot-train --policy.size=NAME (the policy's own table): Table IV
    GLOVE_PRESETS["glove"]      blindgrasp-train-glove --preset=NAME (`glove.py`)
    TABLE_V["wo_r_i"]           the ablation rows (Table V; `ablations.py`)
"""

from __future__ import annotations

from lerobot_blindgrasp.policies.blindgrasp_transformer.configuration_blindgrasp_transformer import SIZES
from lerobot_blindgrasp.presets.ablations import TABLE_V, TEACHERS
from lerobot_blindgrasp.presets.glove import GLOVE_PRESETS
from lerobot_blindgrasp.presets.pipeline import PRESETS, SHIPPED_TEACHER_ITERATIONS, SHIPPED_TEACHER_PRESET
from lerobot_blindgrasp.presets.stage_configs import Preset, TeacherStage
from lerobot_blindgrasp.presets.student import DaggerStage, Schedule, StudentStage, dataset_frames, schedule
from lerobot_blindgrasp.presets.teacher import TEACHER_PRESETS
from lerobot_blindgrasp.presets.teacher_configs import Variant

__all__ = [
    "PRESETS",
    "SHIPPED_TEACHER_ITERATIONS",
    "SHIPPED_TEACHER_PRESET",
    "SIZES",
    "TABLE_V",
    "TEACHERS",
    "TEACHER_PRESETS",
    "DaggerStage",
    "Preset",
    "Schedule",
    "StudentStage",
    "TeacherStage",
    "Variant",
    "dataset_frames",
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
    for p in [p for p in TEACHER_PRESETS.values() if p.stages]:
        *earlier, (last, stop) = p.stages
        prior = TEACHER_PRESETS[last]
        if list(prior.stages) != earlier or not 0 < stop <= prior.max_iterations < p.max_iterations + 1:
            raise ValueError(f"teacher preset {p.name!r}: its stages {p.stages} disagree with {last!r}'s")


_check_teacher_stages()
