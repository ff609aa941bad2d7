"""Demonstration curation (paper Sec. III-C): keep grasp-and-lift episodes with rich fingertip force interaction.

An episode of T <= 100 steps (5 s at 20 Hz) passes when the task reward r_t (eq. 3) stays > 0.5 for >= 0.5 s (10
consecutive steps) and the uniaxial fingertip forces summed over the 3 sensors and the steps exceed 200 N (a sum of
20 Hz samples, not an integral). The sum is of the compressive part max(f, 0) of the *noise-free* force after the
0.1 N deadband: the student's N(0, 0.5 N) noise summed over up to 300 samples random-walks by about +-9 N, and a tip
pulled along its load cell's axis is not pressing. Kept episodes are whole by default, holding included (a student
that never sees a 1 s hold does not learn to hold); `trim_to_success` ends them where both criteria are first met.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass

import numpy as np

from lerobot_blindgrasp import spec


@dataclass(frozen=True)
class CurationConfig:
    task_reward_threshold: float = 0.5  # r_t must be strictly above this ...
    min_hold_s: float = 0.5  # ... for at least this long without a break
    force_sum_threshold_n: float = 200.0  # sum of uniaxial forces over sensors and steps must exceed this
    episode_s: float = spec.DEMO_EPISODE_S  # rollout length, 100 steps
    trim_to_success: bool = False  # True: end kept episodes where both criteria are first met
    enabled: bool = True  # False: the "w/o curation" ablation, every episode kept whole

    @property
    def min_hold_steps(self) -> int:
        return round(self.min_hold_s * spec.CONTROL_HZ)

    @property
    def episode_steps(self) -> int:
        return round(self.episode_s * spec.CONTROL_HZ)

    def to_dict(self) -> dict:
        return {**asdict(self), "min_hold_steps": self.min_hold_steps, "episode_steps": self.episode_steps}


PAPER_CURATION = CurationConfig()
NO_CURATION = CurationConfig(enabled=False, trim_to_success=False)


@dataclass(frozen=True)
class CurationResult:
    passed: bool  # both criteria met (computed even when curation is disabled, for the metadata)
    keep: bool  # written to the dataset
    keep_steps: int  # frames written (trimmed or whole)
    longest_hold_steps: int  # longest run of r_t > threshold
    force_sum_n: float  # compressive force summed over sensors and the whole rollout (N)
    criteria_step: int  # index of the step where both criteria were first met; -1 if never

    @property
    def longest_hold_s(self) -> float:
        return self.longest_hold_steps / spec.CONTROL_HZ


def _first_true(mask: np.ndarray) -> int:
    idx = np.flatnonzero(mask)
    return int(idx[0]) if idx.size else -1


def hold_run_lengths(task_reward: np.ndarray, threshold: float) -> np.ndarray:
    """run[t] = number of consecutive steps ending at t with r > threshold (0 where r <= threshold)."""
    above = np.asarray(task_reward) > threshold
    # Index of the last step at or before t that was not above the threshold (-1 if none yet).
    last_break = np.maximum.accumulate(np.where(~above, np.arange(above.size), -1))
    return np.where(above, np.arange(above.size) - last_break, 0)


def judge_episode(
    task_reward: np.ndarray, uniaxial_force: np.ndarray, cfg: CurationConfig = PAPER_CURATION
) -> CurationResult:
    """Judge one episode. task_reward: (T,) r_t per step; uniaxial_force: (T, 3) noise-free forces (N) per step."""
    r = np.asarray(task_reward, dtype=np.float64).reshape(-1)
    if r.size == 0:
        raise ValueError("cannot curate an empty episode")
    f = np.asarray(uniaxial_force, dtype=np.float64).reshape(r.size, -1)
    if r.size > cfg.episode_steps:
        raise ValueError(f"episode has {r.size} steps, more than the {cfg.episode_steps}-step curation window")
    runs = hold_run_lengths(r, cfg.task_reward_threshold)
    cum_force = np.cumsum(np.clip(f, 0.0, None).sum(axis=1))
    t_hold = _first_true(runs >= cfg.min_hold_steps)
    t_force = _first_true(cum_force > cfg.force_sum_threshold_n)
    passed = t_hold >= 0 and t_force >= 0
    criteria_step = max(t_hold, t_force) if passed else -1
    if not cfg.enabled:
        keep, keep_steps = True, r.size
    else:
        keep = passed
        keep_steps = (criteria_step + 1 if cfg.trim_to_success else r.size) if passed else 0
    return CurationResult(
        passed=bool(passed),
        keep=bool(keep),
        keep_steps=int(keep_steps),
        longest_hold_steps=int(runs.max()),
        force_sum_n=float(cum_force[-1]),
        criteria_step=int(criteria_step),
    )
