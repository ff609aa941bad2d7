"""`blindgrasp-diagnose-student`: why a student trails its teacher, object by object, before anyone tunes it.

    blindgrasp-diagnose-student --student=models/student_cpu --demos=outputs/pipeline_quick_blind/demos \
        --held_out=outputs/held_out_demos --objects=capsule_small,sphere_small --episodes=20

Per object it measures:
- **fit**: the training loss (MSE of delta/0.3, exactly what lerobot-train minimizes) on the object's training demos
  and on held-out teacher rollouts (curated the same way, from another block of the demo seed range), and that
  open-loop error in radians. A held-out loss far above the training loss is overfitting; both high is underfitting.
- **failure kind** of every closed-loop episode on the evaluation start states (those `lerobot-eval --seed` runs),
  from the simulator's ground truth: never touches, presses from above, touches without lifting, knocked out of
  reach (the object left the 10 cm workspace before it was lifted), slips while lifting (rose but never reached the
  success height), or drops during the hold (reached it, then fell, whether or not it then rolled away).
- **drift**: the first step at which the closed-loop observation leaves what the object's demos cover, separately in
  joint space and in force space. Coverage is the distance to the nearest demo frame of the same object within
  +-`window` steps of the same time, in units of the dataset's per-dimension std; a step is outside when that
  distance exceeds the 99th percentile of the same distance for held-out teacher rollouts, and drift is the first of
  `run` outside steps in a row. Demos last 5 s and evaluation 10 s; later steps compare with the demos' last second.

The closed loop steps the batched simulator with the student's LeRobot pre/post-processors, as lerobot-eval does, so
its successes equal lerobot-eval's on the same `--seed` (the report checks this when given an eval folder).
Outputs: `diagnosis.json`, `diagnosis.md` and `diagnosis.png` under `--output_dir`.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np
import torch
from tqdm import tqdm

from lerobot_blindgrasp import spec
from lerobot_blindgrasp.cli import parse_config
from lerobot_blindgrasp.durable import atomic_path, atomic_write_json, atomic_write_text
from lerobot_blindgrasp.results import rates
from lerobot_blindgrasp.sim import objects

KINDS = (
    "success",
    "never touches",
    "presses from above",
    "touches, never lifts",
    "knocked out of reach",
    "slips while lifting",
    "drops during the hold",
)
TOUCH_N = 0.5  # a tip on the object with more than this net force is touching it (noise-free, N)
LIFTED_M = 0.005  # the object rose this much: a lift began
PRESSING_DOWN = 0.5  # mean -F_z/|F| of the touching tips above this: pressing into the table, not squeezing


@dataclass
class DiagnoseConfig:
    """Fit, failure kinds and drift of a blindgrasp_transformer student, per object."""

    student: Path = Path("models/student_cpu")  # a LeRobot pretrained_model folder
    demos: Path | None = None  # the student's training dataset (LeRobotDataset root); fit and drift need it
    held_out: Path | None = None  # held-out curated teacher rollouts (another demo seed); fit and drift need it
    objects: str = "all"  # "all", "medium", or a comma-separated list of catalogue names
    episodes: int = 20  # closed-loop episodes per object
    seed: int = spec.EVAL_SEED  # first evaluation index (lerobot-eval's --seed)
    student_eval: Path | None = None  # a lerobot-eval output folder of the same student and seed: checked against
    teacher: Path | None = (
        None  # the demos' teacher, for the label-noise floor of the loss; default: the shipped one
    )
    output_dir: Path = Path("outputs/student_diagnosis")
    window: int = 10  # drift: demo frames within +-window steps of the same time are the reference
    run: int = 3  # drift: this many outside steps in a row
    device: str = "cpu"
    progress: bool = True

    def __post_init__(self):
        spec.eval_env_seed(self.seed + self.episodes - 1, 0)  # raises if the indices leave the eval block


# --- the student -------------------------------------------------------------------------------------------------


def load_student(path: Path, device: str = "cpu"):
    """(policy, preprocessor, postprocessor) of a pretrained_model folder, the way lerobot-eval loads them."""
    from lerobot.policies.factory import make_pre_post_processors

    from lerobot_blindgrasp.policies.blindgrasp_transformer import BlindgraspTransformerPolicy

    policy = BlindgraspTransformerPolicy.from_pretrained(str(path))
    policy.config.device = device
    policy.to(device).eval()
    from lerobot_blindgrasp.policies.blindgrasp_transformer.processor_blindgrasp_transformer import (
        SensorAugmentStep,
    )

    pre, post = make_pre_post_processors(
        policy.config, pretrained_path=str(path), preprocessor_overrides={"device_processor": {"device": device}}
    )
    for step in pre.steps:  # the fit is measured on the sensors as recorded, not on training-time errors
        if isinstance(step, SensorAugmentStep):
            step.enabled = False
    return policy, pre, post


def student_actor(policy, pre, post):
    """obs dict of the batched env -> absolute joint targets (n, 9), one step of the rolling context."""

    @torch.no_grad()
    def act(obs: dict[str, np.ndarray]) -> np.ndarray:
        batch = pre({spec.STATE_KEY: torch.from_numpy(obs["policy"]).float()})
        return post(policy.select_action(batch)).cpu().numpy().astype(np.float64)

    return act


# --- closed loop -------------------------------------------------------------------------------------------------


class Outcomes:
    """Per-env outcome of a batch of episodes stepped without auto-reset: success, left the workspace, length."""

    def __init__(self, n: int, horizon: int):
        self.alive, self.success, self.left = np.ones(n, bool), np.zeros(n, bool), np.zeros(n, bool)
        self.length = np.full(n, horizon)

    def update(self, t: int, info: dict, term: np.ndarray, trunc: np.ndarray) -> bool:
        """Record control step t's result; False once every episode has ended."""
        self.success |= info["success"] & self.alive
        ended = self.alive & (term | trunc)
        self.left |= ended & term
        self.length[ended] = t + 1
        self.alive &= ~(term | trunc)
        return bool(self.alive.any())


