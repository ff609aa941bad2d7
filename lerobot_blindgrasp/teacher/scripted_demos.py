"""The scripted side-grasp demonstrations that `teacher.aux_bc.PPOWithScriptedDemos` clones: their settings and
their collection. Kept apart from the PPO subclass so that the preset registry can name them without importing torch.
"""

from __future__ import annotations

import copy
from dataclasses import asdict, dataclass

import numpy as np

from lerobot_blindgrasp import spec
from lerobot_blindgrasp.sim import objects, pregrasp, randomization, scripted
from lerobot_blindgrasp.sim.env import BatchedGraspEnv, GraspEnvConfig

# Script rollouts draw their start states from the teacher-training seed range, far above the env seeds of any
# training run (seed + env index), so that they never share a start state with evaluation or demo collection.
SCRIPT_SEED = 1 << 32
# The rsl-rl algorithm that clones them, as the runner config names it (resolved by rsl-rl when the run starts).
ALGORITHM_CLASS = "lerobot_blindgrasp.teacher.aux_bc:PPOWithScriptedDemos"


@dataclass(frozen=True)
class ScriptedDemos:
    objects: tuple[str, ...] = pregrasp.HARD_OBJECTS
    episodes_per_object: int = 64  # script rollouts per object; the successful ones are kept
    steps_per_episode: int = 120  # approach, squeeze, lift and 2 s of hold: the rest is more of the same hold
    # "interleaved": `steps` cloning steps with their own Adam after each PPO update, learning rate `lr`.
    # "joint": the cloning loss, weighted by `coef`, joins PPO's loss in every PPO minibatch step (one optimizer,
    # one gradient; DAPG's form). Adam normalizes each step's size, so interleaved cloning moves the actor by ~lr
    # per step however small its loss, while a joint term moves it only as far as its gradient weighs against PPO's.
    mode: str = "interleaved"
    lr: float = 3e-4  # interleaved: behaviour-cloning Adam learning rate at `start_iteration`
    coef: float = 0.1  # joint: weight of the cloning loss next to PPO's at `start_iteration`
    decay_iterations: int = 700  # ... linearly to 0 over this many iterations; afterwards the paper's reward alone
    start_iteration: int = 0  # PPO alone before this iteration (cloning into a policy that already grasps)
    steps: int = 8  # behaviour-cloning steps after each PPO update
    batch_size: int = 2048
    seed: int = SCRIPT_SEED
    pushes: bool = False  # Table II's random pushes, as the training preset has them (`external_force`)
    # DAgger (Ross et al. 2011): every `relabel_every` updates while the weight is > 0, the current actor's mean is
    # rolled out on `relabel_episodes` fresh start states of the listed objects and the script's action at every
    # state it visits joins the demonstrations. The script's own states are not where the actor goes wrong: on the
    # small capsule it drifts 0.2-0.4 rad (RMS) from the script's action within 10 steps of its own rollouts
    # (docs/results/teacher_cpu_bc.md section 7). 0: off.
    relabel_every: int = 0
    relabel_episodes: int = 64
    # A target at the action bound only asks for "at least this far" (teacher/aux_bc.py `cloning_loss`)
    saturation_aware: bool = False

    def __post_init__(self):
        unknown = sorted(set(self.objects) - set(objects.CATALOGUE))
        if unknown:
            raise ValueError(f"scripted-demo objects not in the catalogue: {unknown}")
        if min(self.episodes_per_object, self.steps_per_episode, self.decay_iterations, self.batch_size,
               self.relabel_episodes) < 1 or min(self.start_iteration, self.relabel_every) < 0:
            raise ValueError(f"scripted demos need positive sizes, got {self}")
        if self.mode not in ("interleaved", "joint"):
            raise ValueError(f"scripted-demo mode must be 'interleaved' or 'joint', got {self.mode!r}")
        spec.check_seeds("teacher_train", self.seed, self.episodes_per_object * len(self.objects))
        if self.relabel_every:
            rounds = -(-self.decay_iterations // self.relabel_every)
            per_round = self.relabel_per_object * len(self.objects)
            spec.check_seeds("teacher_train", self.relabel_seed(0), per_round * rounds)

    @property
    def relabel_per_object(self) -> int:
        return -(-self.relabel_episodes // len(self.objects))

    def relabel_seed(self, round_: int) -> int:
        """First env seed of relabelling round `round_`: after the script's own start states, never reused."""
        per_round = self.relabel_per_object * len(self.objects)
        return self.seed + self.episodes_per_object * len(self.objects) + round_ * per_round

    def as_record(self) -> dict:
        """The JSON form that goes into the runner config (lists, not tuples: it must survive a JSON round trip)."""
        d = asdict(self)
        d["objects"] = list(self.objects)
        if not self.relabel_every:  # as run configs recorded before relabelling existed, so that they still resume
            del d["relabel_every"], d["relabel_episodes"]
        if not self.saturation_aware:
            del d["saturation_aware"]
        return d

    def runner_cfg(self, runner: dict) -> dict:
        """`runner` (an rsl-rl OnPolicyRunner config) with PPO replaced by PPO plus cloning of these demos."""
        runner = copy.deepcopy(runner)
        runner["algorithm"]["class_name"] = ALGORITHM_CLASS
        runner["algorithm"]["scripted_demos"] = self.as_record()
        return runner

    def weight_at(self, iteration: int) -> float:
        """The cloning's learning rate (interleaved) or loss weight (joint) at a PPO iteration: 0 before
        `start_iteration`, then decaying linearly to 0 over `decay_iterations`."""
        if iteration < self.start_iteration:
            return 0.0
        full = self.lr if self.mode == "interleaved" else self.coef
        return full * max(0.0, 1.0 - (iteration - self.start_iteration) / self.decay_iterations)


def collect(cfg: ScriptedDemos) -> dict:
    """Roll the side-grasp script out once per env from training start states; keep the successful episodes.

    Returns {"obs": {"privileged": (M, 92), "policy": (M, 12)}, "actions": (M, 9), "success": {object: rate}},
    float32. Both observation groups are kept so that an actor reading either (the teacher's privileged one, or the
    "RL w/ o_t" row's student one) can be cloned."""
    return _rollout(cfg, cfg.episodes_per_object, cfg.seed, policy=None)


def relabel(cfg: ScriptedDemos, policy, round_: int) -> dict:
    """DAgger's step: roll `policy` (obs dict -> delta-theta) out from `cfg.relabel_episodes` fresh training start
    states of each listed object and label every state it visits with the script's action there. Every episode is
    kept, failed ones most of all; "success" is the policy's own rate on these start states."""
    return _rollout(cfg, cfg.relabel_per_object, cfg.relabel_seed(round_), policy=policy)


def _rollout(cfg: ScriptedDemos, per_object: int, seed: int, policy) -> dict:
    """The script runs alongside every episode; its action drives the env (policy None: `collect`) or only labels
    the states `policy` drives the env to (`relabel`)."""
    n = per_object * len(cfg.objects)
    dr = randomization.PAPER_DR if cfg.pushes else randomization.EVAL_DR  # as train.build_env_config chooses
    env = BatchedGraspEnv(GraspEnvConfig(num_envs=n, objects=cfg.objects, seed=seed, dr=dr, autoreset=False,
                                         nthread=1))
    obs = env.reset()
    script = scripted.SideGraspScript(env.joint_positions(), env.object_position(),
                                      [objects.get_object(name) for name in env.object_names])
    seen_obs, seen_policy, seen_act = [], [], []
    success = np.zeros(n, dtype=bool)
    for t in range(env.max_episode_steps):
        label = script(env.joint_positions())
        if t < cfg.steps_per_episode:
            seen_obs.append(obs["privileged"].astype(np.float32))
            seen_policy.append(obs["policy"].astype(np.float32))
            seen_act.append(label.astype(np.float32))
        obs, _, terminated, _, info = env.step(label if policy is None else policy(obs))
        success |= info["success"]
        if terminated.any():  # an object left the workspace: that episode is not a demonstration
            success &= ~terminated
    env.close()
    names = np.array(env.object_names)
    rates = {name: float(success[names == name].mean()) for name in cfg.objects}
    keep = np.flatnonzero(success) if policy is None else np.arange(n)
    o = np.stack(seen_obs, axis=1)[keep].reshape(-1, spec.PRIVILEGED_DIM)
    p = np.stack(seen_policy, axis=1)[keep].reshape(-1, spec.STATE_DIM)
    a = np.stack(seen_act, axis=1)[keep].reshape(-1, spec.NUM_JOINTS)
    return {"obs": {"privileged": o, "policy": p}, "actions": a, "success": rates}


@dataclass
class ScriptSuccessConfig:
    """How often the side-grasp script lifts each object from training start states (what `cpu_bc` can clone)."""

    objects: str = "all"  # "all", "medium", or a comma-separated list of catalogue names
    episodes_per_object: int = 30
    pushes: bool = True  # Table II's random pushes (the paper's training randomization)
    # A teacher (folder, run or checkpoint): instead of the script's success, how far the teacher's mean action
    # is from the script's along the teacher's own rollouts, per step (what DAgger would correct)
    drift_of: str = ""


def drift(teacher, cfg: ScriptedDemos, steps=(0, 5, 10, 20, 40, 80, 119)) -> dict:
    """RMS difference (rad) between `teacher`'s mean action, clipped to the action bound as the env executes it,
    and the script's action on the states the teacher's own rollouts visit (one relabelling round), at the given
    steps, and the teacher's success on them."""
    data = relabel(cfg, teacher, round_=0)
    n = len(data["actions"]) // cfg.steps_per_episode
    executed = np.clip(teacher(data["obs"]), -spec.ACTION_BOUND_RAD, spec.ACTION_BOUND_RAD)
    err = (executed - data["actions"]).reshape(n, cfg.steps_per_episode, -1)
    rms = np.sqrt((err**2).mean(axis=(0, 2)))
    return {"rms_rad": {t: float(rms[t]) for t in steps if t < len(rms)}, "success": data["success"]}


def main(argv=None) -> None:
    """python -m lerobot_blindgrasp.teacher.scripted_demos [--objects=all] [--episodes_per_object=30]
    [--drift_of=TEACHER]"""
    from lerobot_blindgrasp.cli import parse_config

    cfg = parse_config(ScriptSuccessConfig, argv)
    if cfg.drift_of:
        from lerobot_blindgrasp.teacher.policy import TeacherPolicy

        names = objects.resolve_objects(cfg.objects)
        demos = ScriptedDemos(objects=names, relabel_every=1, relabel_episodes=cfg.episodes_per_object * len(names),
                              pushes=cfg.pushes)
        out = drift(TeacherPolicy(cfg.drift_of), demos)
        print(f"{cfg.drift_of} on its own rollouts ({cfg.episodes_per_object} per object from seed "
              f"{demos.relabel_seed(0)}), success {out['success']}\n")
        print("| step | RMS(teacher - script), rad |\n|---:|---:|")
        for t, v in out["rms_rad"].items():
            print(f"| {t} | {v:.3f} |")
        return
    demos = ScriptedDemos(objects=objects.resolve_objects(cfg.objects), episodes_per_object=cfg.episodes_per_object,
                          steps_per_episode=1, pushes=cfg.pushes)
    rates = collect(demos)["success"]
    print(f"side-grasp script, {cfg.episodes_per_object} episodes per object from seed {demos.seed}, "
          f"pushes={cfg.pushes}\n\n| object | success |\n|---|---:|")
    for name, rate in rates.items():
        print(f"| {name} | {rate:.0%} ({round(rate * cfg.episodes_per_object)}/{cfg.episodes_per_object}) |")
    print(f"| **all** | **{np.mean(list(rates.values())):.1%}** |")


if __name__ == "__main__":
    main()
