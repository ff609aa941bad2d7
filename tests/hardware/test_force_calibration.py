"""Force calibration: `blindgrasp-calibrate-force` run as a user runs it (console script, operator answering its
prompts) on the emulated force board, the file it saves, the robot using it at connect, and the wiring check that
catches a swapped cable. The fit's own refusals are checked on synthetic windows."""

from __future__ import annotations

import json

import numpy as np
import pytest
from emulators.harness import BIN, Operator, cli_env
from emulators.rig import GripperRig

from lerobot_blindgrasp import spec
from lerobot_blindgrasp.emulators.force_board import ForceSensorEmulator
from lerobot_blindgrasp.hardware.force_board import force_calibration as fc
from lerobot_blindgrasp.hardware.force_board.config_force_board import ForceSensorConfig
from lerobot_blindgrasp.hardware.force_board.force_calibration_cli import CalibrateForceConfig, calibrate_force
from lerobot_blindgrasp.hardware.force_board.reader import ForceSensorReader
from lerobot_blindgrasp.robots.blindgrasp_gripper import BlindgraspGripper
from lerobot_blindgrasp.robots.blindgrasp_gripper.config_blindgrasp_gripper import BlindgraspGripperConfig

TRUE_SCALE = (3.1e-5, -2.2e-5, 2.7e-5)  # the cells as built: one bridge wired the other way round
WEIGHT_N = 0.5 * fc.STANDARD_GRAVITY
# The load on each stream channel at each of the five prompts, with the cables as wired (ff, mf, th on 0, 1, 2).
LOADS = [[0, 0, 0], [WEIGHT_N, 0, 0], [0, WEIGHT_N, 0], [0, 0, WEIGHT_N], [0, 0, 0]]


def test_the_command_calibrates_each_fingertip_and_the_robot_uses_it(tmp_path, monkeypatch, caplog):
    cal_dir = tmp_path / "calibration"
    with GripperRig(scale_n_per_count=TRUE_SCALE) as rig:
        rig.hand_move(spec.HOME_POSE)
        op = Operator([str(BIN / "blindgrasp-calibrate-force"), "--robot.type=blindgrasp_gripper", "--robot.id=rig",
                       f"--robot.calibration_dir={cal_dir}", f"--robot.force_sensor.port={rig.force.port}",
                       "--mass_kg=0.5", "--settle_s=0.2", "--window_s=0.4"], cli_env(tmp_path))  # fmt: skip
        for k, load in enumerate(LOADS):
            op.expect(f"Step {k + 1}/5")
            op.expect("Press ENTER")
            rig.force.forces_n = np.array(load, dtype=float)
            op.answer()
        assert op.wait() == 0, op.text
        assert f"Saved {cal_dir / 'rig.force.json'}" in op.text
        saved = json.loads((cal_dir / "rig.force.json").read_text())
        assert saved["format"] == fc.FORMAT and saved["channel_map"] == [0, 1, 2] and saved["mass_kg"] == 0.5
        cal = fc.load_force_calibration(cal_dir / "rig.force.json")
        np.testing.assert_allclose(cal.scales(), TRUE_SCALE, rtol=5e-3)
        np.testing.assert_allclose(cal.offsets(), rig.force.offset, atol=150)  # 300 counts of noise, ~40 frames

        # The robot's config still holds the placeholder scale; the file replaces it at connect.
        cfg = rig.robot_config(cal_dir)
        cfg.force_sensor.scale_n_per_count = [2.5e-5] * 3
        monkeypatch.setattr("builtins.input", rig.calibration_inputs())
        robot = BlindgraspGripper(cfg)
        robot.connect()
        assert "No force calibration" not in caplog.text
        try:
            rig.force.forces_n = np.array([3.0, 4.0, 0.0])
            robot.force.wait_frames(4, 1.0)
            obs = robot.get_observation()
            # With the placeholder the mf cell would read 4 x 2.5 / -2.2 = -4.5 N (a fault).
            assert obs["ff_tip.force"] == pytest.approx(3.0, abs=0.05)
            assert obs["mf_tip.force"] == pytest.approx(4.0, abs=0.05)
        finally:
            robot.disconnect()


def test_without_a_force_calibration_connect_warns_and_names_the_command(tmp_path, caplog):
    """The placeholder scale is used, but not silently: the warning names the file it looked for and the command
    that makes it, with this robot's id."""
    reader = ForceSensorReader("/dev/null", 115_200, [2.5e-5] * 3)
    (tmp_path / "lab_gripper.json").write_text("{}")  # a servo calibration is not a force calibration
    assert fc.apply(reader, tmp_path, "lab_gripper") is None
    assert reader.scale.tolist() == [2.5e-5] * 3
    [record] = [r for r in caplog.records if "No force calibration" in r.getMessage()]
    assert record.levelname == "WARNING"
    message = record.getMessage()
    assert str(tmp_path / "lab_gripper.force.json") in message
    assert (
        'blindgrasp-calibrate-force --robot="include robot_configs/blindgrasp_gripper.yaml" --robot.id=lab_gripper'
        in message
    )


