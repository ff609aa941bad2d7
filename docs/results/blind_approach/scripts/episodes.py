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
