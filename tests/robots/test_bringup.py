"""Bring-up checks of the real gripper: `lerobot-setup-motors` from factory servos, the udev rules, and connect()'s
USB latency timer and a calibration nobody can make.

The latency timer is checked on a fake sysfs tree (`tmp_path`), laid out as the kernel's ftdi_sio driver lays it
out, and once through the robot's real connect() against the emulated servos and force board.
"""

from __future__ import annotations

import dataclasses
import io
import logging
import os
import re
from pathlib import Path

import pytest
from emulators.faults import FaultyBus
from emulators.harness import BIN, Operator, cli_env
from emulators.rig import LATENCY_TIMER_MS, GripperRig

from lerobot_blindgrasp import spec
from lerobot_blindgrasp.hardware.dynamixel import latency_timer
from lerobot_blindgrasp.hardware.dynamixel.latency_timer import check_latency_timer, ensure_low_latency
from lerobot_blindgrasp.robots.blindgrasp_gripper.servo_calibration import CalibrationFileError

ROOT = Path(__file__).resolve().parents[2]
READ_ONLY_SYSFS_INT = Path("/sys/devices/system/cpu/kernel_max")  # 0444 and no store op: root cannot write it


def fake_ftdi(tmp_path: Path, tty: str = "ttyUSB3", ms: int | None = 16) -> tuple[Path, Path]:
    """A /dev and /sys pair for one adapter; `ms=None` makes a usb-serial device without a timer (CH340)."""
    sys_dir = tmp_path / "sys" / "bus" / "usb-serial" / "devices" / tty
    sys_dir.mkdir(parents=True)
    if ms is not None:
        (sys_dir / "latency_timer").write_text(f"{ms}\n")
    dev = tmp_path / "dev"
    (dev / "serial" / "by-id").mkdir(parents=True)
    (dev / tty).touch()
    by_id = dev / "serial" / "by-id" / "usb-FTDI_USB__-__Serial_Converter_FT0ABC12-if00-port0"
    by_id.symlink_to(Path("..") / ".." / tty)
    return tmp_path / "sys", by_id


def test_a_16_ms_timer_is_set_to_1_ms_through_a_by_id_symlink(tmp_path, caplog):
    sysfs, port = fake_ftdi(tmp_path)
    with caplog.at_level(logging.INFO):
        [result] = ensure_low_latency(str(port), sysfs_root=sysfs)
    timer = sysfs / "bus/usb-serial/devices/ttyUSB3/latency_timer"
    assert (result.sysfs_file, result.before_ms, result.after_ms, result.ok) == (timer, 16, 1, True)
    assert timer.read_text().strip() == "1"
    assert "16 ms -> 1 ms" in caplog.text and not [r for r in caplog.records if r.levelno >= logging.WARNING]


def test_a_timer_already_at_1_ms_is_left_alone(tmp_path):
    sysfs, port = fake_ftdi(tmp_path, ms=1)
    timer = sysfs / "bus/usb-serial/devices/ttyUSB3/latency_timer"
    timer.chmod(0o444)  # a write would fail for a non-root user, and root would change the mtime
    before = timer.stat().st_mtime_ns
    result = check_latency_timer(str(port), sysfs)
    assert (result.before_ms, result.after_ms, result.warning()) == (1, 1, None)
    assert timer.stat().st_mtime_ns == before


def test_an_unwritable_timer_warns_with_the_command_to_run(tmp_path, caplog):
    sysfs, port = fake_ftdi(tmp_path)
    timer = sysfs / "bus/usb-serial/devices/ttyUSB3/latency_timer"
    if os.geteuid() == 0:  # root writes any 0444 file; a sysfs attribute without a store op refuses even root
        if not READ_ONLY_SYSFS_INT.is_file():
            pytest.skip(f"needs {READ_ONLY_SYSFS_INT} to stand for a file root cannot write")
        timer.unlink()
        timer.symlink_to(READ_ONLY_SYSFS_INT)
        stands_for = int(READ_ONLY_SYSFS_INT.read_text())
    else:
        timer.chmod(0o444)
        stands_for = 16
    with caplog.at_level(logging.WARNING):
        [result] = ensure_low_latency(str(port), sysfs_root=sysfs)
    assert result.before_ms == stands_for and result.after_ms is None and not result.ok
    assert f"echo 1 | sudo tee {timer}" in caplog.text
    assert "99-blindgrasp.rules" in caplog.text and str(port) in caplog.text