def closed_loop(act_targets, object_name: str, episodes: int, seed: int, reset=None) -> dict[str, np.ndarray]:
    """Run `episodes` evaluation episodes of one object (env k = evaluation index seed + k) and keep the traces.

    act_targets(obs) -> absolute targets; `reset()` is called first (the policy's context). Returns per-episode
    arrays: state (n, T, 12), lift (n, T), touch_force and downward (n, T, 3), success (n,), left (n,) and
    length (n,) (steps until the episode ended)."""
    from lerobot_blindgrasp.sim.env import BatchedGraspEnv, GraspEnvConfig
    from lerobot_blindgrasp.sim.gym_env import start_seed
    from lerobot_blindgrasp.sim.randomization import EVAL_DR

    env = BatchedGraspEnv(
        GraspEnvConfig(
            num_envs=episodes,
            objects=(object_name,),
            seed=start_seed(seed, object_name),
            dr=EVAL_DR,
            autoreset=False,
        )
    )
    if reset is not None:
        reset()
    horizon = env.max_episode_steps
    out = {
        "state": np.zeros((episodes, horizon, spec.STATE_DIM), np.float32),
        "lift": np.zeros((episodes, horizon)),
        "touch_force": np.zeros((episodes, horizon, spec.NUM_FORCES)),
        "downward": np.zeros((episodes, horizon, spec.NUM_FORCES)),
    }
    ends = Outcomes(episodes, horizon)
    obs = env.reset()
    for t in range(horizon):
        out["state"][:, t] = obs["policy"]
        delta = act_targets(obs) - env.joint_positions()  # as the gym env turns a target into the sim's action
        obs, _, term, trunc, info = env.step(delta)
        out["lift"][:, t] = info["lift"]
        out["touch_force"][:, t] = info["tip_object_force"]
        out["downward"][:, t] = info["tip_object_downward"]
        if not ends.update(t, info, term, trunc):
            break
    env.close()
    return {**out, "success": ends.success, "left": ends.left, "length": ends.length}


