"""The one-file glove bridge (`manus_bridge.py`, issue 57 item 1) on the MANUS machine's Python: copied alone into an
empty folder and run under Python 3.10 (ROS 2 Humble's) as a subprocess, from both sources, into the real
teleoperator.

- SDK: a stand-in of the MANUS SDK's shared library (tests/data/glove_bridge/manus_sdk_standin.c: the header's
  signatures and struct layouts, the SDK's call-order rules), compiled here with `cc`, streams recorded hand data:
  the right glove, the left glove, and a user entry carrying the right glove's id.
- ROS 2: a stand-in rclpy (tests/data/glove_bridge/fake_ros2) plays `ManusGlove` messages, shaped as MANUS's
  publisher sends them, on the publisher's topics.

Each time the teleoperator (ManusGlove, with its UDP receiver) must see exactly the right glove's values and map
them to the gripper's joints; SIGTERM then stops the bridge through its clean-up path (callbacks unregistered
before the SDK's ShutDown; the ROS node destroyed and the context shut down). No wall-clock assertion: every wait
is a bounded poll for a condition.
"""

from __future__ import annotations

import ast
import json
import re
import shlex
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
from emulators.glove_sender import FIST, OPEN, free_udp_port

from lerobot_blindgrasp import spec
from lerobot_blindgrasp.teleoperators.manus_glove import ManusGlove, ManusGloveConfig, bridge, protocol
from lerobot_blindgrasp.teleoperators.manus_glove import manus_bridge as mb
from lerobot_blindgrasp.teleoperators.manus_glove import retarget as rt

DATA = Path(__file__).resolve().parents[1] / "data" / "glove_bridge"
BRIDGE = Path(mb.__file__)
RIGHT, LEFT = 0x1234, 0x5678  # glove ids
OTHER_HAND = {c.name: 77.0 for c in mb.CHANNELS}  # the left glove: never in a right-hand datagram
USER = {c.name: 66.0 for c in mb.CHANNELS}  # a user's entry (isUserID), same id as the right glove: skipped
OPEN_ROUNDS = 20  # rounds of the open hand before the fist


def _python310() -> str:
    found = sorted(Path.home().glob(".pyenv/versions/3.10*/bin/python3.10")) + [shutil.which("python3.10")]
    for p in found:
        if p:
            return str(p)
    pytest.skip("no Python 3.10 here (pyenv install 3.10): the bridge's tests run it on ROS 2 Humble's Python")


@pytest.fixture(scope="module")
def py310() -> str:
    return _python310()


@pytest.fixture
def lab(tmp_path) -> Path:
    """The MANUS machine: a folder holding only the copied file."""
    (tmp_path / "lab").mkdir()
    return Path(shutil.copy(BRIDGE, tmp_path / "lab" / "manus_bridge.py"))


@pytest.fixture
def teleop(tmp_path):
    (tmp_path / "op.json").write_text(json.dumps({"open": OPEN, "fist": FIST}))
    t = ManusGlove(ManusGloveConfig(id="op", port=free_udp_port(), calibration_dir=tmp_path, connect_timeout_s=20))
    yield t
    if t.is_connected:
        t.disconnect()


def _values(pose: dict[str, float], side: str) -> list[float]:
    """ErgonomicsData.data (40 floats by ErgonomicsDataType) of a glove of `side` in `pose`."""
    out = [0.0] * 40
    for c in mb.CHANNELS:
        out[c.enum_value(side)] = pose[c.name]
    return out


def _frames_header(path: Path) -> None:
    def entry(glove: int, user: bool, values: list[float]) -> str:
        return f"{{{glove}u, {int(user)}, {{{', '.join(f'{v!r}f' for v in values)}}}}}"

    streams = []
    for k in range(OPEN_ROUNDS + 1):
        pose = OPEN if k < OPEN_ROUNDS else FIST
        entries = [entry(RIGHT, False, _values(pose, "right")), entry(LEFT, False, _values(OTHER_HAND, "left")),
                   entry(RIGHT, True, _values(USER, "right"))]  # fmt: skip
        streams.append("{" + ", ".join(entries) + "}")
    path.write_text(
        f"#define N_STREAMS {len(streams)}\n#define ENTRIES 3\n"
        "static const struct { uint32_t id; bool user; float v[40]; } STREAMS[N_STREAMS][ENTRIES] = {\n"
        + ",\n".join(streams) + "};\n"
        f"#define N_GLOVES 2\nstatic const uint32_t GLOVES[N_GLOVES][2] = {{{{{RIGHT}u, 2}}, {{{LEFT}u, 1}}}};\n"
        '#define N_HOSTS 2\nstatic const char* const HOSTS[N_HOSTS][2] = {{"lab-core", "10.0.0.5"}, '
        '{"other", "10.0.0.6"}};\n'
    )  # fmt: skip