def test_ptys_ch340_and_acm_ports_are_silent(tmp_path, caplog):
    sysfs, ch340 = fake_ftdi(tmp_path, tty="ttyUSB0", ms=None)
    master, slave = os.openpty()
    try:
        with caplog.at_level(logging.DEBUG, logger=latency_timer.__name__):
            results = ensure_low_latency(os.ttyname(slave), str(ch340), "/dev/ttyACM7", sysfs_root=sysfs)
            results += ensure_low_latency(os.ttyname(slave))  # the real /sys: a pty has no usb-serial entry
    finally:
        os.close(master)
        os.close(slave)
    assert [r.sysfs_file for r in results] == [None] * 4 and not caplog.records


def test_the_udev_rules_name_the_adapters_and_set_the_timer():
    text = (ROOT / "robot_configs" / "udev" / "99-blindgrasp.rules").read_text()
    rules = [line for line in text.splitlines() if line.strip() and not line.lstrip().startswith("#")]
    token = re.compile(
        r'^(ACTION|SUBSYSTEM|DRIVERS|ATTRS\{\w+\}|ATTR\{\w+\}|ENV\{\w+\}|SYMLINK|GROUP|MODE)(==|\+=|=)"[^"]*"$'
    )
    for rule in rules:  # udev's own syntax: comma-separated KEY op "value"
        assert all(token.match(t.strip()) for t in rule.split(",")), rule
    # `udevadm trigger` sends "change" unless told --action=add: a rule of "add" alone would wait for a replug.
    assert all('ACTION=="add|change"' in r for r in rules if "ACTION" in r)
    assert "udevadm trigger --action=add" in (ROOT / "docs" / "bringup.md").read_text()
    # The force board's name goes to one board: each of its lines names a serial number or a USB socket, which the
    # lab fills in (a placeholder matches no device), never a chip alone.
    force = [r for r in rules if "blindgrasp_force" in r or 'idProduct}=="6001"' in r]
    assert force and all('ATTRS{serial}=="FORCE_BOARD_SERIAL"' in r or 'ENV{ID_PATH}=="FORCE_BOARD_USB_SOCKET"' in r
                         for r in force), force  # fmt: skip
    u2d2 = [r for r in rules if 'ATTRS{idVendor}=="0403"' in r and 'ATTRS{idProduct}=="6014"' in r]
    assert any('SYMLINK+="blindgrasp_u2d2"' in r and 'GROUP="dialout"' in r for r in u2d2)
    assert any('ATTR{latency_timer}="1"' in r and 'SUBSYSTEM=="usb-serial"' in r for r in u2d2)
    assert sum('SYMLINK+="blindgrasp_force"' in r for r in rules) >= 2  # the Nano's FTDI and CH340 variants
    # The Nano's USB chips the guide names are the ones the rules give the force board's name.
    named = set(
        re.findall(r'idVendor}=="(\w+)", ATTRS{idProduct}=="(\w+)", [^,]+, SYMLINK\+="blindgrasp_force"', text)
    )
    [nano] = re.findall(
        r"the Nano \(([^)]*)\) `/dev/blindgrasp_force`", (ROOT / "docs" / "bringup.md").read_text()
    )
    assert set(re.findall(r"([0-9a-f]{4}):([0-9a-f]{4})", nano)) == named, (nano, named)


def _connect(rig: GripperRig, calibration_dir: Path, monkeypatch):
    from lerobot_blindgrasp.robots.blindgrasp_gripper import BlindgraspGripper

    monkeypatch.setattr("builtins.input", rig.calibration_inputs())
    robot = BlindgraspGripper(rig.robot_config(calibration_dir))
    robot.connect()
    return robot


