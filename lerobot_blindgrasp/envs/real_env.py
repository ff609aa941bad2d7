"""`--env.type=blindgrasp_real`: the paper's real-gripper protocol (success per object over 10 trials) as a
lerobot-eval env, one task group per object; lerobot-rollout has no trials, resets or success. The trial itself is
`real_trial.py`.

    lerobot-eval --policy.path=<checkpoint> --env.type=blindgrasp_real \\
        --env.robot="include robot_configs/blindgrasp_gripper.yaml" \\
        --env.task=medium --eval.n_episodes=10 --eval.batch_size=1 --eval.use_async_envs=false
"""

from __future__ import annotations

import functools
import logging
from dataclasses import dataclass, field

import gymnasium as gym
from lerobot.configs import PolicyFeature
from lerobot.envs.configs import EnvConfig
from lerobot.robots.config import RobotConfig

from lerobot_blindgrasp import policy_contract, spaces, spec
from lerobot_blindgrasp.robots.blindgrasp_gripper import BlindgraspGripperConfig
from lerobot_blindgrasp.sim import objects

logger = logging.getLogger(__name__)


def resolve_real_objects(task: str) -> tuple[str, ...]:
    """ "medium" -> the six ID objects (3D-printed medium replicas); otherwise a comma list of any names, since real
    OOD objects (wine glass, foam brick, ...) have no sim model."""
    if task in ("medium", "all"):
        return objects.MEDIUM_OBJECTS if task == "medium" else objects.PAPER_OBJECTS
    names = tuple(n.strip() for n in task.split(",") if n.strip())
    if not names:
        raise ValueError("--env.task needs at least one object name")
    return names


@EnvConfig.register_subclass("blindgrasp_real")
@dataclass
class BlindGraspRealEnvConfig(EnvConfig):
    # "medium" (the 6 in-distribution objects), "all", or a comma list of object names (real OOD objects welcome).
    task: str | None = "medium"
    fps: int = spec.CONTROL_HZ
    robot: RobotConfig = field(default_factory=BlindgraspGripperConfig)
    episode_s: float = spec.EPISODE_S
    success_mode: str = "operator"  # "operator" | "force"
    # Force criterion (success_mode=force): min_contacts tips (default: all) above hold_force_n.
    hold_force_n: float = 0.5
    min_contacts: int = spec.NUM_FORCES
    # Reset: start-pose tolerance (rad), time limit to reach it, and the wait without a keyboard (force mode).
    home_tolerance_rad: float = 0.05
    home_timeout_s: float = 5.0
    unattended_reset_s: float = 5.0
    tare_each_trial: bool = True
    # Where each trial starts: "home", the paper's (0, pi/3, 0) on every finger; or "sim", the sim env's start pose
    # for the same evaluation index and object, so that a run beside `--env.type=blindgrasp` starts like for like.
    start_pose: str = "home"
    # Python's garbage collector off during each trial's 200 steps and run once after it (`hardware/realtime.py`).
    pause_gc: bool = True
    # Optional JSON-lines log of every trial (object, index, success, who decided, peak forces).
    trial_log: str | None = None
    # An unattended operator's Unix socket (e.g. blindgrasp-twin's): it places the objects and presses the keys.
    operator_socket: str | None = None
    features: dict[str, PolicyFeature] = field(default_factory=spaces.env_features)
    features_map: dict[str, str] = field(default_factory=spaces.env_features_map)

    def __post_init__(self):
        self.objects = resolve_real_objects(self.task or "medium")
        if self.start_pose not in ("home", "sim"):
            raise ValueError("start_pose must be 'home' or 'sim'")
        if self.success_mode not in ("operator", "force"):
            raise ValueError("success_mode must be 'operator' or 'force'")
        if self.fps != spec.CONTROL_HZ:
            raise ValueError(f"The policy runs at {spec.CONTROL_HZ} Hz (spec.CONTROL_HZ); got fps={self.fps}")

    @property
    def gym_kwargs(self) -> dict:
        return {}

    def check_policy(self) -> None:
        """The checkpoint's own files against the robot (`policy_contract.py`) before lerobot-eval loads it (its
        make_policy would overwrite the output features with ours) or anything moves; the robot checks again."""
        command_line = getattr(self.robot, "command_line", None)
        allow = getattr(self.robot, "allow_unverified_policy", False)
        path = command_line.policy_path if command_line is not None else None
        policy_contract.check_named(path, self.robot.type, self.fps, "--env.fps", allow_unverified=allow)

    def create_envs(self, n_envs: int, use_async_envs: bool = False) -> dict[str, dict[int, gym.vector.VectorEnv]]:
        from lerobot_blindgrasp.envs.real_trial import GripperSession, RealGraspEnv

        self.check_policy()
        if n_envs != 1 or use_async_envs:
            logger.warning("One physical gripper: evaluating with one synchronous env (asked n_envs=%s).", n_envs)
        session = GripperSession(self)
        out = {}
        for name in self.objects:
            env_fn = functools.partial(RealGraspEnv, session, name)
            out[name] = {0: gym.vector.SyncVectorEnv([env_fn], autoreset_mode=gym.vector.AutoresetMode.NEXT_STEP)}
        return out
