"""What the project ships besides code: the trained models (`models/`) and the hardware site settings
(`robot_configs/`), found alike from a source checkout and from an installed wheel, whose package data they are
(`setup.py` maps them under `lerobot_blindgrasp.shipped`).
"""

from __future__ import annotations

import importlib.resources
import sys
from dataclasses import dataclass
from pathlib import Path

KINDS = ("models", "robot_configs")
_SOURCE_TREE = Path(__file__).resolve().parents[2]  # the repository root, when this file is in a checkout


class ShippedError(FileNotFoundError):
    """A shipped file or folder that is not there; the message says what there is."""


def folder(kind: str) -> Path:
    """The folder that holds the shipped `kind` ("models" or "robot_configs")."""
    if kind not in KINDS:
        raise ValueError(f"kind must be one of {KINDS}, got {kind!r}")
    packaged = Path(str(importlib.resources.files(__name__) / kind))
    if packaged.is_dir():
        return packaged
    # A checkout: pyproject.toml marks the root, so a stray site-packages/models of another project is never taken.
    if (_SOURCE_TREE / "pyproject.toml").is_file() and (_SOURCE_TREE / kind).is_dir():
        return _SOURCE_TREE / kind
    raise ShippedError(
        f"no shipped {kind} next to {__file__} nor in a source tree; reinstall lerobot_policy_blindgrasp"
    )


def names() -> dict[str, list[str]]:
    """Every shipped model folder and robot config, by kind."""
    models = folder("models").iterdir()
    return {
        "models": sorted(p.name for p in models if p.is_dir() and not p.name.startswith((".", "_"))),
        "robot_configs": sorted(p.stem for p in folder("robot_configs").glob("*.yaml")),
    }


def path(name: str) -> Path:
    """A shipped model folder (`student_cpu`) or robot config (`blindgrasp_gripper`, `.yaml` optional)."""
    model = folder("models") / name
    if model.is_dir():
        return model
    config = folder("robot_configs") / (name if name.endswith(".yaml") else f"{name}.yaml")
    if config.is_file():
        return config
    have = names()
    raise ShippedError(
        f"nothing shipped is called {name!r}; models: {', '.join(have['models'])}; "
        f"robot configs: {', '.join(have['robot_configs'])}"
    )


@dataclass
class ShippedPathConfig:
    """Print the installed path of a shipped model folder or robot config (for `--policy.path=` and draccus'
    `include`), or list them all."""

    name: str | None = None  # a model folder (student_cpu, teacher_cpu_bc) or a robot config (blindgrasp_gripper)


def main(argv=None) -> None:
    from lerobot_blindgrasp.cli import parse_config

    cfg = parse_config(ShippedPathConfig, argv)
    try:
        if cfg.name is None:
            for kind, items in names().items():
                print(f"{kind} ({folder(kind)}): {', '.join(items)}")
            return
        print(path(cfg.name))
    except ShippedError as e:
        print(f"error: {e}", file=sys.stderr)
        raise SystemExit(2) from None


if __name__ == "__main__":
    main()
