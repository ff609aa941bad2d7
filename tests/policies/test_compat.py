"""`compat`: every reach into LeRobot's internals and every process-wide hook is in that one module, and the installed
LeRobot still has what each reach relies on. A LeRobot release that moves or renames any of it fails here first,
by name, instead of silently turning a reach off; and the student's window cache serves this plugin's datasets
only, never another schema's."""

from __future__ import annotations

import ast
import logging
from pathlib import Path

import numpy as np
import pytest
from lerobot.datasets import LeRobotDataset
from lerobot.datasets.dataset_reader import DatasetReader
from lerobot.utils.constants import ACTION, OBS_STATE

from lerobot_blindgrasp import compat, spec
from lerobot_blindgrasp.policies.blindgrasp_transformer import window_cache

PACKAGE = Path(compat.__file__).parent
# Modules that may hold what the scan below looks for, each with its reason.
ALLOWED = {
    "compat.py": "the one home of the reaches",
    "cli.py": "the plugin's own commands' signal handling and command line, not LeRobot's",
    "teleoperators/manus_glove/manus_bridge.py": "a one-file program copied to the glove's PC: imports no package",
}


def test_the_installed_lerobot_has_what_every_reach_relies_on():
    assert compat.installed_version() is not None
    assert compat.check_lerobot() == []


def test_check_names_what_a_changed_lerobot_no_longer_has(monkeypatch):
    """The check reads LeRobot itself: a writer without `embed_images` is reported, by name."""
    from lerobot.datasets import dataset_writer

    monkeypatch.delattr(dataset_writer, "embed_images")
    problems = compat.check_lerobot()
    assert problems == ["lerobot.datasets.dataset_writer.embed_images is gone"]


def test_another_lerobot_version_is_reported_once_with_the_check(monkeypatch, caplog):
    monkeypatch.setattr(compat, "installed_version", lambda: "9.9.9")
    monkeypatch.setattr(compat, "_warned", False)
    with caplog.at_level(logging.WARNING, logger=compat.__name__):
        compat.cli_arg("dataset.root")
        compat.cli_policy_path()
    warnings = [r.getMessage() for r in caplog.records if r.levelno == logging.WARNING]
    assert len(warnings) == 1
    assert f"written for LeRobot {compat.WRITTEN_FOR}, found 9.9.9" in warnings[0]
    assert "what it relies on is there" in warnings[0]


def test_the_command_line_is_read_as_lerobots_parser_reads_it(monkeypatch):
    """What a script's flags say and LeRobot never hands the robot: the policy, the loop's rate (the last rate flag
    given), and the dataset a recording writes."""
    import sys

    argv = ["lerobot-record", "--dataset.repo_id=me/demo", "--dataset.root=/data/demo", "--dataset.fps=30",
            "--dataset.episode_time_s=12", "--policy.path=/ckpt"]  # fmt: skip
    monkeypatch.setattr(sys, "argv", argv)
    assert compat.read_command_line() == compat.CommandLine(
        policy_path="/ckpt", fps=30.0, fps_flag="dataset.fps", dataset_repo_id="me/demo", dataset_root="/data/demo",
        dataset_fps=30.0, episode_time_s=12.0,
    )  # fmt: skip
    monkeypatch.setattr(sys, "argv", ["lerobot-calibrate", "--robot.type=blindgrasp_gripper"])
    assert compat.read_command_line() == compat.CommandLine()


def test_lerobots_own_episode_announcement_is_recognised(caplog):
    from lerobot.utils.utils import log_say

    with caplog.at_level(logging.INFO):
        log_say(f"{compat.ANNOUNCEMENT} 3", play_sounds=False)
        log_say("Reset the environment", play_sounds=False)
        logging.getLogger().info(f"{compat.ANNOUNCEMENT} 4")  # the text alone, not from log_say
    assert [compat.is_episode_announcement(r) for r in caplog.records] == [True, False, False]


def _lerobot_names(tree: ast.AST) -> set[str]:
    names = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.ImportFrom) and (node.module or "").split(".")[0] in ("lerobot", "datasets"):
            names |= {a.asname or a.name for a in node.names}
        elif isinstance(node, ast.Import):
            names |= {(a.asname or a.name).split(".")[0] for a in node.names if a.name.startswith("lerobot.")}
    return names


def _root(node: ast.AST) -> str | None:
    while isinstance(node, ast.Attribute):
        node = node.value
    return node.id if isinstance(node, ast.Name) else None


def _docstrings(tree: ast.AST) -> set[int]:
    return {
        id(n.value)
        for n in ast.walk(tree)
        if isinstance(n, ast.Expr) and isinstance(n.value, ast.Constant) and isinstance(n.value.value, str)
    }