def test_connect_sets_the_bus_adapters_timer(tmp_path, monkeypatch, caplog):
    """The emulators sit on ptys; a fake sysfs entry under the pty's name stands for its FTDI adapter."""
    with GripperRig() as rig:
        rig.hand_move(spec.HOME_POSE)
        timer = tmp_path / "sys" / "bus" / "usb-serial" / "devices" / Path(rig.dxl.port).name / "latency_timer"
        timer.parent.mkdir(parents=True)
        timer.write_text("16\n")
        monkeypatch.setattr(latency_timer, "SYSFS_ROOT", tmp_path / "sys")
        with caplog.at_level(logging.INFO, logger=latency_timer.__name__):
            robot = _connect(rig, tmp_path / "calibration", monkeypatch)
        robot.disconnect()
    assert timer.read_text().strip() == "1"
    assert f"USB latency timer of '{rig.dxl.port}': 16 ms -> 1 ms" in caplog.text


def test_connect_on_the_emulators_says_nothing_about_latency(tmp_path, monkeypatch, caplog):
    with GripperRig() as rig, caplog.at_level(logging.DEBUG, logger=latency_timer.__name__):
        rig.hand_move(spec.HOME_POSE)
        _connect(rig, tmp_path / "calibration", monkeypatch).disconnect()
    assert not [r for r in caplog.records if r.name == latency_timer.__name__]


def test_no_calibration_and_no_operator_is_refused_before_a_byte_is_sent(tmp_path, monkeypatch):
    from lerobot_blindgrasp.robots.blindgrasp_gripper import BlindgraspGripper

    calibration_dir = tmp_path / "calibration"
    calibration_dir.mkdir()
    (calibration_dir / "lab_gripper.json").write_text("{}")  # another id's file: the usual cause
    monkeypatch.setattr("sys.stdin", io.StringIO(""))  # a pipe or /dev/null, as under nohup or a scheduler
    with GripperRig() as rig:
        robot = BlindgraspGripper(dataclasses.replace(rig.robot_config(calibration_dir), id="eval_gripper"))
        with pytest.raises(CalibrationFileError) as err:
            robot.connect()
        assert not rig.dxl.instruction_counts and not robot.is_connected
    message = str(err.value)
    assert "'eval_gripper'" in message and str(calibration_dir / "eval_gripper.json") in message
    assert "lab_gripper" in message and "--robot.id" in message and "lerobot-calibrate" in message


def test_force_calibrations_in_the_folder_are_not_offered_as_robot_ids(tmp_path):
    from lerobot_blindgrasp.robots.blindgrasp_gripper.servo_calibration import calibrated_ids

    for name in ("lab_gripper.json", "lab_gripper.force.json", "spare.force.json", "old_gripper.json"):
        (tmp_path / name).write_text("{}")
    assert calibrated_ids(tmp_path) == ["lab_gripper", "old_gripper"]


def test_the_bringup_geometry_table_is_the_sims():
    from lerobot_blindgrasp.sim import gripper, objects

    text = (ROOT / "docs" / "bringup.md").read_text()
    rows = re.findall(r"^\| [^|]+ \| ([\d.]+) mm \| `(\w+)` \|$", text, flags=re.M)
    assert {name for _, name in rows} >= {"PLATE_HEIGHT", "BASE_RADIUS", "LINK_J10_J11", "LINK_J11_J12",
                                          "LINK_J12_TIPSITE", "TIP_CAPSULE_RADIUS"}  # fmt: skip
    for value, name in rows:
        assert float(value) == pytest.approx(1000 * getattr(gripper, name)), name
    [tip] = re.findall(r"^\| straight finger: tip end above the table \| ([\d.]+) mm \|", text, flags=re.M)
    reach = gripper.TIP_CAPSULE_END + gripper.TIP_CAPSULE_RADIUS
    straight = gripper.PLATE_HEIGHT - gripper.PLATE_TO_J10 - gripper.LINK_J10_J11 - gripper.LINK_J11_J12 - reach
    assert float(tip) == pytest.approx(1000 * straight)
    for geometry, dims in objects.TABLE_I_CM.items():
        label = geometry.replace("_a", " A").replace("_b", " B")
        [row] = re.findall(rf"^\| {label} [^|]*\|([^|]+)\|([^|]+)\|([^|]+)\|", text, flags=re.M)
        for k, cell in enumerate(row):
            numbers = [float(x) for x in re.findall(r"[\d.]+", cell)]
            assert numbers == [v[k] for v in dims.values()], (geometry, cell)