def _calibrate_on(emu: ForceSensorEmulator, tmp_path, monkeypatch, loads, channel_map=(0, 1, 2)):
    prompts = []

    def operator(prompt: str = "") -> str:
        emu.forces_n = np.array(loads[len(prompts)], dtype=float)
        prompts.append(prompt)
        return ""

    monkeypatch.setattr("builtins.input", operator)
    fs = ForceSensorConfig(port=emu.port, channel_map=list(channel_map))
    robot = BlindgraspGripperConfig(id="lab", calibration_dir=tmp_path, force_sensor=fs)
    return calibrate_force(CalibrateForceConfig(robot=robot, settle_s=0.1, window_s=0.3))


def test_a_swapped_cable_is_caught_and_names_both_fingers(tmp_path, monkeypatch):
    """mf_tip's and th_tip's cables swapped on the board: the weight on mf_tip moves channel 2."""
    swapped = [LOADS[0], LOADS[1], LOADS[3], LOADS[2], LOADS[4]]
    with ForceSensorEmulator(scale_n_per_count=TRUE_SCALE) as emu:
        with pytest.raises(fc.ForceCalibrationError, match=r"weight on mf_tip moved channel 2 .*assigns to th_tip; "
                           r"channel_map puts mf_tip on channel 1\. So the mf_tip and th_tip cables are swapped.*"
                           r"channel_map=\[0, 2, 1\]"):  # fmt: skip
            _calibrate_on(emu, tmp_path, monkeypatch, swapped)
        assert not (tmp_path / "lab.force.json").exists()
        # With the suggested channel_map the same wiring calibrates, each finger on its own cable.
        cal = _calibrate_on(emu, tmp_path, monkeypatch, swapped, channel_map=(0, 2, 1))
    assert [cal.fingers[n].channel for n in spec.FORCE_SENSOR_NAMES] == [0, 2, 1]
    np.testing.assert_allclose(cal.scales(), [TRUE_SCALE[0], TRUE_SCALE[2], TRUE_SCALE[1]], rtol=5e-3)


def test_the_robot_refuses_a_calibration_made_with_another_channel_map(tmp_path, monkeypatch):
    with GripperRig() as rig:
        cal = _calibrate_on(rig.force, tmp_path, monkeypatch, LOADS)
        cal.channel_map = [1, 0, 2]
        for name, channel in zip(spec.FORCE_SENSOR_NAMES, cal.channel_map):
            cal.fingers[name].channel = channel
        fc.save_force_calibration(cal, tmp_path / "rig.force.json")
        monkeypatch.setattr("builtins.input", rig.calibration_inputs())
        robot = BlindgraspGripper(rig.robot_config(tmp_path))
        with pytest.raises(
            fc.ForceCalibrationError, match=r"measured with channel_map \[1, 0, 2\].*has \[0, 1, 2\]"
        ):
            robot.connect()
        assert not robot.is_connected
        (tmp_path / "rig.force.json").write_text('{"format": "blindgrasp-force-calibration", "version": 1}')
        with pytest.raises(fc.ForceCalibrationError, match=r"rig\.force\.json is unusable \(KeyError"):
            BlindgraspGripper(rig.robot_config(tmp_path)).connect()


def _window(mean, std=(100.0, 100.0, 100.0)) -> fc.Window:
    return fc.Window(mean=np.asarray(mean, dtype=float), std=np.asarray(std, dtype=float), frames=40)


@pytest.mark.parametrize(
    "loaded, after, why",
    [
        ([[1000, 0, 0], [0, 2e5, 0], [0, 0, 2e5]], [0, 0, 0], r"No channel responded to the weight on ff_tip"),
        (
            [[2e5, 0, 5e4], [0, 2e5, 0], [0, 0, 2e5]],
            [0, 0, 0],
            r"on ff_tip moved channel 0 .* also channel 2 \(th_tip",
        ),
        (
            [[2e5, 0, 0], [0, 2e5, 0], [0, 0, 2e5]],
            [0, 0, 3e4],
            r"th_tip did not come back to its zero .*: \+0\.74 N",
        ),
    ],
)
def test_the_fit_refuses_what_it_cannot_trust(loaded, after, why):
    with pytest.raises(fc.ForceCalibrationError, match=why):
        fc.fit([0, 1, 2], _window([0, 0, 0]), [_window(m) for m in loaded], _window(after), mass_kg=0.5)


def test_the_fit_gives_scale_with_its_sign_and_the_zero():
    loaded = [_window([1e5 + 2e5, -5e4, 7e3]), _window([1e5, -5e4 - 1e5, 7e3]), _window([1e5, -5e4, 7e3 + 4e5])]
    cal = fc.fit([0, 1, 2], _window([1e5, -5e4, 7e3]), loaded, _window([1e5 + 20, -5e4, 7e3]), mass_kg=0.5)
    np.testing.assert_allclose(cal.scales(), [WEIGHT_N / 2e5, -WEIGHT_N / 1e5, WEIGHT_N / 4e5])
    np.testing.assert_allclose(cal.offsets(), [1e5 + 10, -5e4, 7e3])
