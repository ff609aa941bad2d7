"""What importing the package costs and changes: no simulator or RL library, no environment setting.

Each check runs in a fresh interpreter, since this test process has long imported everything.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys

import pytest

HEAVY = ("mujoco", "rsl_rl")
# Parts of the package that registering the plugin types needs none of (the real trial is imported when its envs
# are made; the robot needs no analysis code, the policy no preset registry).
UNNEEDED = (
    "lerobot_blindgrasp.analysis",
    "lerobot_blindgrasp.presets",
    "lab.robustness",
    "lerobot_blindgrasp.teacher",
    "lerobot_blindgrasp.pipeline",
    "lerobot_blindgrasp.envs.real_trial",
)


def _fresh(code: str, env: dict | None = None) -> subprocess.CompletedProcess:
    return subprocess.run(
        [sys.executable, "-c", code],
        env=env or dict(os.environ),
        capture_output=True,
        text=True,
        check=True,
        timeout=300,
    )


def test_plugin_discovery_imports_neither_mujoco_nor_rsl_rl_and_sets_nothing():
    """A LeRobot user who only runs the student on the real gripper never loads the simulator: LeRobot's own plugin
    discovery (what every lerobot-* command does first) registers every type without it, and leaves the OpenMP
    setting alone (that belongs to the commands that train)."""
    env = {k: v for k, v in os.environ.items() if k != "OMP_WAIT_POLICY"}
    code = (
        "import json, os, sys\n"
        "from lerobot.utils.import_utils import register_third_party_plugins\n"
        "register_third_party_plugins()\n"
        "from lerobot.configs import PreTrainedConfig\n"
        "from lerobot.envs.configs import EnvConfig\n"
        "from lerobot.robots.config import RobotConfig\n"
        "print(json.dumps({'loaded': 'lerobot_blindgrasp' in sys.modules,\n"
        "                  'types': [PreTrainedConfig.get_choice_class('blindgrasp_transformer').__name__,\n"
        "                            EnvConfig.get_choice_class('blindgrasp').__name__,\n"
        "                            RobotConfig.get_choice_class('blindgrasp_gripper').__name__],\n"
        "                  'omp_wait_policy': os.environ.get('OMP_WAIT_POLICY'),\n"
        f"                  'heavy': [m for m in {HEAVY!r} if m in sys.modules],\n"
        f"                  'unneeded': [m for m in sys.modules if m.startswith({UNNEEDED!r})]}}))\n"
    )
    out = json.loads(_fresh(code, env).stdout.strip().splitlines()[-1])
    assert out == {
        "loaded": True,
        "heavy": [],
        "unneeded": [],
        "omp_wait_policy": None,
        "types": ["BlindgraspTransformerConfig", "BlindGraspEnvConfig", "BlindgraspGripperConfig"],
    }


@pytest.mark.parametrize("user_setting", [None, "ACTIVE"])
def test_a_training_command_starts_over_with_sleeping_openmp_threads_unless_the_user_chose(user_setting):
    """OpenMP reads OMP_WAIT_POLICY once, when torch loads it: a command that has torch loaded already restarts
    itself (same arguments) with the setting; a policy the user chose is kept, and nothing restarts."""
    env = {k: v for k, v in os.environ.items() if k != "OMP_WAIT_POLICY"}
    if user_setting:
        env["OMP_WAIT_POLICY"] = user_setting
    code = (
        "print('start', flush=True)\n"
        "import os, torch\n"
        "from lerobot_blindgrasp.cli import sleeping_openmp_threads\n"
        "sleeping_openmp_threads(restart=True)\n"
        "print('policy', os.environ['OMP_WAIT_POLICY'])\n"
    )
    lines = _fresh(code, env).stdout.split("\n")
    starts = 1 if user_setting else 2
    assert [ln for ln in lines if ln] == ["start"] * starts + [f"policy {user_setting or 'PASSIVE'}"]


def test_called_from_python_the_setting_only_reaches_the_processes_it_starts():
    env = {k: v for k, v in os.environ.items() if k != "OMP_WAIT_POLICY"}
    code = (
        "print('start', flush=True)\n"
        "import os, subprocess, sys, torch\n"
        "from lerobot_blindgrasp.cli import sleeping_openmp_threads\n"
        "sleeping_openmp_threads(restart=False)\n"
        "child = \"import os; print('child', os.environ['OMP_WAIT_POLICY'])\"\n"
        "print(subprocess.run([sys.executable, '-c', child], capture_output=True, text=True).stdout.strip())\n"
    )
    assert _fresh(code, env).stdout.split() == ["start", "child", "PASSIVE"]
