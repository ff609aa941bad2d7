"""One single-episode check of the suite, through the command the test runs, with how far it is from flipping:
the lift at every step and the hold margin (the lowest lift of the best 20-step window, less the 1.5 cm success
threshold). NOISE=k scales each action by 1 + 2e-7 x a fixed random sign per component (float32's last bit):
one more stand-in for another CPU's rounding per seed.

    python episode_margin.py teacher cylinder_b_large 1000 OUT   # test_wheel.py's blindgrasp-eval-teacher episode
    python episode_margin.py student cylinder_b_large 1001 OUT   # test_shipped_student.py's lerobot-eval episode
"""

import json
import os
import sys
from pathlib import Path

import numpy as np

from lerobot_blindgrasp import spec

STUDENT = Path(__file__).resolve().parents[3] / "models" / "student_cpu"


def recorder(cls, lift_of, lifts: list, rng):
    """Wrap cls.step: perturb the action (with NOISE) and keep each step's lift."""
    step = cls.step

    def wrapped(self, action, *args, **kwargs):
        if rng is not None:
            action = np.asarray(action) * (1 + 2e-7 * rng.choice([-1.0, 1.0], size=np.shape(action)))
        out = step(self, action, *args, **kwargs)
        lifts.append(lift_of(out[4]))
        return out

    cls.step = wrapped


def run_teacher(obj: str, seed: int, out: str, lifts: list, rng) -> bool:
    from lerobot_blindgrasp.sim.batched_env import BatchedGraspEnv
    from lerobot_blindgrasp.teacher import evaluate

    recorder(BatchedGraspEnv, lambda info: float(info["lift"][0]), lifts, rng)
    evaluate.main(["--episodes=1", f"--objects={obj}", "--modes=deterministic", "--progress=false",
                   f"--seed={seed}", f"--output_dir={out}"])  # fmt: skip
    result = json.loads(Path(out, "eval.json").read_text())
    return result["modes"]["deterministic"]["per_object"][obj]["successes"][0]


def run_student(obj: str, seed: int, out: str, lifts: list, rng) -> bool:
    from lerobot.scripts import lerobot_eval

    from lerobot_blindgrasp.sim.gym_env import BlindGraspGymEnv

    recorder(BlindGraspGymEnv, lambda info: info["lift_m"], lifts, rng)
    sys.argv = ["lerobot-eval", f"--policy.path={STUDENT}", "--env.type=blindgrasp", f"--env.task={obj}",
                "--eval.n_episodes=1", "--eval.batch_size=1", "--policy.device=cpu", "--eval.use_async_envs=false",
                "--env.render_stride=50", f"--output_dir={out}", f"--seed={seed}"]  # fmt: skip
    lerobot_eval.main()
    return json.loads(Path(out, "eval_info.json").read_text())["per_task"][0]["metrics"]["successes"][0]


def main() -> None:
    kind, obj, seed, out = sys.argv[1], sys.argv[2], int(sys.argv[3]), sys.argv[4]
    rng = np.random.default_rng(int(os.environ["NOISE"])) if os.environ.get("NOISE") else None
    lifts: list = []
    success = (run_teacher if kind == "teacher" else run_student)(obj, seed, out, lifts, rng)
    lift = np.array(lifts)
    hold = spec.SUCCESS_HOLD_STEPS
    best = max(lift[i : i + hold].min() for i in range(len(lift) - hold + 1))
    np.save(Path(out, "lift.npy"), lift)
    played = ("NOISE", "MKL_CBWR", "ATEN_CPU_CAPABILITY", "BLINDGRASP_CPU_MODEL")
    print(json.dumps({"env": {k: os.environ[k] for k in played if k in os.environ}, "success": bool(success),
                      "steps": len(lift), "max_lift_cm": round(100 * lift.max(), 4),
                      "hold_margin_cm": round(100 * (best - spec.SUCCESS_LIFT_M), 4)}))  # fmt: skip


if __name__ == "__main__":
    main()
