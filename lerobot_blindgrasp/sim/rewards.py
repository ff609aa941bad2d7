"""The paper's reward, eq. 1-7, as named terms over the env axis (mjlab's manager style):

    r = w1 r_t + w2 r_i + w31 r_l + w32 r_a + w33 r_ar            (eq. 1, `total`)

with w = (1.0, 0.2, -500, -0.04, -0.01). The shaping terms `reach` and `touch` are not in the paper; only the
`cpu`/`quick` teacher presets weigh them."""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass, field, fields, replace
from functools import cached_property

import torch

from lerobot_blindgrasp import spec
from lerobot_blindgrasp.sim import sensors


@dataclass(frozen=True)
class StepQuantities:
    """What the reward terms read after a control step, (num_envs, ...) float64 tensors on the envs' device."""

    lift: torch.Tensor  # h_o: object height above its resting height (m)
    d_xy: torch.Tensor  # eq. 2's distance of the object from the gripper centre in the table plane (m)
    uniaxial_force: torch.Tensor  # (n, 3) fingertip sensor readings, noise-free (N)
    q: torch.Tensor  # (n, 9) joint positions (rad)
    action: torch.Tensor  # (n, 9) a_t, clipped delta-theta (rad)
    prev_action: torch.Tensor  # (n, 9) a_{t-1}
    tip_object_distance: torch.Tensor  # (n, 3) each tip's end to the object's surface (m)
    tip_object_force: torch.Tensor  # (n, 3) |net force| of each tip on the object (N)
    contact_threshold_n: float = spec.FORCE_THRESHOLD_N

    @cached_property
    def n_contact(self) -> torch.Tensor:
        return num_contacts(self.uniaxial_force, self.contact_threshold_n)


PAPER_WEIGHTS = {"task": 1.0, "incentive": 0.2, "joint_limit": -500.0, "action": -0.04, "action_rate": -0.01}


@dataclass(frozen=True)
class RewardConfig:
    # eq. 1's weight of each term, by name (`TERMS`); a name left out weighs 0
    weights: Mapping[str, float] = field(default_factory=lambda: dict(PAPER_WEIGHTS))
    reach_scale: float = 10.0  # r_reach = mean over tips of 1 - tanh(reach_scale * d_tip_object)
    target_lift_m: float = spec.TARGET_LIFT_M  # h_t
    contact_threshold_n: float = spec.FORCE_THRESHOLD_N
    workspace_radius_m: float = spec.WORKSPACE_RADIUS_M

    def __post_init__(self):
        unknown = sorted(set(self.weights) - set(TERMS))
        if unknown:
            raise ValueError(f"unknown reward term(s) {unknown}; the terms are {', '.join(TERMS)}")
        # Every term gets its weight, 0 for one left out, so that two configs that weigh the same compare equal
        object.__setattr__(self, "weights", {name: float(self.weights.get(name, 0.0)) for name in TERMS})

    def weight(self, name: str) -> float:
        return self.weights[name]

    def with_weights(self, **weights: float) -> RewardConfig:
        """This config with the named terms' weights set (e.g. a shaping term switched on)."""
        return replace(self, weights={**self.weights, **weights})

    def without(self, *names: str) -> RewardConfig:
        """This config with the named terms switched off (weight 0): how an ablation drops a term."""
        return self.with_weights(**dict.fromkeys(names, 0.0))

    def as_record(self) -> dict:
        """The config as a run records it (teacher_config.json): `w_<term>` for every term, then the parameters."""
        params = {f.name: getattr(self, f.name) for f in fields(self) if f.name != "weights"}
        return {**{f"w_{name}": self.weight(name) for name in TERMS}, **params}

    @classmethod
    def from_record(cls, record: Mapping) -> RewardConfig:
        """The inverse of `as_record` (what a teacher's teacher_config.json holds)."""
        params = {k: v for k, v in record.items() if not k.startswith("w_")}
        unknown = sorted(set(params) - set(cls().as_record()))
        if unknown:
            raise ValueError(f"unknown reward setting(s) {unknown} in {dict(record)}")
        return cls(weights={k[2:]: float(v) for k, v in record.items() if k.startswith("w_")}, **params)


def planar_distance(object_xy: torch.Tensor) -> torch.Tensor:
    """d_xy, eq. 2: distance in the table plane between the object and the gripper centre (the world origin)."""
    return sensors.sum_short(object_xy.square(), -1).sqrt()


