"""`collection.json` in the dataset folder, beside `meta/` (which LeRobot's tools rewrite): how the demos were made,
run by run. `--resume` reads it to refuse demos of another teacher or curation rule and to continue the env seeds.
"""

from __future__ import annotations

import json
from pathlib import Path

from lerobot_blindgrasp import durable

PROVENANCE_NAME = "collection.json"
FORMAT = "blindgrasp-demos/1"

# Settings that must be identical for demos to share one dataset.
_MUST_MATCH = ("teacher_sha256", "stochastic", "curation", "randomization", "objects")


def is_collection(root: Path) -> bool:
    """Whether `root` was written by blindgrasp-collect-demos (its collection.json), not by lerobot-record."""
    return (Path(root) / PROVENANCE_NAME).is_file()


def load_provenance(root: Path) -> dict:
    p = Path(root) / PROVENANCE_NAME
    if not p.is_file():
        raise FileNotFoundError(f"{root} has no {PROVENANCE_NAME}; it was not written by blindgrasp-collect-demos")
    data = json.loads(p.read_text())
    if data.get("format") != FORMAT:
        raise ValueError(f"{p}: unknown format {data.get('format')!r}, expected {FORMAT!r}")
    return data


def save_provenance(root: Path, data: dict) -> None:
    durable.atomic_write_json(Path(root) / PROVENANCE_NAME, data, indent=2)


def mismatches(old: dict, new: dict) -> list[str]:
    """Settings of `new` that differ from the dataset's `old` provenance (compared as JSON: tuples == lists)."""

    def as_json(v):
        return json.loads(json.dumps(v))

    return [key for key in _MUST_MATCH if as_json(old.get(key)) != as_json(new.get(key))]
