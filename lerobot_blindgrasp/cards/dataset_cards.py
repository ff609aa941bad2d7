"""Dataset cards for blindgrasp datasets: LeRobot's own (`create_lerobot_dataset_card`: its template, the `configs`
entry the Hub viewer needs) with our body from `card_templates/` (package data) as `dataset_description`, our tags,
the license and the paper's citation. `push_to_hub` builds the card from the same arguments, so the README.md written
next to the data is what lands on the Hub.
"""

from __future__ import annotations

import importlib.metadata
import importlib.resources
import json
from dataclasses import fields
from pathlib import Path

import jinja2

from lerobot_blindgrasp import durable, project
from lerobot_blindgrasp.sim import randomization

TEMPLATE_PACKAGE, TEMPLATE_DIR = "lerobot_blindgrasp.cards", "card_templates"
TEMPLATES = {"sim": "sim_teacher_demos.md", "glove": "glove_teleop_demos.md"}
CARD_NAME = "README.md"
DEFAULT_LICENSE = "apache-2.0"  # the project's license

PAPER = (
    "Lee, Choi, Kim, Nam, Jeong: Why Look at It at All?: Vision-Free Multifingered Blind Grasping Using Uniaxial "
    "Fingertip Force Sensing (2025)"
)
CITATION_BIBTEX = """@article{lee2025blindgrasping,
  title  = {Why Look at It at All?: Vision-Free Multifingered Blind Grasping Using Uniaxial Fingertip
            Force Sensing},
  author = {Lee, Edgar and Choi, Junho and Kim, Taemin and Nam, Changjoo and Jeong, Seokhwan},
  year   = {2025}
}"""
_COMMON_TAGS = ["blind-grasping", "force-sensing", "multifingered-gripper", "dclaw", "grasping", "blindgrasp"]
TAGS = {
    "sim": _COMMON_TAGS + ["simulation", "mujoco", "teacher-student", "behavior-cloning"],
    "glove": _COMMON_TAGS + ["real-robot", "teleoperation", "data-glove"],
}
# Hub license identifiers we accept (https://huggingface.co/docs/hub/repositories-licenses); the full list is
# longer, these are the ones that make sense for a robotics dataset.
HUB_LICENSES = frozenset(
    {
        "apache-2.0", "mit", "bsd-3-clause", "cc0-1.0", "cc-by-4.0", "cc-by-sa-4.0", "cc-by-nc-4.0",
        "cc-by-nc-sa-4.0", "odc-by", "odbl", "pddl", "openrail", "other", "unknown",
    }
)  # fmt: skip


def render_body(kind: str, context: dict) -> str:
    if kind not in TEMPLATES:
        raise ValueError(f"unknown card kind {kind!r}; choose from {', '.join(TEMPLATES)}")
    template = importlib.resources.files(TEMPLATE_PACKAGE) / TEMPLATE_DIR / TEMPLATES[kind]
    if not template.is_file():
        raise FileNotFoundError(f"card template {template} is missing; reinstall lerobot_policy_blindgrasp")
    env = jinja2.Environment(undefined=jinja2.StrictUndefined, keep_trailing_newline=True)
    return env.from_string(template.read_text(encoding="utf-8")).render(**context).strip() + "\n"


def versions() -> dict:
    from lerobot_blindgrasp import __version__

    return {
        "plugin_version": __version__,
        "lerobot_version": importlib.metadata.version("lerobot"),
        "code_line": project.code_line(),
    }


def randomization_rows(dr: dict) -> list[tuple[str, str]]:
    labels = {
        "joint_offset_rad": "joint offset at reset, per joint (rad), uniform ±",
        "object_xy_m": "object position at reset, x and y (m), uniform ±",
        "object_friction": "object friction coefficient, uniform",
        "robot_friction": "fingertip friction coefficient, uniform",
        "object_mass_scale": "object mass scale, uniform",
        "kp_scale": "servo stiffness scale, log-uniform",
        "kv_scale": "servo damping scale, log-uniform",
        "external_force": "external pushes on the object",
        "joint_noise_rad": "joint position noise std (rad)",
        "force_noise_n": "fingertip force noise std (N)",
    }
    rows = []
    for f in fields(randomization.DomainRandomization):
        if f.name in ("push_force_n", "push_period_s") and not dr.get("external_force"):
            continue  # irrelevant while pushes are off
        value = dr.get(f.name)
        if f.name in randomization.ROBUSTNESS_FIELDS and value in (None, f.default):
            continue  # beyond Table II and off (or recorded before it existed)
        if isinstance(value, (list, tuple)):
            value = f"[{value[0]:g}, {value[1]:g}]"
        elif isinstance(value, bool):
            value = "on" if value else "off"
        elif isinstance(value, float):
            value = f"{value:.4g}"
        rows.append((labels.get(f.name, f.name), str(value)))
    return rows