def _foreign_private(target: ast.Attribute) -> bool:
    """`x._name = ...` on another object than self or cls: another library's private state (LeRobot's writers)."""
    owner = target.value.id if isinstance(target.value, ast.Name) else None
    return target.attr.startswith("_") and not target.attr.startswith("__") and owner not in ("self", "cls")


def _reaches(tree: ast.AST) -> list[str]:
    """Each line that patches LeRobot, writes its private state, sets a process-wide hook, reads LeRobot's command
    line or matches its logs."""
    lerobot, docs, found = _lerobot_names(tree), _docstrings(tree), []
    for node in ast.walk(tree):
        line = getattr(node, "lineno", 0)
        if isinstance(node, ast.Call) and isinstance(node.func, ast.Name) and node.func.id == "setattr":
            target = node.args[0] if node.args else None
            if lerobot and not (isinstance(target, ast.Name) and target.id == "self"):
                found.append(f"{line}: setattr in a module that imports LeRobot")
        if isinstance(node, ast.Call) and isinstance(node.func, ast.Attribute):
            if node.func.attr == "signal" and _root(node.func) == "signal":
                found.append(f"{line}: signal.signal(")
        if isinstance(node, ast.Call):
            name = node.func.attr if isinstance(node.func, ast.Attribute) else getattr(node.func, "id", None)
            if name in ("get_path_arg", "parse_arg") and len(node.args) < 2 and not node.keywords:
                found.append(f"{line}: {name} reads sys.argv")
        if isinstance(node, ast.Assign | ast.AugAssign | ast.AnnAssign):
            targets = node.targets if isinstance(node, ast.Assign) else [node.target]
            for t in (e for x in targets for e in (x.elts if isinstance(x, ast.Tuple) else [x])):
                if isinstance(t, ast.Attribute) and (
                    _root(t) in lerobot or ast.unparse(t) in ("sys.excepthook", "sys.argv") or _foreign_private(t)
                ):
                    found.append(f"{line}: {ast.unparse(t)} =")
        if isinstance(node, ast.Constant) and isinstance(node.value, str) and id(node) not in docs:
            if node.value == "log_say" or node.value.startswith(compat.ANNOUNCEMENT):
                found.append(f"{line}: LeRobot's log text {node.value!r}")
    return found


def test_every_reach_is_in_compat_only():
    strays = []
    for path in sorted(PACKAGE.rglob("*.py")):
        rel = path.relative_to(PACKAGE).as_posix()
        if rel not in ALLOWED:
            strays += [f"{rel}:{r}" for r in _reaches(ast.parse(path.read_text(), rel))]
    assert not strays, "reaches outside compat.py:\n" + "\n".join(strays)


def test_the_scan_finds_each_kind_of_reach():
    """The scan above is not vacuous: compat.py itself holds one of each kind it looks for."""
    found = "\n".join(_reaches(ast.parse((PACKAGE / "compat.py").read_text())))
    for kind in (
        "setattr",
        "signal.signal(",
        "get_path_arg",
        "parse_arg",
        "sys.excepthook =",
        "sys.argv =",
        "ds._is_finalized =",
        "log_say",
    ):
        assert kind in found, kind


def _tiny_dataset(root: Path, features: dict) -> Path:
    ds = LeRobotDataset.create("local/compat", fps=spec.CONTROL_HZ, features=features, root=root, use_videos=False)
    rng = np.random.default_rng(0)
    for _ in range(2):
        for _ in range(5):
            frame = {k: rng.normal(size=f["shape"]).astype(np.float32) for k, f in features.items()}
            ds.add_frame({**frame, "task": "reach"})
        ds.save_episode()
    ds.finalize()
    return root


def _windowed(root: Path) -> LeRobotDataset:
    return LeRobotDataset("local/compat", root=root, delta_timestamps={OBS_STATE: [-1 / spec.CONTROL_HZ, 0.0]})


@pytest.mark.parametrize("schema", ["this plugin's", "another"])
def test_the_window_cache_serves_this_plugins_schema_only(tmp_path, schema):
    """A low-dimensional dataset of another schema (a user's ACT data, say), which the cache could serve exactly,
    keeps LeRobot's reader; the same dataset with this plugin's state and action names is served."""
    features = spec.dataset_features()
    if schema == "another":
        features = {
            OBS_STATE: {"dtype": "float32", "shape": (3,), "names": ["x", "y", "z"]},
            ACTION: {"dtype": "float32", "shape": (2,), "names": ["u", "v"]},
        }
    ds = _windowed(_tiny_dataset(tmp_path / "ds", features))
    assert window_cache.servable(ds.reader)  # only the schema decides
    assert window_cache.ours(ds.meta) == (schema == "this plugin's")
    expected = window_cache.LowDimWindowReader if schema == "this plugin's" else DatasetReader
    assert type(ds.reader) is expected
    item = ds[3]
    assert item[OBS_STATE].shape == (2, features[OBS_STATE]["shape"][0])
