"""What a user who installs from the package index gets: `python -m build` makes an sdist and a wheel that
`twine check` accepts, and the wheel, installed into a fresh venv and run from a folder outside the source tree,
has everything the README's first commands need: plugin discovery, the robot configs, the shipped teacher (the
default of `blindgrasp-eval-teacher`) and the shipped student (`lerobot-eval`).

The fresh venv reuses this venv's packages through a `.pth` line (a plain path: the editable install's own `.pth`
hooks in that folder are not run, so only the wheel's copy of the plugin is importable), and the wheel goes in with
`pip install --no-deps`: nothing is downloaded. Builds without isolation (the build backend from this venv).
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import sysconfig
import tarfile
import time
import zipfile
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
DIST = "lerobot_policy_blindgrasp"

# Run inside the fresh venv: discovery through LeRobot's own function, the registries it fills, and the shipped
# data found through the installed package (not the source tree).
CHECK_INSTALLED = r"""
import json, sys
import draccus
from lerobot.utils.import_utils import register_third_party_plugins
register_third_party_plugins()
from lerobot.configs.policies import PreTrainedConfig
from lerobot.envs.configs import EnvConfig
from lerobot.robots.config import RobotConfig
from lerobot.teleoperators.config import TeleoperatorConfig
import lerobot_blindgrasp
from lerobot_blindgrasp import shipped
from lerobot_blindgrasp import project
from lerobot_blindgrasp.robots.blindgrasp_gripper import BlindgraspGripperConfig
from lerobot_blindgrasp.teacher.policy import default_teacher
from dataclasses import dataclass

@dataclass
class Cli:  # the way lerobot-calibrate and lerobot-record read --robot
    robot: RobotConfig

