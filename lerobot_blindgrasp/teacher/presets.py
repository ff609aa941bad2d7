"""Kept for imports written before the one preset registry: the teacher presets live in
`lerobot_blindgrasp.presets.teacher` (and the whole registry in `lerobot_blindgrasp.presets`)."""

from lerobot_blindgrasp.presets.teacher import (  # noqa: F401
    CONTACT_REWARD_TERMS,
    CPU,
    PAPER,
    PRESETS,
    QUICK,
    TeacherPreset,
    Variant,
    get_preset,
)