@pytest.fixture(scope="module")
def sdk_library(tmp_path_factory) -> Path:
    cc = shutil.which("cc")
    if cc is None:
        pytest.skip("no C compiler (cc): install the package gcc")
    out = tmp_path_factory.mktemp("sdk")
    _frames_header(out / "standin_frames.h")
    lib = out / "libManusSDK_Integrated.so"
    subprocess.run([cc, "-shared", "-fPIC", "-O1", "-Wall", "-Werror", "-I", str(out), "-o", str(lib),
                    str(DATA / "manus_sdk_standin.c"), "-lpthread"], check=True, timeout=120)  # fmt: skip
    return lib


def _start(py: str, lab: Path, args: list[str], env: dict[str, str], isolated: bool = True) -> subprocess.Popen:
    cmd = [py, *(["-I"] if isolated else []), str(lab), *args]
    return subprocess.Popen(
        cmd, cwd=lab.parent, env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True
    )


def _wait_for(condition, proc: subprocess.Popen, what: str) -> None:
    deadline = time.monotonic() + 30.0  # a bound for a loaded machine, not a timing claim
    while not condition():
        assert proc.poll() is None, proc.communicate()
        assert time.monotonic() < deadline, f"no {what}"
        time.sleep(0.02)


def _drive_and_stop(proc: subprocess.Popen, teleop: ManusGlove, also=lambda: True) -> str:
    """Connect the teleoperator to the running bridge, wait (bounded) for the fist and `also`, check the joints,
    SIGTERM the bridge."""
    try:
        teleop.connect()  # calibrated from the file; waits for the first datagram
        _wait_for(lambda: teleop.receiver.latest()[0].ergonomics["IndexMCPStretch"] == 85.0, proc, "fist")
        _wait_for(also, proc, "bridge state")
        frame, _ = teleop.receiver.latest()
        assert frame.ergonomics == {k: FIST[k] for k in rt.REQUIRED_KEYS}  # the right glove, none of 77 or 66
        assert teleop.receiver.rejected == 0 and teleop.receiver.restarts == 0
        q = np.array([teleop.get_action()[k] for k in spec.ACTION_NAMES])
        cfg = teleop.config
        flex = [1, 2, 4, 5, 7, 8]
        np.testing.assert_allclose(q[flex], np.array(cfg.closed_pose)[flex], atol=1e-9)
        # spread: relative to the open hand, gain 1 rad/rad (ff, mf: 2 -> -3 deg; th: 25 -> 15 deg)
        spread = np.array(cfg.open_pose)[[0, 3, 6]] + np.radians([-5.0, -5.0, -10.0]) * np.array(cfg.spread_gain)
        lo, hi = np.array(spec.JOINT_LOWER)[[0, 3, 6]], np.array(spec.JOINT_UPPER)[[0, 3, 6]]
        np.testing.assert_allclose(q[[0, 3, 6]], np.clip(spread, lo, hi), atol=1e-6)
    finally:
        proc.send_signal(signal.SIGTERM)
        _, err = proc.communicate(timeout=30)
    assert proc.returncode == 0, err
    return err


