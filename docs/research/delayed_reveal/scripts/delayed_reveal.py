"""A blind-approach teacher whose object reveal comes DELAY control steps after the touch, not at it.

Why (docs/research/student_gap.md, "The blind teacher's student"): the shipped blind teacher sees the object's pose the
moment a load cell reads above 2 N and acts on it at once; its student can tell the small capsule from the small
sphere only from the step after. Here the actor's object inputs stay hidden until a load cell has read above
TOUCH_N for more than DELAY consecutive steps, so the teacher's first DELAY touching steps cannot depend on the object.

The mask needs per-env state (a count of touching steps). An env's first step is recognised by its previous action
being exactly 0 (the env zeroes it on reset; a policy's delta is never exactly 0 on all 9 joints), so the same mask
works in rsl-rl's training loop, in blindgrasp-collect-demos and in the episode loop below, all of which auto-reset
or reset without telling the policy.

    python delayed_reveal.py eval TEACHER DELAY OBJECTS OUT.json          the teacher with the delayed mask
    python delayed_reveal.py train OUT_DIR START.pt ITERATIONS DELAY [ARGS]   PPO fine-tune from a blind teacher run
    python delayed_reveal.py collect DELAY <blindgrasp-collect-demos arguments>
"""

# Recorded experiment code: it patches the package's stateless mask of commit 1409010, which the package has since
# replaced by this very recipe (teacher preset cpu_bc_blind_reveal6 (blind_approach.ActorInput(reveal_delay_steps=6))). Re-run it as recorded from that commit (`git checkout 1409010`).
from lerobot_blindgrasp.teacher import blind_approach as _pkg  # noqa: E402

if not hasattr(_pkg, "with_blind_group"):
    raise SystemExit(f"{__file__} ran at commit 1409010; the package now does this: teacher preset cpu_bc_blind_reveal6 (blind_approach.ActorInput(reveal_delay_steps=6))")

import shutil
import sys
from pathlib import Path

import numpy as np
import torch

sys.path.insert(0, str(Path(__file__).resolve().parents[2] / "student_gmm" / "scripts"))
from episodes import every_object  # noqa: E402  (the shared episode loop of the student_gmm scripts)

from lerobot_blindgrasp import spec  # noqa: E402
from lerobot_blindgrasp.teacher import blind_approach  # noqa: E402

_PREV = spec.PRIVILEGED_SLICES["previous_action"]


class DelayedMask:
    """`blind_approach.with_blind_group` with the reveal DELAY steps after the touch (stateful, one batch)."""

    def __init__(self, delay: int, always_hidden: np.ndarray | None = None):
        self.delay, self.count, self.last, self.out = delay, None, None, None
        self.always_hidden = np.array([], dtype=int) if always_hidden is None else always_hidden  # columns hidden all episode

    def mask(self, priv: np.ndarray) -> np.ndarray:
        if self.last is not None and priv.shape == self.last.shape and np.array_equal(priv, self.last):
            return self.out.copy()  # the same observation asked for twice: do not count it twice
        if self.count is None or len(self.count) != len(priv):
            self.count = np.zeros(len(priv), dtype=int)
        self.count[(priv[:, _PREV] == 0.0).all(axis=1)] = 0  # an env's first step
        touched = (priv[:, blind_approach._UNIAXIAL] >= blind_approach.TOUCH_N).any(axis=1)
        self.count = np.where(touched, self.count + 1, 0)
        out = np.array(priv, copy=True)
        out[np.ix_(self.count <= self.delay, blind_approach._HIDDEN_COLUMNS)] = 0.0
        out[:, self.always_hidden] = 0.0
        self.last, self.out = np.array(priv, copy=True), out
        return out.copy()

    def with_blind_group(self, obs: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
        return {**obs, blind_approach.GROUP: self.mask(obs["privileged"])}


def install(delay: int, always_hidden: np.ndarray | None = None) -> DelayedMask:
    """Route every caller of the package's mask (rsl-rl env adapter, TeacherPolicy) through a DelayedMask."""
    from lerobot_blindgrasp.teacher import vecenv

    m = DelayedMask(delay, always_hidden)
    blind_approach.with_blind_group = m.with_blind_group
    vecenv.with_blind_group = m.with_blind_group
    return m


def evaluate(folder: str, delay: int, which: str, out: str) -> None:
    from lerobot_blindgrasp.teacher.policy import TeacherPolicy

    torch.set_num_threads(1)
    install(delay)
    every_object(which, TeacherPolicy(folder), out)


def train(out: Path, start: Path, iterations: int, delay: int, extra: list[str]) -> None:
    """PPO continues a cpu_bc_blind_approach run from START (model_N.pt) for ITERATIONS more, with the delayed mask."""
    import dataclasses

    from lerobot_blindgrasp.presets import teacher as presets
    from lerobot_blindgrasp.teacher import train as trainer

    install(delay)
    first = int(start.stem.split("_")[1])
    base = presets.CPU_BC_BLIND_APPROACH
    preset = dataclasses.replace(
        base, name=f"cpu_bc_blind_reveal{delay}", max_iterations=first + 1 + iterations, continues=None,
        deviations=base.deviations + (f"from iteration {first + 1}, the object is revealed {delay} steps after the "
                                      "touch (a load cell above 2 N for more than that many consecutive steps)",),
    )
    presets.PRESETS[preset.name] = preset
    out.mkdir(parents=True, exist_ok=True)
    if not list(out.glob("model_*.pt")):
        shutil.copy(start, out / (start.name + ".tmp"))
        shutil.move(out / (start.name + ".tmp"), out / start.name)
    trainer.main([f"--output_dir={out}", f"--preset={preset.name}", "--threads=2", *extra])


if __name__ == "__main__":
    cmd = sys.argv[1]
    if cmd == "eval":
        evaluate(sys.argv[2], int(sys.argv[3]), sys.argv[4], sys.argv[5])
    elif cmd == "train":
        train(Path(sys.argv[2]), Path(sys.argv[3]), int(sys.argv[4]), int(sys.argv[5]), sys.argv[6:])
    elif cmd == "collect":
        from lerobot_blindgrasp.demos.collect import main

        install(int(sys.argv[2]))
        main(sys.argv[3:])
