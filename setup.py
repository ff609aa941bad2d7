"""Only what pyproject.toml cannot say: ship the top-level `models/` and `robot_configs/` inside the wheel.

The design keeps both folders at the repository root, outside the package; a wheel must still carry them (the
commands' default teacher, the shipped student, the robot configs for draccus' `include`). setuptools maps them
onto `lerobot_blindgrasp.shipped.models` and `lerobot_blindgrasp.shipped.robot_configs` (their files are listed
as package data in pyproject.toml). An explicit package list and a mapping cannot sit beside pyproject's
`packages.find`, so the package list lives here. Everything else is in pyproject.toml.
"""

from setuptools import find_packages, setup

SHIPPED = {
    "lerobot_blindgrasp.shipped.models": "models",
    "lerobot_blindgrasp.shipped.robot_configs": "robot_configs",
}

setup(
    packages=find_packages(include=["lerobot_blindgrasp", "lerobot_blindgrasp.*", "lerobot_policy_blindgrasp"])
    + list(SHIPPED),
    package_dir=SHIPPED,
)
