"""One real-gripper trial (= one lerobot-eval episode) as a gym env (`RealGraspEnv`), on the one gripper its
`GripperSession` holds: reset to the start pose, the operator's ENTER (unattended: a wait) and a tare, torque on
and the bus watchdog fed all along; then 200 steps at 20 Hz paced by a `StepPacer`; success (lifted and held for
1 s) decided by the operator's keys (the paper's protocol) or, unattended, by `min_contacts` tips above
`hold_force_n` for `spec.SUCCESS_HOLD_S` (a proxy that sees a sustained grasp, not the lift).
"""

from __future__ import annotations

import json
import logging
import time

import gymnasium as gym
import numpy as np

from lerobot_blindgrasp import durable, spaces, spec
from lerobot_blindgrasp.envs import real_report
from lerobot_blindgrasp.envs.operator import FAILURE_KEYS, SUCCESS_KEYS, OperatorKeys, SocketOperator
from lerobot_blindgrasp.hardware.loop_timing import StepPacer
from lerobot_blindgrasp.hardware.realtime import GcPause
from lerobot_blindgrasp.robots.blindgrasp_gripper.errors import GripperStallError
from lerobot_blindgrasp.sim import objects, randomization
from lerobot_blindgrasp.sim.gym_env import start_seed

logger = logging.getLogger(__name__)


def sim_start_pose(object_name: str, eval_index: int) -> np.ndarray:
    """The joints where `--env.type=blindgrasp` starts evaluation index `eval_index` on `object_name`, clipped."""
    if object_name not in objects.CATALOGUE:
        raise ValueError(f"start_pose=sim needs an object of the sim's catalogue; {object_name!r} is not one")
    seeds = np.array([start_seed(eval_index, object_name)], dtype=np.uint64)
    q0, _ = randomization.draw_reset(randomization.EVAL_DR, seeds, np.zeros(1, dtype=np.int64))
    return np.clip(q0[0].numpy(), spec.JOINT_LOWER, spec.JOINT_UPPER)


def task_string(name: str) -> str:
    if name in objects.CATALOGUE:
        return objects.CATALOGUE[name].task
    return f"grasp and lift the {name.replace('_', ' ')}"


class GripperSession:
    """The one robot (one serial bus) shared by the per-object envs: connected at the first reset, disconnected
    once at the end (or on any error, by the robot's own latched stop)."""

    def __init__(self, cfg, keys: OperatorKeys | None = None):
        """`cfg`: the `--env.*` config (`BlindGraspRealEnvConfig`, which documents the trial's settings)."""
        from lerobot.robots.utils import make_robot_from_config

        self.cfg = cfg
        self.robot = make_robot_from_config(cfg.robot)
        if set(self.robot.observation_features) != set(spec.STATE_NAMES):
            raise ValueError(f"Robot type {cfg.robot.type} lacks the spec observation {spec.STATE_NAMES}")
        self.keys = keys
        self.trials: dict[str, int] = {}

    def ensure_connected(self) -> None:
        if self.keys is None:
            sock = self.cfg.operator_socket  # None: a person at the keyboard; else an operator program
            self.keys = OperatorKeys() if sock is None else SocketOperator(sock)
        if self.cfg.success_mode == "operator" and not self.keys.available:
            raise RuntimeError(
                "success_mode=operator needs keyboard input (a display for pynput, or run lerobot-eval in a "
                "terminal); use --env.success_mode=force for unattended runs."
            )
        if not self.robot.is_connected:
            self.robot.connect()

    def close(self) -> None:
        if self.robot.is_connected:
            self.robot.disconnect()
        if self.keys is not None:
            self.keys.stop()
            # lerobot-eval writes eval_info.json after this: it names who judged the trials (envs/real_report.py).
            judge = self.keys.judge if self.cfg.success_mode == "operator" else "force criterion"
            real_report.stamp_judge_at_exit(judge)


