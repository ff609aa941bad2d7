"""The episode loop the scripts here share: one object's evaluation start states, any actor, success per episode."""
from lerobot_blindgrasp.analysis.student_diagnosis import Outcomes
from lerobot_blindgrasp.sim.env import BatchedGraspEnv, GraspEnvConfig
from lerobot_blindgrasp.sim.gym_env import start_seed
from lerobot_blindgrasp.sim.randomization import EVAL_DR


def successes(name: str, act_delta, dr=EVAL_DR, episodes: int = 20, seed: int = 1000) -> list[bool]:
    """Run `episodes` episodes of `name` (env k = evaluation index seed + k); act_delta(t, obs, env) -> delta."""
    env = BatchedGraspEnv(GraspEnvConfig(num_envs=episodes, objects=(name,), seed=start_seed(seed, name), dr=dr,
                                         autoreset=False))
    obs = env.reset()
    ends = Outcomes(episodes, env.max_episode_steps)
    for t in range(env.max_episode_steps):
        obs, _, term, trunc, info = env.step(act_delta(t, obs, env))
        if not ends.update(t, info, term, trunc):
            break
    env.close()
    return ends.success.tolist()


def every_object(which: str, act, out: str, dr=EVAL_DR) -> dict[str, list[bool]]:
    """`successes` for each object of `which` (act(obs) -> delta), printed as it goes and written to `out` (json)."""
    import json
    from pathlib import Path

    from lerobot_blindgrasp.sim import objects

    res = {}
    for name in objects.resolve_objects(which):
        res[name] = successes(name, lambda t, obs, env: act(obs), dr=dr)
        print(name, sum(res[name]), flush=True)
    print("all", sum(map(sum, res.values())), "/", sum(map(len, res.values())))
    Path(out).write_text(json.dumps(res, separators=(",", ":")))
    return res
