"""`python -m lab.diagnosis.student_diagnosis`: why a student trails its teacher, object by object, before anyone tunes it.

    python -m lab.diagnosis.student_diagnosis --student=models/student_cpu --demos=outputs/pipeline_quick_blind/demos \
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

from lab.diagnosis.student_fit import (
    SPACES,
    Coverage,
    episodes_by_object,
    first_run_above,
    imitation_loss,
    label_noise_floor,
)
from lerobot_blindgrasp import spec
from lerobot_blindgrasp.cli import parse_config
from lerobot_blindgrasp.durable import atomic_path, atomic_write_json, atomic_write_text
from lerobot_blindgrasp.results import rates
from lerobot_blindgrasp.rollout.actors import StudentActor
from lerobot_blindgrasp.rollout.envs import make_batched_env
from lerobot_blindgrasp.rollout.loop import Episode, run_batch
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


# --- closed loop -------------------------------------------------------------------------------------------------
# What the closed loop keeps of each step: o_t, and the ground truth the failure kinds are read from.
TRACES = ("state", "lift", "tip_object_force", "tip_object_downward")


def closed_loop(student: StudentActor, object_name: str, episodes: int, seed: int) -> list[Episode]:
    """`episodes` evaluation episodes of one object (env k = evaluation index seed + k), with their traces."""
    student.reset()
    return run_batch(
        make_batched_env("eval", (object_name,), episodes=episodes, seed=seed), student, record=TRACES
    )


def fit_preprocessor(student: StudentActor):
    """The student's preprocessor with its training-time sensor errors off: the fit is measured on the sensors
    as recorded."""
    from lerobot_blindgrasp.policies.blindgrasp_transformer.processor_blindgrasp_transformer import (
        SensorAugmentStep,
    )

    for step in student.preprocessor.steps:
        if isinstance(step, SensorAugmentStep):
            step.enabled = False
    return student.preprocessor


def failure_kind(ep: Episode) -> str:
    """One episode's outcome as one of KINDS, from ground truth (see the module docstring)."""
    if ep.success:
        return "success"
    lift = ep.traces["lift"]
    force = ep.traces["tip_object_force"]
    touching = force > TOUCH_N
    if not touching.any():
        return "never touches"
    if lift.max() >= spec.SUCCESS_LIFT_M:
        return "drops during the hold"
    if lift.max() >= LIFTED_M:
        return "slips while lifting"
    if ep.left_workspace:  # pushed or rolled out of the 10 cm workspace before any lift
        return "knocked out of reach"
    down = ep.traces["tip_object_downward"][touching]
    return "presses from above" if down.mean() > PRESSING_DOWN else "touches, never lifts"


# --- the command -------------------------------------------------------------------------------------------------


def diagnose(cfg: DiagnoseConfig) -> dict:
    names = objects.resolve_objects(cfg.objects)
    student = StudentActor.load(cfg.student, names, cfg.device)
    policy, pre = student.policy, fit_preprocessor(student)
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
    for name in tqdm(names, desc="diagnose", disable=not cfg.progress):
        torch.manual_seed(cfg.seed)
        eps = closed_loop(student, name, cfg.episodes, cfg.seed)
        kinds = [failure_kind(ep) for ep in eps]
        row: dict = {
            "successes": [ep.success for ep in eps],
            "kinds": kinds,
            "kind_counts": {k: kinds.count(k) for k in KINDS if kinds.count(k)},
            "max_lift_cm": [round(float(ep.traces["lift"].max()) * 100, 2) for ep in eps],
        }
        if name in train:
            row["fit"] = {"train": imitation_loss(policy, pre, train[name]), "demos": len(train[name])}
            if name in held:
                row["fit"]["held_out"] = imitation_loss(policy, pre, held[name])
                row["fit"]["held_out_episodes"] = len(held[name])
                row["drift"] = _drift(eps, train[name], held[name], std, cfg)
        result["objects"][name] = row
    if cfg.student_eval:
        result["matches_lerobot_eval"] = _check_against_eval(result, cfg.student_eval)
    return result


def _drift(eps: list[Episode], train_eps, held_eps, std, cfg) -> dict:
    cov = Coverage([s for s, _ in train_eps], std, cfg.window)
    out = {}
    for space, dims in SPACES.items():
        held_d = np.concatenate([cov.distance(s[None], dims)[0] for s, _ in held_eps])
        threshold = float(np.percentile(held_d, 99))
        dist = [cov.distance(ep.state[None], dims)[0] for ep in eps]
        steps = [first_run_above(d[None], threshold, cfg.run, np.array([len(d)]))[0] for d in dist]
        out[space] = {
            "threshold": threshold,
            "first_step": [int(s) for s in steps],
            "median_distance": [float(np.median(d)) for d in dist],
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