robot = draccus.parse(Cli, args=[f"--robot=include {shipped.path('blindgrasp_gripper')}"]).robot
assert isinstance(robot, BlindgraspGripperConfig), type(robot)
print(json.dumps({
    "package": lerobot_blindgrasp.__file__,
    "policy": "blindgrasp_transformer" in PreTrainedConfig.get_known_choices(),
    "env": "blindgrasp" in EnvConfig.get_known_choices(),
    "robot": "blindgrasp_gripper" in RobotConfig.get_known_choices(),
    "teleop": "manus_glove" in TeleoperatorConfig.get_known_choices(),
    "robot_config": str(shipped.path("blindgrasp_gripper")),
    "servo_ids": list(robot.servo_ids),
    "teacher": str(default_teacher()),
    "student": str(shipped.path("student_cpu")),
    "source_url": project.source_url(),
}))
"""


@pytest.fixture(scope="module")
def built(tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("dist")
    proc = subprocess.run([sys.executable, "-m", "build", "--no-isolation", "--outdir", str(out), str(ROOT)],
                          capture_output=True, text=True, timeout=300)  # fmt: skip
    assert proc.returncode == 0, proc.stdout[-3000:] + proc.stderr[-3000:]
    return out


def _one(folder: Path, pattern: str) -> Path:
    found = sorted(folder.glob(pattern))
    assert len(found) == 1, found
    return found[0]


def test_sdist_and_wheel_pass_twine_check_and_carry_the_shipped_files(built):
    wheel, sdist = _one(built, f"{DIST}-*.whl"), _one(built, f"{DIST}-*.tar.gz")
    proc = subprocess.run([sys.executable, "-m", "twine", "check", "--strict", str(wheel), str(sdist)],
                          capture_output=True, text=True, timeout=120)  # fmt: skip
    assert proc.returncode == 0 and proc.stdout.count("PASSED") == 2, proc.stdout + proc.stderr
    names = set(zipfile.ZipFile(wheel).namelist())
    for top in ("models", "robot_configs"):
        files = [
            p.relative_to(ROOT) for p in (ROOT / top).rglob("*") if p.is_file() and "__pycache__" not in p.parts
        ]
        assert files, top
        missing = [str(f) for f in files if f"lerobot_blindgrasp/shipped/{f.as_posix()}" not in names]
        assert not missing, f"not in the wheel: {missing}"
    assert "lerobot_blindgrasp/cards/card_templates/sim_teacher_demos.md" in names
    # The lab (benchmarks, the twin's measurement campaign, research diagnosis) runs from a clone, not the wheel.
    assert not [n for n in names if n.startswith(("lab/", "tests/"))]
    entry_points = zipfile.ZipFile(wheel).read(next(n for n in names if n.endswith("entry_points.txt"))).decode()
    assert "lerobot_blindgrasp." in entry_points and " lab." not in entry_points and "= lab." not in entry_points
    metadata = next(n for n in names if n.endswith(".dist-info/METADATA"))
    text = zipfile.ZipFile(wheel).read(metadata).decode()
    assert "Project-URL: Source, " in text and f"Name: {DIST}" in text
    # The license the metadata names travels with the code, as its full text.
    assert "License-Expression: Apache-2.0" in text and "License-File: LICENSE" in text
    licence = next(n for n in names if n.endswith(".dist-info/licenses/LICENSE"))
    assert zipfile.ZipFile(wheel).read(licence).decode() == (ROOT / "LICENSE").read_text()


def test_the_sdist_carries_what_a_packager_builds_and_tests_from(built):
    """The license, changelog and citation, the guides, the tests with their data and emulators, the scripts the
    README runs, the lab the tests import, and the shipped files; no training state or bytecode."""
    sdist = _one(built, f"{DIST}-*.tar.gz")
    with tarfile.open(sdist) as tar:
        names = {n.split("/", 1)[1] for n in tar.getnames() if "/" in n}
    tracked = [p.relative_to(ROOT).as_posix() for p in _tracked_or_none() or []]
    wanted = {"LICENSE", "CHANGELOG.md", "CITATION.cff", "README.md", "pyproject.toml", "setup.py", "MANIFEST.in"}
    wanted |= {
        p for p in tracked if p.split("/")[0] in ("docs", "tests", "scripts", "lab", "models", "robot_configs")
    }
    wanted |= {"docs/getting-started.md", "docs/results.md", "tests/conftest.py", "scripts/main.sh"}
    missing = sorted(wanted - names)
    assert not missing, f"not in the sdist: {missing[:20]}"
    assert not [n for n in names if n.endswith((".pyc", ".pt")) or "__pycache__" in n]


def test_the_project_page_is_the_readme_with_absolute_links(built):
    """The index shows the long description alone: each of the README's relative links and its image becomes an
    address built from [project.urls] (a page under the Changelog URL's folder, the image's bytes under /raw/)."""
    import tomllib

    from lerobot_blindgrasp.cards import links

    wheel = _one(built, f"{DIST}-*.whl")
    with zipfile.ZipFile(wheel) as z:
        metadata = z.read(next(n for n in z.namelist() if n.endswith(".dist-info/METADATA"))).decode()
    assert "Description-Content-Type: text/markdown" in metadata
    description = metadata.split("\n\n", 1)[1]
    readme = (ROOT / "README.md").read_text(encoding="utf-8")
    urls = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]["urls"]
    base, raw = links.file_base(urls), links.raw_base(urls)
    assert base.startswith(urls["Source"]) and raw.startswith(urls["Source"])
    relative = [m for m in links.LINK.finditer(readme) if links.is_relative(m.group(3))]
    assert relative and any(m.group(1) for m in relative)  # pages and the picture
    found = [m.group(3) for m in links.LINK.finditer(description)]
    assert len(found) == len(list(links.LINK.finditer(readme)))
    assert all(not links.is_relative(t) for t in found), [t for t in found if links.is_relative(t)]
    for m in relative:  # each one points at the file it pointed at in the tree
        path, fragment = links.repo_path(m.group(3), "README.md")
        assert (ROOT / path).exists(), path
        assert f"]({(raw if m.group(1) else base) + path}{fragment})" in description, m.group(0)


def _tracked_or_none() -> list[Path] | None:
    """The tracked files (none outside a git checkout, where the fixed list above is what is checked)."""
    try:
        proc = subprocess.run(["git", "ls-files", "-z"], cwd=ROOT, capture_output=True)
    except OSError:  # no git
        return None
    if proc.returncode != 0:
        return None
    return [ROOT / p for p in proc.stdout.decode().split("\0") if p and (ROOT / p).is_file()]


@pytest.mark.slow
def test_the_wheel_works_outside_the_source_tree(built, tmp_path):
    venv = tmp_path / "venv"
    subprocess.run([sys.executable, "-m", "venv", "--without-pip", str(venv)], check=True, timeout=120)
    py = venv / "bin" / "python"
    site = subprocess.run([str(py), "-c", "import sysconfig; print(sysconfig.get_paths()['purelib'])"],
                          check=True, capture_output=True, text=True).stdout.strip()  # fmt: skip
    Path(site, "_test_venv_packages.pth").write_text(sysconfig.get_paths()["purelib"] + "\n")
    wheel = _one(built, f"{DIST}-*.whl")
    # This venv's pip, told to install into the fresh venv's interpreter (`--python`): no pip download either.
    # Without PYTHONPATH: a source tree on it shows pip the build's egg-info as this version, already installed.
    clean = {k: v for k, v in os.environ.items() if k != "PYTHONPATH"}
    subprocess.run([sys.executable, "-m", "pip", "--python", str(py), "install", "--no-deps", "--no-index",
                    "--quiet", str(wheel)], check=True, timeout=300, env=clean)  # fmt: skip
    assert (Path(site) / "lerobot_blindgrasp" / "__init__.py").is_file(), (
        "pip left the fresh venv without the wheel"
    )
    work = tmp_path / "elsewhere"  # no models/ or robot_configs/ here: only the wheel can provide them
    work.mkdir()
    env = {k: v for k, v in os.environ.items() if k not in ("PYTHONPATH", "BLINDGRASP_TEACHER", "VIRTUAL_ENV")}
    env.update(HF_HUB_OFFLINE="1", OMP_NUM_THREADS="1", PATH=f"{venv / 'bin'}:{env.get('PATH', '')}",
               MUJOCO_GL=os.environ.get("MUJOCO_GL", "egl"))  # fmt: skip

    def run(*cmd, timeout=300):
        start = time.monotonic()
        proc = subprocess.run(cmd, cwd=work, env=env, capture_output=True, text=True, timeout=timeout)
        print(f"{time.monotonic() - start:.1f} s: {' '.join(map(str, cmd))[:120]}")
        assert proc.returncode == 0, f"{cmd}\n{proc.stdout[-3000:]}\n{proc.stderr[-3000:]}"
        return proc.stdout

    info = json.loads(run(str(py), "-c", CHECK_INSTALLED).strip().splitlines()[-1])
    installed = Path(site).resolve()
    for key in ("package", "robot_config", "teacher", "student"):
        assert Path(info[key]).resolve().is_relative_to(installed), (key, info[key])
    assert info["policy"] and info["env"] and info["robot"] and info["teleop"]
    assert info["servo_ids"] == [10, 11, 12, 20, 21, 22, 30, 31, 32] and info["source_url"]
    scripts = {p.name for p in (venv / "bin").glob("blindgrasp-*")}
    assert {"blindgrasp-path", "blindgrasp-eval-teacher", "blindgrasp-publish", "blindgrasp-pipeline"} <= scripts

    # The default teacher, as the README's command runs it (one episode of one object, deterministic).
    run(str(venv / "bin" / "blindgrasp-eval-teacher"), "--episodes=1", "--objects=cylinder_b_large",
        "--modes=deterministic", "--progress=false", f"--output_dir={work / 'teacher_eval'}")  # fmt: skip
    teacher = json.loads((work / "teacher_eval" / "eval.json").read_text())
    assert Path(teacher["checkpoint"]).resolve().is_relative_to(installed), teacher["checkpoint"]
    assert teacher["modes"]["deterministic"]["per_object"]["cylinder_b_large"]["successes"] == [True]

    # The shipped student through plain lerobot-eval (start state 1001 of the large cylinder B: lifted in its
    # recorded eval and alone, tests/policies/test_shipped_student.py).
    run(
        str(py),
        "-m",
        "lerobot.scripts.lerobot_eval",
        f"--policy.path={info['student']}",
        "--env.type=blindgrasp",
        "--env.task=cylinder_b_large",
        "--eval.n_episodes=1",
        "--eval.batch_size=1",
        "--policy.device=cpu",
        "--eval.use_async_envs=false",
        "--env.render_stride=50",
        f"--output_dir={work / 'eval'}",
        "--seed=1001",
    )
    result = json.loads((work / "eval" / "eval_info.json").read_text())
    assert result["per_task"][0]["metrics"]["successes"] == [True]
