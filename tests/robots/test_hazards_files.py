"""Hazards of the files and artifacts loaded and written (docs/hardware.md, "Hazard analysis", table "Files and
artifacts loaded": the gripper and glove calibrations, the robot and teleop configs, the policy's `config.json`,
processors and weights, the dataset files written). Each is refused by name before anything moves (hypothesis:
any file is valid or refused), and a full disk while writing a dataset keeps the first error."""

from __future__ import annotations

import ast
import errno
import io
import json
import logging
import math
import os
import re
import subprocess
import sys
from pathlib import Path
from types import SimpleNamespace

import draccus
import pytest
from emulators.glove_sender import FIST, OPEN, free_udp_port, write_glove_calibration
from emulators.hostile import FAST, json_values
from emulators.loop import no_prompt
from hypothesis import given
from hypothesis import strategies as st
from lerobot.robots.config import RobotConfig
from lerobot.teleoperators.config import TeleoperatorConfig
from test_policy_check import ROBOT, _checkpoint

from lerobot_blindgrasp import policy_contract, spec
from lerobot_blindgrasp.policy_contract import PolicyMismatchError
from lerobot_blindgrasp.robots.blindgrasp_gripper import BlindgraspGripper, BlindgraspGripperConfig
from lerobot_blindgrasp.robots.blindgrasp_gripper import servo_calibration as calib
from lerobot_blindgrasp.robots.blindgrasp_gripper.servo_calibration import CalibrationFileError
from lerobot_blindgrasp.teleoperators.manus_glove import ManusGlove, ManusGloveConfig
from lerobot_blindgrasp.teleoperators.manus_glove.manus_glove import GloveCalibrationError
from lerobot_blindgrasp.teleoperators.manus_glove.retarget import REQUIRED_KEYS

PACKAGE = Path(__file__).resolve().parents[2] / "lerobot_blindgrasp"


# --- the gripper's calibration ----------------------------------------------------------------------------------
@pytest.mark.parametrize(
    "edit,why",
    [
        (lambda c: c.pop("mf_j21"), r"joints \['mf_j21'\] are missing"),
        (lambda c: c["th_j30"].update(drive_mode=3), "th_j30: drive_mode 3"),
        (lambda c: c["ff_j10"].update(id=99), "ff_j10: servo ID 99"),
        (lambda c: c["ff_j12"].update(range_min=3000, range_max=100), r"ff_j12: range \[3000, 100\]"),
        (lambda c: c["ff_j11"].pop("homing_offset"), r"ff_j11: lacks \['homing_offset'\]"),
    ],
)
def test_bad_calibration_file_is_refused_before_any_motion(rig, robot, monkeypatch, edit, why):
    robot.disconnect()
    cal = json.loads(robot.calibration_fpath.read_text())
    edit(cal)
    robot.calibration_fpath.write_text(json.dumps(cal))
    no_prompt(monkeypatch)
    packets = sum(rig.dxl.instruction_counts.values())
    r = BlindgraspGripper(rig.robot_config(robot.calibration_dir))
    with pytest.raises(CalibrationFileError, match=why):
        r.connect()
    assert sum(rig.dxl.instruction_counts.values()) == packets  # the port was never even opened
    assert not r.is_connected and not rig.dxl.any_torque()


def test_lerobot_calibrate_replaces_a_bad_file(rig, robot, monkeypatch):
    robot.disconnect()
    robot.calibration_fpath.write_text("{not json")
    monkeypatch.setattr("builtins.input", rig.calibration_inputs())
    r = BlindgraspGripper(rig.robot_config(robot.calibration_dir))
    r.connect(calibrate=False)  # what lerobot-calibrate does
    r.calibrate()
    r.disconnect()
    assert BlindgraspGripper(rig.robot_config(robot.calibration_dir)).calibration_error is None