def num_contacts(uniaxial_force, threshold: float = spec.FORCE_THRESHOLD_N):
    """n_contact: fingertip sensors reading more than the contact threshold (0.1 N)."""
    return (uniaxial_force > threshold).sum(axis=-1)


def r_task(s: StepQuantities, cfg: RewardConfig) -> torch.Tensor:
    """Eq. 3, active only with >= 1 fingertip contact and the object inside the workspace. h_o is clipped at 0 so
    that resting penetration cannot push the square root's argument past 1."""
    h_t = cfg.target_lift_m
    h_o = s.lift.clamp_min(0.0)
    centred = 1.0 - torch.sqrt((s.d_xy / cfg.workspace_radius_m).clamp(0.0, 1.0))
    height = torch.where(h_o < h_t, 1.0 - torch.sqrt(((h_t - h_o) / h_t).clamp(0.0, 1.0)), 1.0)
    active = (s.n_contact >= 1) & (s.d_xy < cfg.workspace_radius_m)
    return torch.where(active, height * centred, 0.0)


def r_incentive(s: StepQuantities, cfg: RewardConfig) -> torch.Tensor:
    """Eq. 4: 1 when all three fingertips sense contact."""
    return (s.n_contact == spec.NUM_FORCES).to(torch.float64)


def r_joint_limit(s: StepQuantities, cfg: RewardConfig) -> torch.Tensor:
    """Eq. 5: summed violation (rad) of the allowed joint range over the nine joints."""
    lower, upper = _joint_limits(s.q)
    return ((lower - s.q).clamp_min(0.0) + (s.q - upper).clamp_min(0.0)).sum(-1)


def r_action(s: StepQuantities, cfg: RewardConfig) -> torch.Tensor:
    """Eq. 6: |a_t|^2, a_t = delta-theta in rad."""
    return s.action.square().sum(-1)


def r_action_rate(s: StepQuantities, cfg: RewardConfig) -> torch.Tensor:
    """Eq. 7: |a_t - a_{t-1}|^2."""
    return (s.action - s.prev_action).square().sum(-1)


def r_reach(s: StepQuantities, cfg: RewardConfig) -> torch.Tensor:
    """Shaping (not in the paper): pulls tips toward the object; r_t is 0 until a lift, so small budgets stall."""
    return (1.0 - torch.tanh(cfg.reach_scale * s.tip_object_distance.clamp_min(0.0))).mean(-1)


def r_touch(s: StepQuantities, cfg: RewardConfig) -> torch.Tensor:
    """Shaping (not in the paper): fraction of tips pressing on the *object* (> 0.1 N, any direction), not the table."""
    return (s.tip_object_force > cfg.contact_threshold_n).to(torch.float64).mean(-1)


_LIMITS: dict[torch.device, tuple[torch.Tensor, torch.Tensor]] = {}


def _joint_limits(q: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
    """spec's joint limits as tensors on q's device, made once per device (not on every step)."""
    if q.device not in _LIMITS:
        _LIMITS[q.device] = (
            torch.as_tensor(spec.JOINT_LOWER, dtype=torch.float64, device=q.device),
            torch.as_tensor(spec.JOINT_UPPER, dtype=torch.float64, device=q.device),
        )
    return _LIMITS[q.device]


# Every term, by name, in eq. 1's order (the shaping terms last): the order `total` sums in.
TERMS: dict[str, Callable[[StepQuantities, RewardConfig], torch.Tensor]] = {
    fn.__name__.removeprefix("r_"): fn
    for fn in (r_task, r_incentive, r_joint_limit, r_action, r_action_rate, r_reach, r_touch)
}
TERM_NAMES = tuple(TERMS)
PAPER_REWARD = RewardConfig()


def compute_terms(s: StepQuantities, cfg: RewardConfig) -> dict[str, torch.Tensor]:
    """Every term, unweighted, by name (the env logs each one separately)."""
    return {name: fn(s, cfg) for name, fn in TERMS.items()}


def total(terms: Mapping[str, torch.Tensor], cfg: RewardConfig) -> torch.Tensor:
    """Eq. 1: the weighted sum of the terms (with the shaping terms' weights, 0 in the paper)."""
    out = 0.0
    for name in TERMS:
        out = out + cfg.weight(name) * terms[name]
    return out
