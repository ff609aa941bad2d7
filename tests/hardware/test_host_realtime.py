"""The host's loop mitigations (`hardware/realtime.py`): a real-time priority, locked memory and no garbage
collection inside a trial. Each setter is run for real, in its own process where it changes the process (the
scheduling class, mlockall); the refusals are real ones, made by the kernel under a dropped capability and a zero
limit (`setpriv`, `prlimit`). Nothing here measures time: the benchmark (lab/bench/loop_under_load.py) does."""

from __future__ import annotations

import dataclasses
import gc
import os
import shutil
import subprocess
import sys
import weakref
from pathlib import Path

import pytest

from lerobot_blindgrasp.hardware import realtime

# The module alone, by its path (standard library only): the package would import LeRobot and torch.
LOAD = f"""
import importlib.util
spec = importlib.util.spec_from_file_location("realtime", {str(Path(realtime.__file__))!r})
rt = importlib.util.module_from_spec(spec)
spec.loader.exec_module(rt)
"""


def run_python(code: str, *prefix: str) -> subprocess.CompletedProcess:
    return subprocess.run([*prefix, sys.executable, "-c", LOAD + code], capture_output=True, text=True, timeout=60)


def without(cap: str, **limit: str) -> list[str]:
    """A prefix that runs a command without `cap` (dropped from the bounding set, so root loses it at exec too) and
    with the given resource limits."""
    if not (shutil.which("setpriv") and shutil.which("prlimit")):
        pytest.skip("needs util-linux's setpriv and prlimit")
    limits = [f"--{k}={v}" for k, v in limit.items()]
    return ["setpriv", f"--bounding-set=-{cap}", f"--inh-caps=-{cap}", "prlimit", *limits]


SET_PRIORITY = """
import logging, os, threading
logging.basicConfig(level=logging.WARNING, format="%(message)s")
print("GOT", rt.set_realtime_priority(7))
seen = []
t = threading.Thread(target=lambda: seen.append(os.sched_getscheduler(0)))
t.start(); t.join()
print("MAIN", os.sched_getscheduler(0) == os.SCHED_FIFO, "THREAD", seen[0] == os.SCHED_FIFO)
"""


def test_a_refused_realtime_priority_says_how_to_allow_it_and_the_loop_goes_on():
    res = run_python(SET_PRIORITY, *without("sys_nice", rtprio="0"))
    assert res.returncode == 0, res.stderr
    assert "GOT not permitted (RLIMIT_RTPRIO 0)" in res.stdout
    assert "MAIN False THREAD False" in res.stdout
    assert "RLIMIT_RTPRIO is 0" in res.stderr and "ulimit -r 7" in res.stderr and "CAP_SYS_NICE" in res.stderr


def test_a_permitted_realtime_priority_holds_for_the_thread_and_the_threads_it_starts():
    res = run_python(SET_PRIORITY)
    assert res.returncode == 0, res.stderr
    if "not permitted" in res.stdout:
        pytest.skip(f"this machine refuses SCHED_FIFO even within RLIMIT_RTPRIO: {res.stdout.strip()}")
    assert "GOT SCHED_FIFO 7" in res.stdout and "MAIN True THREAD True" in res.stdout


def test_a_priority_outside_sched_fifo_range_is_refused_before_anything_changes():
    with pytest.raises(ValueError, match="realtime_priority"):
        realtime.set_realtime_priority(os.sched_get_priority_max(os.SCHED_FIFO) + 1)
    assert realtime.set_realtime_priority(0) == "off"
    assert os.sched_getscheduler(0) == os.SCHED_OTHER


LOCK = """
import logging
logging.basicConfig(level=logging.WARNING, format="%(message)s")
print("GOT", rt.lock_memory())
print("VmLck", [l.split()[1] for l in open("/proc/self/status") if l.startswith("VmLck")][0])
"""


def test_locked_memory_over_the_limit_says_how_to_allow_it():
    res = run_python(LOCK, *without("ipc_lock", memlock="65536"))  # 64 KiB: far below a Python process
    assert res.returncode == 0, res.stderr
    assert "GOT not locked (" in res.stdout and "RLIMIT_MEMLOCK 64 KiB" in res.stdout and "VmLck 0" in res.stdout
    assert "memlock unlimited" in res.stderr and "CAP_IPC_LOCK" in res.stderr


