"""Only what pyproject.toml cannot say.

1. Ship the top-level `models/` and `robot_configs/` inside the wheel. The design keeps both folders at the
   repository root, outside the package; a wheel must still carry them (the commands' default teacher, the shipped
   student, the robot configs for draccus' `include`). setuptools maps them onto `lerobot_blindgrasp.shipped.models`
   and `lerobot_blindgrasp.shipped.robot_configs` (their files are listed as package data in pyproject.toml). An
   explicit package list and a mapping cannot sit beside pyproject's `packages.find`, so the package list lives here.
2. The long description (the package index's project page) is README.md with its relative links and its image made
   absolute from `[project.urls]` (`lerobot_blindgrasp/cards/links.py`): the index shows the README alone, where
   `docs/...` resolves to nothing.

Everything else is in pyproject.toml.
"""

import importlib.util
import tomllib
from pathlib import Path

from setuptools import find_packages, setup

ROOT = Path(__file__).resolve().parent
SHIPPED = {
    "lerobot_blindgrasp.shipped.models": "models",
    "lerobot_blindgrasp.shipped.robot_configs": "robot_configs",
}


def long_description() -> str:
    # Loaded by path: importing the package would import LeRobot, which a build environment does not have.
    spec = importlib.util.spec_from_file_location(
        "_blindgrasp_links", ROOT / "lerobot_blindgrasp" / "cards" / "links.py"
    )
    links = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(links)
    urls = tomllib.loads((ROOT / "pyproject.toml").read_text(encoding="utf-8"))["project"]["urls"]
    return links.absolute_links((ROOT / "README.md").read_text(encoding="utf-8"), "README.md", urls)


setup(
    packages=find_packages(include=["lerobot_blindgrasp", "lerobot_blindgrasp.*", "lerobot_policy_blindgrasp"])
    + list(SHIPPED),
    package_dir=SHIPPED,
    long_description=long_description(),
    long_description_content_type="text/markdown",
)