def test_the_power_sizing_is_nine_stall_currents():
    from lerobot_blindgrasp.hardware import xm430

    text = (ROOT / "docs" / "bringup.md").read_text()
    total = 9 * xm430.STALL_CURRENT_A
    assert f"9 x {xm430.STALL_CURRENT_A} A = {total:.1f} A ({total * xm430.RECOMMENDED_VOLTAGE_V:.0f} W)" in text


def test_real_report_answers_a_bare_path_and_takes_the_run_folder(tmp_path, capsys):
    from lerobot_blindgrasp.envs import real_report

    recorded = ROOT / "tests" / "data" / "real_eval_info.json"
    with pytest.raises(SystemExit, match=re.escape(f"real_report --eval_info={recorded}")):
        real_report.main([str(recorded)])  # the form the docs used to show
    run = tmp_path / "run"
    run.mkdir()
    (run / "eval_info.json").write_text(recorded.read_text())
    real_report.main([f"--eval_info={run}"])
    table = capsys.readouterr().out
    assert "| cylinder_a_medium | 2 | 0 | 0.0 % | 0-66 % |" in table and "| **overall** | 4 |" in table
    (run / "eval_info.json").write_text('{"overall": {}}')
    with pytest.raises(SystemExit, match="no per_task list"):
        real_report.main([f"--eval_info={run}"])


def test_a_force_port_that_is_not_there_says_how_to_find_it(tmp_path):
    from lerobot_blindgrasp.hardware.force_board.config_force_board import ForceSensorConfig
    from lerobot_blindgrasp.hardware.force_board.reader import ForceSensorReader, ForceStreamError

    assert ForceSensorConfig().port.startswith("/dev/ttyUSB")  # what a Nano's FT232RL or CH340 appears as
    reader = ForceSensorReader(str(tmp_path / "ttyUSB1"), 115_200, [2.5e-5] * 3)
    with pytest.raises(ForceStreamError, match=r"ttyUSB1'.*lerobot-find-port.*99-blindgrasp\.rules"):
        reader.connect()
    assert not reader.is_connected


def test_lerobot_setup_motors_from_factory_servos_one_at_a_time(tmp_path):
    """README's `lerobot-setup-motors` (the real CLI, the real dynamixel-sdk) on nine servos out of the box: each
    at ID 1 and 57 600 bps, plugged onto the cable alone when the CLI asks for it. Afterwards all nine share the
    cable at their own IDs and the config's baud rate, and `lerobot-calibrate`'s bus finds them."""
    from dynamixel_sdk import COMM_SUCCESS, PacketHandler, PortHandler

    from lerobot_blindgrasp.emulators.control_table import BAUD_REGISTER

    config = ROOT / "robot_configs" / "blindgrasp_gripper.yaml"
    joints = spec.JOINT_NAMES
    with FaultyBus([], baudrate=57_600) as emu:
        cmd = [str(BIN / "lerobot-setup-motors"), f"--robot=include {config}", "--robot.id=new",
               f"--robot.port={emu.port}", f"--robot.calibration_dir={tmp_path / 'calibration'}",
               f"--robot.latency_timer_ms={LATENCY_TIMER_MS}"]  # fmt: skip
        op = Operator(cmd, cli_env(tmp_path))
        fresh = []
        for joint, dxl_id in reversed(list(zip(joints, spec.SERVO_IDS, strict=True))):
            op.expect(f"Connect the controller board to the '{joint}' servo (ID {dxl_id}) only")
            fresh.append(FaultyBus.factory_servo())
            emu.plug(fresh[-1])  # the previous servo unplugged, this one out of its box
            op.answer()
            op.expect(f"'{joint}' servo: ID {dxl_id} at 1000000 bps")
        assert op.wait() == 0, op.text[-3000:]
        assert [s.get("ID") for s in fresh] == list(reversed(spec.SERVO_IDS))
        assert {s.get("Baud_Rate") for s in fresh} == {BAUD_REGISTER[1_000_000]}
        emu.plug(*fresh)  # the finished gripper: all nine on one cable
        port, ph = PortHandler(emu.port), PacketHandler(2.0)
        assert port.openPort() and port.setBaudRate(1_000_000)
        try:
            found, result = ph.broadcastPing(port)
        finally:
            port.closePort()
    assert result == COMM_SUCCESS and sorted(found) == sorted(spec.SERVO_IDS)