def test_locked_memory_within_the_limit_is_locked():
    res = run_python(LOCK)
    assert res.returncode == 0, res.stderr
    if "not locked" in res.stdout:
        pytest.skip(f"this machine refuses mlockall: {res.stdout.strip()}")
    assert "GOT locked" in res.stdout
    assert int(res.stdout.split("VmLck")[1].split()[0]) > 0  # kB locked: the interpreter's pages


class Node:
    pass


def test_the_gc_pause_keeps_cycles_until_it_resumes_and_then_collects_them():
    pause = realtime.GcPause()
    assert gc.isenabled()
    try:
        pause.pause()
        pause.pause()  # a second pause changes nothing
        assert not gc.isenabled()
        frozen = gc.get_freeze_count()
        assert frozen > 0  # what existed: out of every later collection's way
        node = Node()
        node.me = node  # a cycle: only the collector frees it
        alive = weakref.ref(node)
        del node
        for _ in range(3 * gc.get_threshold()[0]):  # allocations that would have triggered a collection
            Node()
        assert alive() is not None
    finally:
        pause.resume()
    assert gc.isenabled() and not pause.paused
    assert alive() is None  # collected on resuming, by a young-generation pass
    assert gc.get_freeze_count() >= frozen  # the frozen stay frozen: no full pass over them after a trial
    pause.resume()  # a second resume changes nothing
    assert gc.isenabled()


def test_the_robot_config_checks_the_priority_range(tmp_path, rig):
    with pytest.raises(ValueError, match="realtime_priority"):
        dataclasses.replace(rig.robot_config(tmp_path / "calibration"), realtime_priority=100)


def test_connect_applies_the_robot_configs_priority_to_the_control_thread_and_its_force_reader(
    tmp_path,
    rig,
    monkeypatch,
):
    from lerobot_blindgrasp.robots.blindgrasp_gripper import BlindgraspGripper

    monkeypatch.setattr("builtins.input", rig.calibration_inputs())
    cfg = dataclasses.replace(rig.robot_config(tmp_path / "calibration"), realtime_priority=1)
    robot = BlindgraspGripper(cfg)
    try:
        robot.connect()
        got = robot.host_setup
        assert got["memory"] == "off"
        if got["scheduling"].startswith("not permitted"):
            pytest.skip(f"SCHED_FIFO refused here: {got}")
        assert got["scheduling"] == "SCHED_FIFO 1"
        assert os.sched_getscheduler(0) == os.SCHED_FIFO
        # The force reader's thread starts inside connect, after the setting: it inherits it.
        assert os.sched_getscheduler(robot.force._thread.native_id) == os.SCHED_FIFO
        robot.get_observation()
    finally:
        os.sched_setscheduler(0, os.SCHED_OTHER, os.sched_param(0))  # the test runner's own thread goes back
        if robot.is_connected:
            robot.disconnect()


@pytest.mark.parametrize("pause_gc", [True, False])
def test_a_trial_runs_without_garbage_collection_and_collects_after_it(tmp_path, rig, monkeypatch, pause_gc):
    import numpy as np

    from lerobot_blindgrasp import spec
    from lerobot_blindgrasp.envs.real_env import BlindGraspRealEnvConfig

    monkeypatch.setattr("builtins.input", rig.calibration_inputs())
    cfg = BlindGraspRealEnvConfig(robot=rig.robot_config(tmp_path / "calibration"), task="sphere_medium",
                                  success_mode="force", unattended_reset_s=0.05, episode_s=0.25, pause_gc=pause_gc)  # fmt: skip
    vec = cfg.create_envs(n_envs=1)["sphere_medium"][0]
    try:
        vec.reset(seed=0)
        during = [gc.isenabled()]
        for _ in range(10):
            *_, term, trunc, _ = vec.step(np.tile(spec.HOME_POSE, (1, 1)))
            if term[0] or trunc[0]:
                break
            during.append(gc.isenabled())
        assert trunc[0]  # 5 steps, no object: the trial ran out of time
        assert during == [not pause_gc] * 5
        assert gc.isenabled()  # the trial is over: collected, and the collector back on
    finally:
        vec.close()
    assert gc.isenabled()
