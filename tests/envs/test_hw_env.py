"""`--env.type=blindgrasp_real`: the paper's real-gripper protocol as a gym env, on the emulated gripper."""

from __future__ import annotations

import json
import threading

import gymnasium as gym
import numpy as np
import pytest
from emulators.harness import ScriptedKeyboard, trial_env

from lerobot_blindgrasp import spec
from lerobot_blindgrasp.envs.operator import OperatorKeys
from lerobot_blindgrasp.envs.real_env import BlindGraspRealEnvConfig
from lerobot_blindgrasp.envs.real_report import success_table

CLOSE = np.tile([0.0, -0.2, -0.3], 3)[None]  # squeezes past the emulated object's contact at J*1 = 0.2 rad


def test_force_mode_trials_through_the_vector_env(rig, calibrated, tmp_path):
    log = tmp_path / "trials.jsonl"
    cfg = BlindGraspRealEnvConfig(robot=calibrated, task="cylinder_a_medium,foam_brick", success_mode="force",
                                  unattended_reset_s=0.05, episode_s=2.0, trial_log=str(log))  # fmt: skip
    envs = cfg.create_envs(n_envs=4, use_async_envs=True)  # one gripper: always one synchronous env
    assert list(envs) == ["cylinder_a_medium", "foam_brick"]  # one task group per object
    vec = envs["cylinder_a_medium"][0]
    assert isinstance(vec, gym.vector.SyncVectorEnv) and vec.num_envs == 1
    assert vec.call("_max_episode_steps") == (40,)
    assert vec.call("task_description") == ("grasp and lift the medium cylinder a",)
    assert envs["foam_brick"][0].call("task")[0] == "grasp and lift the foam brick"

    obs, _ = vec.reset(seed=0)  # connects, drives to the start pose (0, pi/3, 0), tares
    assert obs["agent_pos"].shape == (1, spec.STATE_DIM) and obs["agent_pos"].dtype == np.float32
    np.testing.assert_allclose(obs["agent_pos"][0, :9], spec.HOME_POSE, atol=cfg.home_tolerance_rad)
    rig.place_object()
    for t in range(40):  # noqa: B007 (t is read after the loop)
        obs, reward, term, trunc, info = vec.step(CLOSE)
        if term[0] or trunc[0]:
            break
    assert term[0] and info["is_success"][0] and reward[0] == 1.0
    assert spec.SUCCESS_HOLD_STEPS <= t + 1 < 40  # held >= 1 s (20 steps) with all three tips loaded
    assert obs["agent_pos"][0, 9:].min() > cfg.hold_force_n

    rig.remove_object()  # no object: nothing to squeeze, the trial runs out of time and fails
    brick = envs["foam_brick"][0]
    brick.reset(seed=1)
    for _ in range(40):
        *_, term, trunc, info = brick.step(CLOSE)
        if term[0] or trunc[0]:
            break
    assert trunc[0] and not info["is_success"][0]
    for group in envs.values():
        group[0].close()
    assert not rig.dxl.any_torque()
    trials = [json.loads(line) for line in log.read_text().splitlines()]
    assert [(t["object"], t["success"], t["decided_by"]) for t in trials] == [
        ("cylinder_a_medium", True, "force criterion"),
        ("foam_brick", False, "force criterion"),
    ]


def test_operator_mode_decides_with_keys(rig, calibrated):
    keys = OperatorKeys(listener_factory=ScriptedKeyboard)
    env = trial_env(calibrated, "sphere_medium", keys, episode_s=0.5)
    press = keys.listener.press
    try:
        outcomes = []
        for decision in ("s", "f", "timeout-y"):
            press("enter")  # object placed
            env.reset()
            info = {}
            for t in range(env._max_episode_steps):
                if t == 3 and decision in ("s", "f"):
                    press(decision)
                if t == env._max_episode_steps - 1 and decision == "timeout-y":
                    threading.Timer(0.2, press, ["y"]).start()  # answers the question asked at the time limit
                _, _, term, trunc, info = env.step(CLOSE[0])
                if term or trunc:
                    break
            outcomes.append((t + 1, info["is_success"]))
        assert outcomes == [(4, True), (4, False), (10, True)]
    finally:
        env.close()
    assert not rig.dxl.any_torque()


def test_operator_mode_without_a_keyboard_is_refused(calibrated):
    env = trial_env(calibrated, "sphere_medium")  # no keyboard (headless), in the default operator mode
    with pytest.raises(RuntimeError, match="success_mode=force"):
        env.session.ensure_connected()


def test_per_object_success_table():
    info = {"per_task": [
        {"task_group": "cylinder_a_medium", "task_id": 0, "metrics": {"successes": [True] * 9 + [False]}},
        {"task_group": "wine_glass", "task_id": 0, "metrics": {"successes": [True] * 10}},
    ]}  # fmt: skip
    table = success_table(info).splitlines()
    assert table[0].endswith("| 95 % interval |")  # Wilson, as every recorded rate
    assert table[2] == "| cylinder_a_medium | 10 | 9 | 90.0 % | 60-98 % |"
    assert table[3] == "| wine_glass | 10 | 10 | 100.0 % | 72-100 % |"
    assert table[4] == "| **overall** | 20 | 19 | 95.0 % | 76-99 % |"


def test_config_rejects_a_different_control_rate():
    with pytest.raises(ValueError, match="20 Hz"):
        BlindGraspRealEnvConfig(fps=30)
