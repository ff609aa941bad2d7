"""How well a student fits its demonstrations, and where its closed loop leaves them (`python -m lab.diagnosis.student_diagnosis`).

- `episodes_by_object`: a blindgrasp LeRobotDataset's episodes, per object, read with LeRobot's loader;
- `imitation_loss`: the training loss (MSE of delta/0.3, what lerobot-train minimizes) over their frames, and its
  open-loop error in radians; `label_noise_floor`: what a perfect student still scores on stochastic labels;
- `Coverage` and `first_run_above`: the distance of a closed-loop observation to the nearest demo frame near the
  same time, and the first step of a run outside what the demos cover (drift).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import torch

from lerobot_blindgrasp import spec
from lerobot_blindgrasp.sim import objects


def episodes_by_object(root: Path) -> dict[str, list[tuple[np.ndarray, np.ndarray]]]:
    """{object: [(state (T, 12), action (T, 9)), ...]} of a blindgrasp LeRobotDataset, read with LeRobot's loader."""
    from lerobot.datasets.lerobot_dataset import LeRobotDataset

    ds = LeRobotDataset(repo_id=f"local/{Path(root).name}", root=root)
    hf = ds.hf_dataset.with_format("numpy")
    state = np.stack(hf["observation.state"]).astype(np.float32)
    action = np.stack(hf["action"]).astype(np.float32)
    episode = np.asarray(hf["episode_index"]).reshape(-1)
    task_index = np.asarray(hf["task_index"]).reshape(-1)
    by_task = {objects.get_object(o).task: o for o in objects.CATALOGUE}
    task_names = dict(enumerate(ds.meta.tasks.index))
    out: dict[str, list] = {}
    for e in np.unique(episode):
        rows = np.flatnonzero(episode == e)
        name = by_task[task_names[int(task_index[rows[0]])]]
        out.setdefault(name, []).append((state[rows], action[rows]))
    return out


def windows(state: np.ndarray, context: int) -> tuple[np.ndarray, np.ndarray]:
    """Every frame's context window as lerobot-train loads it: (T, context, 12) states and (T, context) padding flags
    (frames before the episode start repeat its first frame and are flagged)."""
    t = np.arange(len(state))[:, None] + np.arange(1 - context, 1)[None, :]
    return state[np.clip(t, 0, None)], t < 0


@torch.no_grad()
def imitation_loss(policy, pre, episodes: list[tuple[np.ndarray, np.ndarray]], batch: int = 1024) -> dict:
    """Mean training loss (MSE of delta/0.3 over the 9 joints) and RMS action error (rad) over all frames."""
    sq, n = 0.0, 0
    for state, action in episodes:
        win, pad = windows(state, policy.config.n_obs_steps)
        for s in range(0, len(win), batch):
            b = pre(
                {
                    spec.STATE_KEY: torch.from_numpy(win[s : s + batch]),
                    f"{spec.STATE_KEY}_is_pad": torch.from_numpy(pad[s : s + batch]),
                    spec.ACTION_KEY: torch.from_numpy(action[s : s + batch]),
                }
            )
            per_sample, _ = policy.forward(b, reduction="none")
            sq += float(per_sample.sum()) * spec.ACTION_DIM
            n += per_sample.numel() * spec.ACTION_DIM
    mse = sq / max(n, 1)
    return {"mse": mse, "rms_rad": float(np.sqrt(mse)) * spec.ACTION_BOUND_RAD, "frames": n // spec.ACTION_DIM}


def label_noise_floor(teacher: Path | None) -> float:
    """The loss a perfect student still has on stochastic-teacher labels: mean over joints of (std / 0.3)^2, the
    variance of the teacher's Gaussian in the loss's units (clipping at +-0.3 rad trims it slightly)."""
    from lerobot_blindgrasp.teacher.policy import TeacherPolicy, default_teacher

    std = TeacherPolicy(teacher or default_teacher()).action_std
    return float(np.mean((std / spec.ACTION_BOUND_RAD) ** 2))


class Coverage:
    """Distance of an observation to the nearest demo frame of one object near the same time (std units)."""

    def __init__(self, demo_states: list[np.ndarray], std: np.ndarray, window: int):
        self.window = window
        self.std = np.maximum(std, 1e-6)
        self.by_time: dict[int, np.ndarray] = {}
        horizon = max(len(s) for s in demo_states)
        self.horizon = horizon
        for t in range(horizon):
            lo, hi = max(0, t - window), t + window + 1
            rows = [s[lo:hi] for s in demo_states if len(s) > lo]
            self.by_time[t] = np.concatenate(rows) / self.std

    def distance(self, state: np.ndarray, dims: slice) -> np.ndarray:
        """state (n, T, 12) -> (n, T) nearest-neighbour distance over `dims`."""
        n, horizon, _ = state.shape
        out = np.zeros((n, horizon))
        z = state / self.std
        for t in range(horizon):
            ref = self.by_time[min(t, self.horizon - 1 - self.window // 2)][:, dims]
            d = ((z[:, t, None, dims] - ref[None]) ** 2).sum(-1)
            out[:, t] = np.sqrt(d.min(1))
        return out


SPACES = {"joints": spec.STATE_JOINT_SLICE, "forces": spec.STATE_FORCE_SLICE}


def first_run_above(dist: np.ndarray, threshold: float, run: int, length: np.ndarray) -> np.ndarray:
    """(n,) first step starting `run` consecutive steps above threshold, within each episode; -1 if none."""
    above = dist > threshold
    out = np.full(len(dist), -1)
    for k in range(len(dist)):
        a = above[k, : int(length[k])]
        streak = np.convolve(a.astype(int), np.ones(run, int), "valid") == run
        hits = np.flatnonzero(streak)
        if hits.size:
            out[k] = int(hits[0])
    return out