@pytest.mark.parametrize(("mode", "python"), [("integrated", "3.10"), ("core", "3.10"), ("integrated", "3.12")])
def test_the_sdk_bridge_drives_the_teleoperator(request, lab, sdk_library, teleop, tmp_path, mode, python):
    """Under Python 3.10 (ROS 2 Humble's) and this suite's own Python, 3.12 or later (Jazzy's is 3.12)."""
    log = tmp_path / "sdk_calls.log"
    args = ["--source=sdk", f"--sdk_mode={mode}", "--side=right", f"--port={teleop.config.port}", "--source_port=0",
            f"--sdk_library={sdk_library}", "--status_every_s=0.5"]  # fmt: skip
    if mode == "core":
        args.append("--sdk_host=10.0.0.6")  # the second host found, by its address
    py = request.getfixturevalue("py310") if python == "3.10" else sys.executable
    proc = _start(py, lab, args, {"STANDIN_LOG": str(log), "STANDIN_DISCONNECT_AT": "5"})
    err = _drive_and_stop(proc, teleop, also=lambda: log.read_text().count("CoreSdk_ConnectToHost") == 2)
    calls = log.read_text().splitlines()
    init = "CoreSdk_InitializeIntegrated" if mode == "integrated" else "CoreSdk_InitializeCore"
    order = [init, "CoreSdk_RegisterCallbackForErgonomicsStream", "CoreSdk_InitializeCoordinateSystemWithVUH",
             "CoreSdk_ConnectToHost", "CoreSdk_GetDataForGlove_UsingGloveId", "CoreSdk_ShutDown"]  # fmt: skip
    assert [calls.index(c) for c in order] == sorted(calls.index(c) for c in order), calls
    assert "  view=3 up=6 handedness=2 scale=1 world=1" in calls
    assert "  not in the landscape yet" in calls  # the glove's side was asked again, not guessed
    assert calls[calls.index("CoreSdk_ConnectToHost") + 1] == (
        "  host ''" if mode == "integrated" else "  host 'other'"
    )
    if mode == "core":
        assert calls.index("CoreSdk_LookForHosts") < calls.index("CoreSdk_GetAvailableHostsFound")
    else:
        assert calls[calls.index("CoreSdk_ConnectToHost") - 1] == "ManusHost_Init"
    assert calls[-1] == "  shut down with the ergonomics callback unregistered"
    # A disconnect in the stream (a dongle unplugged): the bridge connected again and went on.
    assert calls.count("CoreSdk_ConnectToHost") == 2 and "MANUS SDK disconnected: reconnecting." in err
    assert "is the right hand" in err and "is the left hand" in err and "Stopped." in err
    forwarded = [line for line in err.splitlines() if "right-hand poses" in line][-1]
    assert "skipped 0 of the other hand" not in forwarded  # the left glove was seen and skipped


def test_an_sdk_call_that_fails_is_named_with_its_code(py310, lab, sdk_library, tmp_path):
    log = tmp_path / "sdk_calls.log"
    env = {"STANDIN_LOG": str(log), "STANDIN_FAIL": "CoreSdk_InitializeCoordinateSystemWithVUH=16"}
    proc = _start(py310, lab, ["--source=sdk", f"--sdk_library={sdk_library}", "--source_port=0"], env)
    _, err = proc.communicate(timeout=60)
    assert proc.returncode == 2
    assert (
        "error: CoreSdk_InitializeCoordinateSystemWithVUH returned 16 (SDKReturnCode_NoCoordinateSystemSet)" in err
    )
    assert log.read_text().splitlines()[-1].startswith("  shut down")  # shut down all the same


def test_a_missing_sdk_library_says_how_to_name_it(py310, lab, tmp_path):
    proc = _start(py310, lab, ["--source=sdk", f"--sdk_library={tmp_path / 'nothing.so'}", "--source_port=0"], {})
    _, err = proc.communicate(timeout=60)
    assert proc.returncode == 2 and "cannot load the MANUS SDK library" in err and "--sdk_library=" in err


def _ros_rounds() -> list[list[dict]]:
    def msg(topic, glove_id, side, pose, spelling):
        return {"topic": topic, "glove_id": glove_id, "side": side,
                "ergonomics": [[spelling(c), pose[c.name]] for c in mb.CHANNELS]}  # fmt: skip

    rounds = []
    for k in range(OPEN_ROUNDS + 1):
        pose = OPEN if k < OPEN_ROUNDS else FIST
        rounds.append([
            msg("manus_glove_0", RIGHT, "Right", pose, lambda c: c.ros2),  # the publisher's strings
            msg("manus_glove_1", LEFT, "Left", OTHER_HAND, lambda c: c.ros2),
            msg("manus_glove_2", RIGHT + 1, "Right", USER, lambda c: c.name),  # a topic the bridge is not told of
        ])  # fmt: skip
    return rounds


@pytest.mark.parametrize("package", ["manus_ros2_msgs", "manus_ros2"])
def test_the_ros2_bridge_under_python310_drives_the_teleoperator(py310, lab, teleop, tmp_path, package):
    ros = shutil.copytree(DATA / "fake_ros2", tmp_path / "ros")
    if package != "manus_ros2_msgs":  # the other public spelling of MANUS's message package
        (ros / "manus_ros2_msgs").rename(ros / package)
    (tmp_path / "rounds.json").write_text(json.dumps(_ros_rounds()))
    log = tmp_path / "ros.log"
    env = {"PYTHONPATH": str(ros), "FAKE_ROS2_ROUNDS": str(tmp_path / "rounds.json"), "FAKE_ROS2_LOG": str(log)}
    args = ["--source=ros2", "--side=right", f"--port={teleop.config.port}", "--source_port=0",
            "--topics=manus_glove_0,manus_glove_1", "--status_every_s=0.5"]  # fmt: skip
    err = _drive_and_stop(_start(py310, lab, args, env, isolated=False), teleop)
    calls = log.read_text().splitlines()
    assert calls[:4] == ["init", "create_node blindgrasp_glove_bridge",
                         f"subscribe manus_glove_0 {package}.msg.ManusGlove depth=1",
                         f"subscribe manus_glove_1 {package}.msg.ManusGlove depth=1"]  # fmt: skip
    assert calls[-2:] == ["destroy_node", "shutdown"]
    assert "Stopped." in err and "skipped 0 of the other hand" not in err.splitlines()[-2]


