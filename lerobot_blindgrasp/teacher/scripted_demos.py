"""The collection of the scripted side-grasp demonstrations that `teacher.aux_bc.PPOWithScriptedDemos` clones; their
settings are `presets.teacher_configs.ScriptedDemos`."""

from __future__ import annotations

import numpy as np

from lerobot_blindgrasp import spec
from lerobot_blindgrasp.presets.teacher_configs import ScriptedDemos
from lerobot_blindgrasp.sim import objects, randomization


def collect_scripted_demos(cfg: ScriptedDemos) -> dict:
    """Roll the side-grasp script out once per env from training start states; keep the successful episodes:
    {"obs": {"privileged": (M, 92), "policy": (M, 12)}, "actions": (M, 9), "success": {object: rate}}, float32."""
    # MuJoCo only when demos are collected, not when a preset names them
    from lerobot_blindgrasp.rollout.envs import make_batched_env
    from lerobot_blindgrasp.sim import scripted

    n = cfg.episodes_per_object * len(cfg.objects)
    dr = randomization.PAPER_DR if cfg.pushes else randomization.EVAL_DR  # as train.build_env_config chooses
    env = make_batched_env("scripts", cfg.objects, num_envs=n, seed=cfg.seed, dr=dr, nthread=1)
    obs = env.reset()
    script = scripted.SideGraspScript(
        env.joint_positions(), env.object_position(), [objects.get_object(name) for name in env.object_names]
    )
    seen_obs, seen_policy, seen_act = [], [], []
    success = np.zeros(n, dtype=bool)
    for t in range(env.max_episode_steps):
        action = script(env.joint_positions())
        if t < cfg.steps_per_episode:
            seen_obs.append(obs["privileged"].astype(np.float32))
            seen_policy.append(obs["policy"].astype(np.float32))
            seen_act.append(action.astype(np.float32))
        obs, _, terminated, _, info = env.step(action)
        success = (success | info["success"]) & ~terminated  # an object that left the workspace: no demonstration
    env.close()
    names = np.array(env.object_names)
    rates = {name: float(success[names == name].mean()) for name in cfg.objects}
    keep = np.flatnonzero(success)
    o = np.stack(seen_obs, axis=1)[keep].reshape(-1, spec.PRIVILEGED_DIM)
    p = np.stack(seen_policy, axis=1)[keep].reshape(-1, spec.STATE_DIM)
    a = np.stack(seen_act, axis=1)[keep].reshape(-1, spec.NUM_JOINTS)
    return {"obs": {"privileged": o, "policy": p}, "actions": a, "success": rates}