def failure_kind(trace: dict[str, np.ndarray], k: int) -> str:
    """One episode's outcome as one of KINDS, from ground truth (see the module docstring)."""
    n = int(trace["length"][k])
    if trace["success"][k]:
        return "success"
    lift = trace["lift"][k, :n]
    force = trace["touch_force"][k, :n]
    touching = force > TOUCH_N
    if not touching.any():
        return "never touches"
    if lift.max() >= spec.SUCCESS_LIFT_M:
        return "drops during the hold"
    if lift.max() >= LIFTED_M:
        return "slips while lifting"
    if trace["left"][k]:  # pushed or rolled out of the 10 cm workspace before any lift
        return "knocked out of reach"
    down = trace["downward"][k, :n][touching]
    return "presses from above" if down.mean() > PRESSING_DOWN else "touches, never lifts"


# --- datasets ----------------------------------------------------------------------------------------------------


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


# --- drift -------------------------------------------------------------------------------------------------------


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


# --- the command -------------------------------------------------------------------------------------------------


def diagnose(cfg: DiagnoseConfig) -> dict:
    policy, pre, post = load_student(cfg.student, cfg.device)
    names = objects.resolve_objects(cfg.objects)
    train = episodes_by_object(cfg.demos) if cfg.demos else {}
    held = episodes_by_object(cfg.held_out) if cfg.held_out else {}
    std = None
    if train:
        std = np.concatenate([s for eps in train.values() for s, _ in eps]).std(0)
    result: dict = {
        "student": str(cfg.student),
        "seed": cfg.seed,
        "episodes": cfg.episodes,
        "demos": str(cfg.demos),
        "held_out": str(cfg.held_out),
        "objects": {},
        "label_noise_floor": label_noise_floor(cfg.teacher),
    }
    act = student_actor(policy, pre, post)
    for name in tqdm(names, desc="diagnose", disable=not cfg.progress):
        torch.manual_seed(cfg.seed)
        trace = closed_loop(act, name, cfg.episodes, cfg.seed, reset=policy.reset)
        kinds = [failure_kind(trace, k) for k in range(cfg.episodes)]
        row: dict = {
            "successes": [bool(s) for s in trace["success"]],
            "kinds": kinds,
            "kind_counts": {k: kinds.count(k) for k in KINDS if kinds.count(k)},
            "max_lift_cm": [round(float(x) * 100, 2) for x in trace["lift"].max(1)],
        }
        if name in train:
            row["fit"] = {"train": imitation_loss(policy, pre, train[name]), "demos": len(train[name])}
            if name in held:
                row["fit"]["held_out"] = imitation_loss(policy, pre, held[name])
                row["fit"]["held_out_episodes"] = len(held[name])
                row["drift"] = _drift(trace, train[name], held[name], std, cfg)
        result["objects"][name] = row
    if cfg.student_eval:
        result["matches_lerobot_eval"] = _check_against_eval(result, cfg.student_eval)
    return result


def _drift(trace, train_eps, held_eps, std, cfg) -> dict:
    cov = Coverage([s for s, _ in train_eps], std, cfg.window)
    out = {}
    for space, dims in SPACES.items():
        held_states = [s for s, _ in held_eps]
        held_d = np.concatenate([cov.distance(s[None], dims)[0] for s in held_states])
        threshold = float(np.percentile(held_d, 99))
        dist = cov.distance(trace["state"], dims)
        step = first_run_above(dist, threshold, cfg.run, trace["length"])
        out[space] = {
            "threshold": threshold,
            "first_step": [int(s) for s in step],
            "median_distance": [float(np.median(d[: int(n)])) for d, n in zip(dist, trace["length"])],
        }
    return out


def _check_against_eval(result: dict, eval_dir: Path) -> dict:
    from lerobot_blindgrasp.results.compare import load_successes

    theirs = load_successes(eval_dir)
    same = {o: theirs.get(o, [])[: len(r["successes"])] == r["successes"] for o, r in result["objects"].items()}
    return {"all": all(same.values()), "per_object": same}


