"""The one env factory: a purpose (`PURPOSES`: its seed range, randomization and resets), the objects and the seeds
in; the batched env out. Env i of a training purpose has seed + i; env i of an evaluation purpose runs evaluation
index seed + i // n on object i % n, the start state `lerobot-eval --seed` gives it (`sim.gym_env.start_seed`).

    make_batched_env("eval", ("capsule_small",), episodes=20, seed=1000)  # lerobot-eval's start states
    make_batched_env("demos", objects, num_envs=180, seed=spec.DEMO_SEED)  # auto-resetting teacher rollouts
"""

from __future__ import annotations

from dataclasses import dataclass

from lerobot_blindgrasp import spec
from lerobot_blindgrasp.sim import randomization
from lerobot_blindgrasp.sim.batched_config import GraspEnvConfig
from lerobot_blindgrasp.sim.batched_env import BatchedGraspEnv
from lerobot_blindgrasp.sim.gym_env import start_seed


@dataclass(frozen=True)
class Purpose:
    seed_range: str  # a key of spec.SEED_RANGES
    dr: randomization.DomainRandomization | None  # None: the caller must give one
    autoreset: bool
    eval_seeds: bool = False  # seeds are evaluation indices, mapped per object (spec.eval_env_seed)


PURPOSES: dict[str, Purpose] = {
    "train": Purpose("teacher_train", randomization.PAPER_DR, autoreset=True),
    "scripts": Purpose("teacher_train", randomization.EVAL_DR, autoreset=False),
    "demos": Purpose("demos", randomization.EVAL_DR, autoreset=True),
    "dagger": Purpose("demos", randomization.EVAL_DR, autoreset=False),
    "eval": Purpose("eval", randomization.EVAL_DR, autoreset=False, eval_seeds=True),
    "robustness": Purpose("eval", None, autoreset=False, eval_seeds=True),
}


def eval_start_seeds(object_names: tuple[str, ...], episodes: int, seed: int, copies: int = 1) -> tuple[int, ...]:
    """Env seeds of `episodes` evaluation indices per object from `seed`, objects round-robin as the env assigns
    them (env i: object i % n, index seed + i // n), the whole batch `copies` times (policies side by side)."""
    spec.eval_env_seed(seed + episodes - 1, 0)  # raises if the indices leave the eval block
    n = len(object_names)
    one = tuple(start_seed(seed + i // n, object_names[i % n]) for i in range(n * episodes))
    return one * copies


def env_config(
    purpose: str,
    object_names: tuple[str, ...],
    *,
    seed: int,
    num_envs: int | None = None,
    episodes: int | None = None,
    copies: int = 1,
    dr: randomization.DomainRandomization | None = None,
    **options,
) -> GraspEnvConfig:
    """The `GraspEnvConfig` of `purpose`: `episodes` per object (and `copies` of the batch) for evaluation, else
    `num_envs`. `dr` replaces the purpose's randomization; `options` are further GraspEnvConfig fields."""
    if purpose not in PURPOSES:
        raise ValueError(f"unknown purpose {purpose!r}; choose from {', '.join(PURPOSES)}")
    p = PURPOSES[purpose]
    dr = dr or p.dr
    if dr is None:
        raise ValueError(f"a {purpose} env needs the randomization under test (dr=...)")
    if p.eval_seeds:
        if episodes is None or num_envs is not None:
            raise ValueError(f"a {purpose} env takes episodes per object, not num_envs")
        seeds = eval_start_seeds(tuple(object_names), episodes, seed, copies)
        options |= {"num_envs": len(seeds), "env_seeds": seeds}
    else:
        if num_envs is None or episodes is not None:
            raise ValueError(f"a {purpose} env takes num_envs (env i seeded seed + i), not episodes")
        spec.check_seeds(p.seed_range, seed, num_envs)
        options |= {"num_envs": num_envs, "seed": seed}
    return GraspEnvConfig(objects=tuple(object_names), dr=dr, autoreset=p.autoreset, **options)


def make_batched_env(purpose: str, object_names: tuple[str, ...], **kwargs) -> BatchedGraspEnv:
    return BatchedGraspEnv(env_config(purpose, object_names, **kwargs))