def dataset_fields(repo_id: str, meta) -> dict:
    """What both card kinds say about the dataset itself, from LeRobot's metadata."""
    return {
        "repo_id": repo_id,
        "n_episodes": meta.total_episodes,
        "n_frames": meta.total_frames,
        "fps": meta.fps,
        "robot_type": meta.robot_type,
    }


def glove_context(repo_id: str, meta, operators: list[str], notes: str) -> dict:
    per_task: dict[str, dict] = {}
    episodes = meta.episodes or {"tasks": [], "length": []}  # LeRobot loads none for an empty dataset
    for tasks, length in zip(episodes["tasks"], episodes["length"], strict=True):
        for task in tasks:
            row = per_task.setdefault(task, {"task": task, "episodes": 0, "frames": 0})
            row["episodes"] += 1
            row["frames"] += int(length)
    return {
        **dataset_fields(repo_id, meta),
        "tasks": list(per_task.values()),
        "features": {
            k: v
            for k, v in meta.features.items()
            if k not in ("timestamp", "frame_index", "episode_index", "index", "task_index")
        },
        "operators": operators,
        "notes": notes,
        **versions(),
    }


def card_kwargs(
    repo_id: str,
    kind: str,
    context: dict,
    meta,
    license: str = DEFAULT_LICENSE,
    extra_tags: list[str] | None = None,
) -> dict:
    """Keyword arguments for `create_lerobot_dataset_card` and `LeRobotDataset.push_to_hub` (same keys), for a
    card of `kind` ("sim" or "glove") rendered from `context`; `meta` is the dataset's LeRobotDatasetMetadata."""
    if license not in HUB_LICENSES:
        raise ValueError(f"license {license!r} is not one of {sorted(HUB_LICENSES)}")
    return {
        "tags": TAGS[kind] + list(extra_tags or []),
        "license": license,
        "dataset_description": render_body(kind, context),
        "paper": PAPER,
        "citation_bibtex": CITATION_BIBTEX,
        "_dataset_info": meta.info,  # not a card kwarg: popped by build_card
    }


def glove_card_kwargs(root: Path, repo_id: str, operators: list[str] | None = None, notes: str = "", **kw) -> dict:
    """The card of a glove teleoperation recording (`lerobot-record`), from its LeRobot metadata."""
    from lerobot.datasets.dataset_metadata import LeRobotDatasetMetadata

    meta = LeRobotDatasetMetadata(repo_id, root=Path(root))
    return card_kwargs(repo_id, "glove", glove_context(repo_id, meta, operators or [], notes), meta, **kw)


def build_card(kwargs: dict, repo_id: str):
    """The huggingface_hub DatasetCard LeRobot will push for these kwargs."""
    from lerobot.datasets.utils import create_lerobot_dataset_card

    kw = dict(kwargs)
    return create_lerobot_dataset_card(dataset_info=kw.pop("_dataset_info"), repo_id=repo_id, **kw)


def write_card(root: Path, repo_id: str, kwargs: dict) -> Path:
    """Render the card of these `card_kwargs` and save it as `root/README.md`."""
    card = build_card(kwargs, repo_id)
    validate(str(card))
    out = Path(root) / CARD_NAME
    durable.atomic_write_text(out, str(card))  # what DatasetCard.save writes, but atomically
    return out


def validate(text: str) -> dict:
    """Parse a card with huggingface_hub and check the Hub metadata we rely on; returns the metadata dict (the
    offline part of the Hub's own validator, `DatasetCard.validate`, an online call)."""
    from huggingface_hub import DatasetCard

    card = DatasetCard(text)
    data = card.data.to_dict()
    problems = []
    if "robotics" not in (data.get("task_categories") or []):
        problems.append("task_categories must include 'robotics'")
    tags = data.get("tags") or []
    if not tags or not all(isinstance(t, str) and t and " " not in t for t in tags):
        problems.append(f"tags must be non-empty strings without spaces, got {tags!r}")
    if data.get("license") not in HUB_LICENSES:
        problems.append(f"license {data.get('license')!r} is not a Hub license identifier")
    configs = data.get("configs") or []
    if not any(c.get("data_files") for c in configs):
        problems.append("configs must point the Hub viewer at the parquet data files")
    if problems:
        raise ValueError("invalid dataset card metadata: " + "; ".join(problems))
    json.dumps(data)  # the metadata must be plain data
    return data