def markdown(result: dict) -> str:
    lines = [
        "| object | success | " + " | ".join(KINDS[1:]) + " | train loss | held-out loss | held-out rms (rad) "
        "| drift joints (failed / succeeded) | drift forces (failed / succeeded) |",
        "|---|---:|" + "---:|" * (len(KINDS) - 1) + "---:|---:|---:|---:|---:|",
    ]
    for name, r in result["objects"].items():
        cells = [rates.format_rate(*rates.count(r["successes"]))]
        cells += [str(r["kind_counts"].get(k, 0)) for k in KINDS[1:]]
        fit = r.get("fit", {})
        cells.append(f"{fit['train']['mse']:.4f}" if fit else "-")
        cells.append(f"{fit['held_out']['mse']:.4f}" if "held_out" in fit else "-")
        cells.append(f"{fit['held_out']['rms_rad']:.3f}" if "held_out" in fit else "-")
        for space in SPACES:
            d = r.get("drift", {}).get(space)
            cells.append(_drift_cell(d, r["successes"]) if d else "-")
        lines.append(f"| {name} | " + " | ".join(cells) + " |")
    lines += [
        "",
        "Drift: episodes that leave the demos' coverage / all, and the median step at which they do (20 "
        "steps = 1 s). Loss: MSE of delta/0.3 (the training loss); rms: its open-loop error in rad. "
        f"Label-noise floor of the loss (the stochastic teacher's own variance): "
        f"{result['label_noise_floor']:.4f}.",
    ]
    if "matches_lerobot_eval" in result:
        lines.append(f"Closed-loop successes equal lerobot-eval's: {result['matches_lerobot_eval']['all']}.")
    return "\n".join(lines) + "\n"


def _drift_cell(d: dict, successes: list[bool]) -> str:
    parts = []
    for want in (False, True):
        steps = [s for s, ok in zip(d["first_step"], successes) if ok == want]
        drifted = [s for s in steps if s >= 0]
        med = f" @{int(np.median(drifted))}" if drifted else ""
        parts.append(f"{len(drifted)}/{len(steps)}{med}")
    return " / ".join(parts)


def plot(result: dict, path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    names = list(result["objects"])
    fig, (ax0, ax1) = plt.subplots(1, 2, figsize=(max(8, 0.7 * len(names) + 6), 4.5))
    bottom = np.zeros(len(names))
    for kind in KINDS:
        vals = np.array([result["objects"][n]["kind_counts"].get(kind, 0) for n in names], float)
        ax0.bar(range(len(names)), vals, bottom=bottom, label=kind)
        bottom += vals
    ax0.set_xticks(range(len(names)), [n.replace("_", " ") for n in names], rotation=60, ha="right", fontsize=8)
    ax0.set_ylabel("episodes")
    ax0.set_title("Closed-loop outcome per object")
    ax0.legend(fontsize=7)
    fitted = [n for n in names if "held_out" in result["objects"][n].get("fit", {})]
    x = np.arange(len(fitted))
    for i, split in enumerate(("train", "held_out")):
        ax1.bar(
            x + (i - 0.5) * 0.4,
            [result["objects"][n]["fit"][split]["mse"] for n in fitted],
            0.4,
            label=split.replace("_", "-"),
        )
    ax1.set_xticks(x, [n.replace("_", " ") for n in fitted], rotation=60, ha="right", fontsize=8)
    ax1.axhline(result["label_noise_floor"], color="k", ls="--", lw=1, label="label-noise floor")
    ax1.set_ylabel("imitation loss (MSE of delta / 0.3)")
    ax1.set_title("Fit")
    ax1.legend(fontsize=7)
    fig.tight_layout()
    with atomic_path(path) as tmp:
        fig.savefig(tmp, dpi=110, format="png")
    plt.close(fig)


def main(argv=None) -> None:
    cfg = parse_config(DiagnoseConfig, argv)
    result = diagnose(cfg)
    out = cfg.output_dir
    out.mkdir(parents=True, exist_ok=True)
    atomic_write_json(out / "diagnosis.json", result, indent=1)
    atomic_write_text(out / "diagnosis.md", markdown(result))
    plot(result, out / "diagnosis.png")
    print(markdown(result))
    print(f"wrote {out}/diagnosis.json, diagnosis.md, diagnosis.png")


if __name__ == "__main__":
    main()
