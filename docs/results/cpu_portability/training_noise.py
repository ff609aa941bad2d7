"""The golden training setting (tests/golden_sim.py: Table II's pushes, 18 envs, two 4 s episodes each) under
float-noise stand-ins: the teacher's actions scaled by 1 + 2e-7 x a fixed random sign per component, one seed per
stand-in. Prints which episodes succeed and at which step each success latched, against the plain run, and each
episode's hold margin (lowest lift of its best 20-step window less the 1.5 cm threshold).

    python docs/results/cpu_portability/training_noise.py 12
"""

import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[3] / "tests"))
import golden_sim as g  # noqa: E402

from lerobot_blindgrasp import spec  # noqa: E402
from lerobot_blindgrasp.teacher import policy  # noqa: E402

PLAIN = policy.TeacherPolicy.__call__


def training_run(seed: int) -> dict:
    rng = np.random.default_rng(seed)

    def noisy(self, obs, stochastic=False):
        action = PLAIN(self, obs, stochastic)
        return action * (1 + 2e-7 * rng.choice([-1.0, 1.0], size=action.shape)) if seed else action

    policy.TeacherPolicy.__call__ = noisy
    try:
        return g.rollouts(settings=("training",))["training"]
    finally:
        policy.TeacherPolicy.__call__ = PLAIN


def margins(run: dict) -> list[list[float]]:
    """Per env, per ended episode: the hold margin in cm."""
    hold, out = spec.SUCCESS_HOLD_STEPS, []
    for i in range(run["done"].shape[1]):
        lifts = [run["lift"][a : b + 1, i] for a, b in g._episodes(run["done"][:, i])]
        best = [max(x[j : j + hold].min() for j in range(len(x) - hold + 1)) for x in lifts]
        out.append([round(float(100 * (b - spec.SUCCESS_LIFT_M)), 2) for b in best])
    return out


def latched(run: dict) -> set:
    s = run["success"]
    return {tuple(x) for x in np.argwhere(s & ~np.vstack([np.zeros_like(s[:1]), s[:-1]])).tolist()}


def main() -> None:
    base = training_run(0)
    flags, m = g.exact(base, "training")["episode_successes"], margins(base)
    ok = [x for f, mm in zip(flags, m, strict=True) for s, x in zip(f, mm, strict=True) if s]
    bad = [x for f, mm in zip(flags, m, strict=True) for s, x in zip(f, mm, strict=True) if not s]
    print(f"plain: {g.successful_episodes(base)} successful; hold margin of the weakest success {min(ok)} cm, "
          f"of the strongest failure {max(bad)} cm; peak lift of each failure (cm):",
          [round(float(100 * base["lift"][a : b + 1, i].max()), 2) for i in range(18)
           for (a, b), s in zip(g._episodes(base["done"][:, i]), flags[i], strict=True) if not s])  # fmt: skip
    for seed in range(1, int(sys.argv[1]) + 1):
        run = training_run(seed)
        same = g.exact(run, "training") == g.exact(base, "training")
        moved = sorted(latched(run) ^ latched(base))
        print(
            f"noise {seed}: {g.successful_episodes(run)} successful; every exact quantity as plain: {same}; "
            f"success latch steps (step, env) that moved: {moved or 'none'}",
            flush=True,
        )


if __name__ == "__main__":
    main()