def test_without_rclpy_the_ros2_source_says_what_to_source(py310, lab):
    proc = _start(py310, lab, ["--source=ros2", "--source_port=0"], {})
    _, err = proc.communicate(timeout=60)
    assert proc.returncode == 2 and "rclpy is not importable" in err and "--source=sdk" in err


def test_the_teleoperator_reads_the_bridges_own_names_and_datagram():
    """One source: the receiver's names table and datagram are the standalone bridge's objects, not copies."""
    assert protocol.encode is mb.encode and protocol.GloveSender is mb.GloveSender and protocol.PROTO is mb.PROTO
    assert protocol.SESSION_RE is mb.SESSION_RE
    assert mb.USED_CHANNELS == rt.REQUIRED_KEYS  # what the bridge warns about is what the retargeting reads
    assert bridge.BridgeConfig is mb.BridgeConfig


def test_the_bridge_imports_only_the_standard_library_and_ros2():
    tree = ast.parse(BRIDGE.read_text())
    imported = {a.name.split(".")[0] for n in ast.walk(tree) if isinstance(n, ast.Import) for a in n.names}
    imported |= {n.module.split(".")[0] for n in ast.walk(tree) if isinstance(n, ast.ImportFrom) and n.module}
    imported |= {"manus_ros2_msgs", "manus_ros2"} & set(BRIDGE.read_text().split('"'))  # __import__ by name
    assert imported - set(sys.stdlib_module_names) <= {"rclpy", "manus_ros2_msgs", "manus_ros2"}, imported
    assert not any(isinstance(n, ast.ImportFrom) and n.level for n in ast.walk(tree))  # runs as a lone file


def test_the_command_and_the_file_read_the_same_flags():
    """`blindgrasp-glove-bridge` (draccus) and `python3 manus_bridge.py` (argparse) build the same config."""
    from lerobot_blindgrasp.cli import parse_config

    for argv in (["--topics=[a,b]", "--side=left", "--port=5", "--status_every_s=0.5"],
                 ["--source=sdk", "--sdk_mode=core", "--sdk_host=10.0.0.6", "--glove_id=7", "--sdk_library=x.so"]):  # fmt: skip
        assert mb.parse_args(argv) == parse_config(mb.BridgeConfig, argv)
    assert mb.parse_args(["--topics=a,b"]).topics == ["a", "b"]
    with pytest.raises(SystemExit):
        mb.parse_args(["--source=serial"])


def _documented_bridge_lines() -> list[str]:
    """Every `python3 manus_bridge.py ...` line of README.md's and docs/glove.md's shell blocks."""
    root = BRIDGE.parents[3]
    out = []
    for doc in (root / "README.md", root / "docs" / "glove.md"):
        for block in re.findall(r"^\s*```(?:bash|sh)\n(.*?)^\s*```", doc.read_text(), flags=re.M | re.S):
            out += [
                line.strip() for line in block.splitlines() if line.strip().startswith("python3 manus_bridge.py")
            ]
    return out


def test_the_documented_bridge_commands_parse(capsys):
    """The docs' `python3 manus_bridge.py` lines (not read by test_docs_commands, which parses the package's own
    commands) reach a valid config with the flags as printed; `--help` prints the help."""
    lines = _documented_bridge_lines()
    assert {"--source=ros2", "--source=sdk", "--help"} <= {
        w for line in lines for w in shlex.split(line, comments=True)
    }
    for line in lines:
        argv = shlex.split(line, comments=True)[2:]
        argv = [re.sub(r"<([^>]+)>", lambda m: re.sub(r"\W+", "_", m.group(1)), a) for a in argv]
        if argv == ["--help"]:
            with pytest.raises(SystemExit) as e:
                mb.parse_args(argv)
            assert e.value.code == 0 and "--sdk_library" in capsys.readouterr().out
        else:
            assert isinstance(mb.parse_args(argv), mb.BridgeConfig), line