def _file_variants(text: str, wrong_values=(True, "12", 1.5, None)):
    raw = json.loads(text)
    first = next(iter(raw))
    yield "empty", b""
    yield "half", text[: len(text) // 2].encode()
    yield "last byte cut", text.rstrip()[:-1].encode()
    yield "not UTF-8", b"\xff\xfe" + text.encode()
    yield "a list", b"[]"
    for key in list(raw[first])[:1]:
        for wrong in wrong_values:
            bad = json.loads(text)
            bad[first][key] = wrong
            yield f"{key}={wrong!r}", json.dumps(bad).encode()


def test_truncated_or_corrupt_gripper_calibration_is_refused(rig, robot, monkeypatch):
    robot.disconnect()
    no_prompt(monkeypatch)
    good = robot.calibration_fpath.read_text()
    for name, text in _file_variants(good):
        robot.calibration_fpath.write_bytes(text)
        r = BlindgraspGripper(rig.robot_config(robot.calibration_dir))
        with pytest.raises(
            CalibrationFileError, match=r"invalid.*Run lerobot-calibrate --robot.type=blindgrasp_grip"
        ):
            r.connect()
        assert not r.is_connected, name
    assert not rig.dxl.any_torque()


def _gripper_file() -> bytes:
    ids = dict(zip(spec.JOINT_NAMES, spec.SERVO_IDS, strict=True))
    cal = calib.build(ids, dict.fromkeys(ids, 1), dict.fromkeys(ids, -1000), spec.JOINT_LOWER, spec.JOINT_UPPER)
    return json.dumps({j: vars(c) for j, c in cal.items()}, indent=4).encode()


def _mutations(good: bytes):
    raw = json.loads(good)
    keys = st.sampled_from(sorted(raw))
    return st.one_of(
        st.integers(0, len(good) - 1).map(lambda n: good[:n]),  # truncated anywhere
        st.binary(max_size=80),
        json_values.map(lambda v: json.dumps(v).encode()),
        st.builds(
            lambda n, junk: good[:n] + junk + good[n:],
            st.integers(0, len(good)),
            st.binary(min_size=1, max_size=8),
        ),  # fmt: skip
        st.builds(lambda k, v: _replace(raw, k, v), keys, json_values | st.integers(-(2**70), 2**70)),
    )


def _replace(raw: dict, key: str, value) -> bytes:
    out = json.loads(json.dumps(raw))
    inner = out[key]
    if isinstance(inner, dict):
        inner[sorted(inner)[len(str(value)) % len(inner)]] = value
    else:
        out[key] = value
    return json.dumps(out).encode()


@FAST
@given(data=_mutations(_gripper_file()))
def test_a_gripper_calibration_file_is_valid_or_refused_by_name(tmp_path_factory, data):
    d = tmp_path_factory.mktemp("cal")
    (d / "g.json").write_bytes(data)
    robot = BlindgraspGripper(BlindgraspGripperConfig(id="g", calibration_dir=d))  # never raises
    if robot.calibration_error is not None:
        assert isinstance(robot.calibration_error, calib.CalibrationFileError)
        assert "lerobot-calibrate" in str(robot.calibration_error) and robot.calibration == {}
        with pytest.raises(calib.CalibrationFileError):
            robot.connect()  # refused before the port is opened
    else:
        ids = dict(zip(spec.JOINT_NAMES, spec.SERVO_IDS, strict=True))
        assert calib.servo_calibration_problems(robot.calibration, ids) == []
        assert all(type(getattr(c, f)) is int for c in robot.calibration.values() for f in calib.RECORD_FIELDS)


# --- the glove's calibration ------------------------------------------------------------------------------------
def test_truncated_or_corrupt_glove_calibration_is_refused(tmp_path, monkeypatch):
    no_prompt(monkeypatch)
    write_glove_calibration(tmp_path / "op.json")
    good = (tmp_path / "op.json").read_text()
    cfg = ManusGloveConfig(id="op", port=free_udp_port(), calibration_dir=tmp_path)
    as_bool = json.dumps({"open": OPEN, "fist": {**FIST, "IndexMCPSpread": True}}).encode()
    for _name, text in [*_file_variants(good, (True, "12", None, [1])), ("a bool for a number", as_bool)]:
        (tmp_path / "op.json").write_bytes(text)
        with pytest.raises(
            GloveCalibrationError, match=r"invalid.*Run lerobot-calibrate --teleop.type=manus_glove"
        ):
            ManusGlove(cfg).connect()


@FAST
@given(data=_mutations(json.dumps({"open": OPEN, "fist": FIST}).encode()))
def test_a_glove_calibration_file_is_valid_or_refused_by_name(tmp_path_factory, data):
    d = tmp_path_factory.mktemp("glove")
    (d / "op.json").write_bytes(data)
    glove = ManusGlove(ManusGloveConfig(id="op", calibration_dir=d))  # never raises
    if glove.calibration_error is not None:
        assert isinstance(glove.calibration_error, GloveCalibrationError)
        assert "lerobot-calibrate" in str(glove.calibration_error) and glove.calibration is None
    else:
        cal = glove.calibration
        for pose in (cal.open, cal.fist):
            assert all(math.isfinite(pose[k]) and not isinstance(pose[k], bool) for k in REQUIRED_KEYS)


# --- robot and teleop configs -----------------------------------------------------------------------------------
@pytest.mark.parametrize(
    "cut,why",
    [
        ("baudrate: 1000000", "baudrate 100 is not a Dynamixel rate"),
        ("  tare_s: 0.5", r"force_sensor.\['tare_s'\]"),
    ],
)
def test_a_corrupt_robot_config_is_refused(tmp_path, cut, why):
    text = (Path(__file__).resolve().parents[2] / "robot_configs" / "blindgrasp_gripper.yaml").read_text()
    broken = text.replace(cut, cut.split(":")[0] + ": " + ("100" if "baud" in cut else "0"))
    (tmp_path / "r.yaml").write_text(broken)
    with pytest.raises(Exception) as e, open(tmp_path / "r.yaml") as f, draccus.config_type("yaml"):
        draccus.load(RobotConfig, f)
    assert re.search(why, _chain(e.value)), _chain(e.value)
    with pytest.raises(Exception) as e, draccus.config_type("yaml"):
        draccus.load(TeleoperatorConfig, io.StringIO("type: manus_glove\nfrozen_frames: -3\n"))
    assert "frozen_frames must be 0 (off) or >= 2" in _chain(e.value)


def _chain(e: BaseException | None) -> str:
    """The messages of an exception and its causes (draccus wraps a config's ValueError in its own error)."""
    out = []
    while e is not None:
        out.append(str(e))
        e = e.__cause__ or e.__context__
    return " <- ".join(out)


# --- the policy's files -----------------------------------------------------------------------------------------
def test_a_truncated_checkpoint_config_is_refused_before_anything_moves(tmp_path):
    ckpt = _checkpoint(tmp_path)
    (ckpt / "config.json").write_text((ckpt / "config.json").read_text()[:40])
    with pytest.raises(PolicyMismatchError, match=r"config.json is unreadable \(JSONDecodeError"):
        policy_contract.check_checkpoint(ckpt, ROBOT)


def test_normalizer_stats_fitted_on_another_state_are_refused(tmp_path):
    """config.json edited to 12 while the saved normalizer was fitted on a 10-d state: refused by the file."""
    ckpt = _checkpoint(tmp_path)
    pre = json.loads((ckpt / "policy_preprocessor.json").read_text())
    pre["steps"][-1]["config"]["features"]["observation.state"]["shape"] = [10]
    (ckpt / "policy_preprocessor.json").write_text(json.dumps(pre))
    bad, _ = policy_contract.checkpoint_problems(ckpt, ROBOT)
    assert bad == [
        f"'observation.state' shape (10,) in {ckpt / 'policy_preprocessor.json'} (normalizer), the robot has (12,)"
    ]


def test_a_policy_with_nan_or_zero_normalizer_stats_is_refused(tmp_path):
    """A state feature that never varied in the training data (a dead load cell) has std 0: the normalizer divides by
    eps, and any change of it reaches the network x 1e8. NaN stats (a broken stats file) make every action NaN."""
    from safetensors.torch import load_file, save_file

    ckpt = _checkpoint(tmp_path)
    path = ckpt / "policy_preprocessor_step_4_normalizer_processor.safetensors"
    stats = load_file(str(path))
    stats["observation.state.std"][10] = 0.0
    stats["observation.state.mean"][0] = float("nan")
    save_file(stats, str(path))
    bad, _ = policy_contract.checkpoint_problems(ckpt, ROBOT)
    assert bad == [f"observation.state.mean not finite at ['observation.state[0] (ff_j10.pos)'] in {path}",
                   f"observation.state.std is 0 at ['observation.state[10] (mf_tip.force)'] in {path}: any change "
                   "of that input would reach the network multiplied by 1/eps"]  # fmt: skip


def test_a_policy_with_nan_weights_is_refused(tmp_path):
    from safetensors.torch import load_file, save_file

    ckpt = _checkpoint(tmp_path)
    weights = load_file(str(ckpt / "model.safetensors"))
    name = sorted(weights)[0]
    weights[name].view(-1)[:3] = float("nan")
    save_file(weights, str(ckpt / "model.safetensors"))
    bad, _ = policy_contract.checkpoint_problems(ckpt, ROBOT)
    assert bad == [f"3 non-finite weights in {ckpt / 'model.safetensors'} (in ['{name}'])"]


# --- dataset files written --------------------------------------------------------------------------------------
def test_no_cleanup_finalizes_a_dataset_bare():
    """Every `finalize()` in a `finally` of the package goes through `compat.finalize_or_abandon` inside
    `_cleanup`: a second failure there (a full disk fails the footer write too) is logged, never raised over the
    first, and the writers are abandoned so that pyarrow does not abort at exit."""
    bare = []
    for path in sorted(PACKAGE.rglob("*.py")):
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
            if isinstance(node, ast.Try):
                calls = [c for stmt in node.finalbody for c in ast.walk(stmt) if isinstance(c, ast.Call)]
                bare += [f"{path.relative_to(PACKAGE.parent)}:{c.lineno}" for c in calls
                         if isinstance(c.func, ast.Attribute) and c.func.attr == "finalize"]  # fmt: skip
    assert not bare, bare


def test_a_full_disk_at_finalize_keeps_the_first_error(tmp_path, monkeypatch, caplog):
    """No root needed: the write fails with ENOSPC (the first error), then finalize() fails with ENOSPC too."""
    from lab.bench.demos_bench import _writer_speed
    from lerobot_blindgrasp.demos import curation, dataset

    create = dataset.create

    def full_disk(*args, **kwargs):
        ds = create(*args, **kwargs)
        ds.finalize = lambda: (_ for _ in ()).throw(OSError(errno.ENOSPC, "No space left on device", "footer"))
        return ds

    def write_episode(*args, **kwargs):
        raise OSError(errno.ENOSPC, "No space left on device", "episode data")

    monkeypatch.setattr(curation, "judge_episode", lambda *args: None)
    monkeypatch.setattr(dataset, "create", full_disk)
    monkeypatch.setattr(dataset, "write_episode", write_episode)
    with caplog.at_level(logging.ERROR), pytest.raises(OSError) as e:
        _writer_speed([SimpleNamespace(task_reward=None, uniaxial_force=None)], tmp_path / "w", per_frame=False)
    assert e.value.filename == "episode data"  # the first error, not the finalize's
    assert "Finalizing the dataset also failed (the disk is full (ENOSPC)); the first error stands" in caplog.text


def _tmpfs(path: Path, size_kb: int) -> bool:
    if os.geteuid() != 0:
        return False
    path.mkdir(parents=True, exist_ok=True)
    return subprocess.run(["mount", "-t", "tmpfs", "-o", f"size={size_kb}k", "tmpfs", str(path)],
                          capture_output=True).returncode == 0  # fmt: skip


def test_a_second_failure_during_cleanup_never_masks_the_first_or_aborts(tmp_path):
    """A disk that fills during demo collection: the stats write fails (the first error), then finalize() fails too
    (the footer write). The run ends with the first error in one message and exit 4, not a chained traceback and
    pyarrow's abort at interpreter shutdown (exit 134)."""
    disk = tmp_path / "small"
    if not _tmpfs(disk, 100):
        pytest.skip("needs root to mount a 100 kB tmpfs (a real full disk)")
    try:
        cmd = [
            sys.executable,
            "-m",
            "lerobot_blindgrasp.demos.collect_cli",
            f"--output_dir={disk / 'demos'}",
            "--repo_id=test/full",
            "--episodes_per_object=4",
            "--num_envs=2",
            "--curation.enabled=false",
            "--objects=cylinder_a_medium,cuboid_a_medium",
            "--progress=false",
            "--threads=1",
            "--checkpoint_s=0",
        ]
        env = {**os.environ, "HF_HUB_OFFLINE": "1", "OMP_NUM_THREADS": "1"}
        out = subprocess.run(cmd, capture_output=True, text=True, env=env, timeout=300)
    finally:
        subprocess.run(["umount", "-l", str(disk)], capture_output=True)
    text = out.stdout + out.stderr
    assert out.returncode == 4, text[-3000:]
    assert "Traceback" not in text and "also failed" in text, text[-3000:]
    assert "error: could not write" in text and "the disk is full (ENOSPC)" in text