class RealGraspEnv(gym.Env):
    metadata = {"render_modes": ["rgb_array"], "render_fps": spec.CONTROL_HZ}

    def __init__(self, session: GripperSession, object_name: str):
        self.session, self.robot = session, session.robot  # the one gripper, shared by the per-object envs
        self.cfg = session.cfg
        self.object_name = object_name
        self.task = self.task_description = task_string(object_name)
        self.render_mode = "rgb_array"
        self.observation_space = spaces.observation_space()
        self.action_space = spaces.action_space()
        self._max_episode_steps = int(round(self.cfg.episode_s * spec.CONTROL_HZ))
        self._obs = np.zeros(spec.STATE_DIM, dtype=np.float32)
        self._gc = GcPause()
        self._reset_trial_state()

    def _reset_trial_state(self) -> None:
        self._t = 0
        self._held = 0
        self._decided: tuple[bool, str] | None = None
        self._peak = np.zeros(spec.NUM_FORCES)
        self._schedule = StepPacer(spec.CONTROL_DT)
        self._overruns_at_start = self._overruns()
        # Where each period goes, logged per trial; "policy" is the caller's time between a step and the next.
        self._step_s: dict[str, list[float]] = {"read": [], "policy": [], "write": []}
        self._returned_at: float | None = None
        self._stopped: str | None = None  # the stall stop's message, when one ended the trial

    def _overruns(self) -> int:
        timing = getattr(self.robot, "timing", None)
        return timing.overruns if timing is not None else 0

    def _observe(self) -> dict[str, np.ndarray]:
        started = time.monotonic()
        obs = self.robot.get_observation()
        self._schedule.sampled(started, time.monotonic())
        self._obs = np.array([obs[k] for k in spec.STATE_NAMES], dtype=np.float32)
        return spaces.observation(self._obs)

    def _go_home(self, pose: np.ndarray) -> None:
        home = dict(zip(spec.ACTION_NAMES, pose.tolist(), strict=True))
        deadline = time.monotonic() + self.cfg.home_timeout_s
        while True:
            self._observe()
            err = np.abs(self._obs[spec.STATE_JOINT_SLICE] - pose).max()
            if err <= self.cfg.home_tolerance_rad:
                return
            if time.monotonic() > deadline:
                raise RuntimeError(
                    f"The gripper did not reach the start pose within {self.cfg.home_timeout_s} s "
                    f"(worst joint error {err:.3f} rad): check for an obstruction."
                )
            self.robot.send_action(home)
            time.sleep(spec.CONTROL_DT)

    def reset(self, *, seed: int | None = None, options: dict | None = None):
        super().reset(seed=seed)
        self.session.ensure_connected()
        self._reset_trial_state()
        keys = self.session.keys
        k = self.session.trials.get(self.object_name, 0) + 1
        self._seed = seed  # lerobot-eval's evaluation index: the start state an unattended operator places
        index = k - 1 if seed is None else int(seed)
        self._go_home(sim_start_pose(self.object_name, index) if self.cfg.start_pose == "sim" else spec.HOME_POSE)
        self.session.trials[self.object_name] = k
        if hasattr(keys, "announce_trial"):  # an unattended operator places the object this trial names
            keys.announce_trial(self.object_name, index)
        if keys.available:  # an ENTER pressed while the gripper was homing counts: the operator is ready
            print(f"\n[{self.object_name}] trial {k}: place the object at the claw centre, hands clear, ENTER.")
            self._wait_keeping_bus_alive({"enter"})
        else:
            logger.info("[%s] trial %d starts in %.1f s", self.object_name, k, self.cfg.unattended_reset_s)
            self._wait_keeping_bus_alive(None, self.cfg.unattended_reset_s)
        if self.cfg.tare_each_trial and hasattr(self.robot, "tare_forces"):
            self.robot.tare_forces()
        if hasattr(self.robot, "check_health_before_start"):  # a servo near a limit must not start a trial
            self.robot.check_health_before_start()
        if self.cfg.success_mode == "operator":
            print("Running (10 s): press 's' once the object is held off the table for 1 s, 'f' to abort.")
        self._overruns_at_start = self._overruns()
        if self.cfg.pause_gc:
            self._gc.pause()
        self._schedule.start()  # from the observation's start, as every later period: the first one is 50 ms too
        obs = self._observe()
        self._returned_at = time.perf_counter()
        return obs, {"is_success": False}

    def _wait_keeping_bus_alive(self, keys: set[str] | None, duration_s: float = 0.0) -> str | None:
        """Wait for one of `keys` (None: for `duration_s`) holding the pose, with `keep_alive` every period: the
        bus watchdog stays armed for a dead host instead of tripping on a person's pause."""
        keep_alive = getattr(self.robot, "keep_alive", None)
        deadline = time.monotonic() + duration_s
        while True:
            if keys is not None:
                if (key := self.session.keys.wait_for(keys, timeout_s=spec.CONTROL_DT)) is not None:
                    return key
            elif (left := deadline - time.monotonic()) > 0:
                time.sleep(min(left, spec.CONTROL_DT))
            else:
                return None
            if keep_alive is not None:
                keep_alive()

    def step(self, action):
        action = np.asarray(action, dtype=np.float64).reshape(spec.ACTION_DIM)
        t_in = time.perf_counter()
        if self._returned_at is not None:
            self._step_s["policy"].append(t_in - self._returned_at)
        try:
            self.robot.send_action(dict(zip(spec.ACTION_NAMES, action.tolist(), strict=True)))
            self._step_s["write"].append(time.perf_counter() - t_in)
            self._schedule.wait()
            t_read = time.perf_counter()
            obs = self._observe()
        except GripperStallError as e:
            return self._end_on_stall(e)
        self._step_s["read"].append(time.perf_counter() - t_read)
        self._t += 1
        forces = self._obs[spec.STATE_FORCE_SLICE]
        self._peak = np.maximum(self._peak, forces)
        if self._decided is None:
            self._judge(forces)
        truncated = self._t >= self._max_episode_steps and self._decided is None
        if truncated and self.cfg.success_mode == "operator":
            self._decided = (self._ask_outcome(), self.session.keys.judge)
            truncated = False
        elif truncated:
            self._decided = (False, "force criterion")
        terminated = self._decided is not None and not truncated
        success = bool(self._decided and self._decided[0])
        if terminated or truncated:
            self._finish_trial(success)
        self._returned_at = time.perf_counter()
        return obs, float(success), terminated, truncated, {"is_success": success}

    def _finish_trial(self, success: bool) -> None:
        self._log_trial(success)
        self._gc.resume()  # between trials, where a collection may take its time
        self.session.keys.clear()  # keys pressed during this trial must not decide the next one

    def _end_on_stall(self, e: GripperStallError):
        """The stall stop ends this trial as a failure instead of the whole evaluation: a finger squeezed at its
        current limit for seconds (a missed grasp runs its full 10 s), the torque is off, and the servos are within
        their limits. The next trial reconnects through every check of a first connect. A stop whose torque-off
        was not confirmed still ends the session."""
        if not getattr(e, "torque_off_confirmed", False):
            raise e
        logger.warning("[%s] trial %d ended by the stall stop: %s", self.object_name,
                       self.session.trials[self.object_name], e)  # fmt: skip
        self._decided, self._stopped = (False, "stall stop"), str(e)
        self._finish_trial(False)
        return spaces.observation(self._obs), 0.0, True, False, {"is_success": False}

    def _judge(self, forces: np.ndarray) -> None:
        if self.cfg.success_mode == "operator":
            while (key := self.session.keys.poll()) is not None:
                if key in SUCCESS_KEYS | FAILURE_KEYS:
                    self._decided = (key in SUCCESS_KEYS, self.session.keys.judge)
                    return
            return
        contacts = int((forces > self.cfg.hold_force_n).sum())
        self._held = self._held + 1 if contacts >= self.cfg.min_contacts else 0
        if self._held >= spec.SUCCESS_HOLD_STEPS:
            self._decided = (True, "force criterion")

    def _ask_outcome(self) -> bool:
        # Hold the final pose while the operator answers: the last target stays on the servos.
        print("10 s elapsed. Was the object lifted and held for >= 1 s? press y or n.")
        return self._wait_keeping_bus_alive(SUCCESS_KEYS | FAILURE_KEYS) in SUCCESS_KEYS

    def _log_trial(self, success: bool) -> None:
        who = self._decided[1] if self._decided else "time limit"
        trial, outcome = self.session.trials[self.object_name], "SUCCESS" if success else "failure"
        logger.info("[%s] trial %d: %s (%s, %d steps)", self.object_name, trial, outcome, who, self._t)
        if self.cfg.trial_log:
            record = {
                "object": self.object_name,
                "trial": trial,
                "seed": getattr(self, "_seed", None),
                "success": success,
                "decided_by": who,
                "steps": self._t,
                "peak_force_n": [round(float(f), 3) for f in self._peak],
                "loop_overruns": self._overruns() - self._overruns_at_start,
                "late_steps_rebased": self._schedule.rebased,
                "stopped": self._stopped,
                "step_ms": {
                    k: [round(1e3 * float(np.percentile(v, p)), 2) for p in (50, 99, 100)] if v else []
                    for k, v in self._step_s.items()
                },  # p50, p99, max
            }
            durable.atomic_append_text(self.cfg.trial_log, json.dumps(record) + "\n")  # a kill leaves no half line

    def render(self) -> np.ndarray:
        """A 64 x 96 strip chart of the state (no camera on a blind gripper): 9 joint bars, 3 force bars."""
        img = np.full((64, 96, 3), 255, dtype=np.uint8)
        q = (self._obs[spec.STATE_JOINT_SLICE] - spec.JOINT_LOWER) / (spec.JOINT_UPPER - spec.JOINT_LOWER)
        f = np.clip(self._obs[spec.STATE_FORCE_SLICE] / 10.0, 0.0, 1.0)
        for i, v in enumerate(np.concatenate([q, f])):
            h = int(np.clip(v, 0.0, 1.0) * 60)
            color = (40, 90, 200) if i < spec.NUM_JOINTS else (220, 60, 40)
            img[62 - h : 62, 2 + 8 * i : 8 + 8 * i] = color
        return img

    def close(self) -> None:
        self._gc.resume()
        self.session.close()
