"""Student presets for glove recordings (`lerobot-record` on the real gripper), alone or merged with sim demos, for
`blindgrasp-train-glove --preset=NAME`; the `*_smoke` ones are the same plumbing at CI size. Settings only: no real
glove recordings exist in this repository. Sizes: 20 ten-second episodes per object are 4000 frames, against the
quick sim preset's 72,000, so `glove` counts epochs (as Table IV) and `sim_plus_glove` trains `cpu`'s 5000 steps.
"""

from __future__ import annotations

from dataclasses import dataclass

from lerobot_blindgrasp.presets.student import StudentStage


@dataclass(frozen=True, kw_only=True)
class GlovePreset:
    name: str
    student: StudentStage
    sim_demos: bool  # True: the glove recordings are merged with a sim demo set (--sim_demos)
    # How many copies of the glove episodes go into a merge with sim demos: LeRobot's sampler draws every frame
    # equally often, so copies are how a small real set keeps a share of the batches. 1: no oversampling.
    glove_copies: int = 1
    deviations: tuple[str, ...] = ()

    def __post_init__(self):
        if self.glove_copies < 1:
            raise ValueError(f"preset {self.name!r}: glove_copies must be >= 1")
        if self.glove_copies > 1 and not self.sim_demos:
            raise ValueError(f"preset {self.name!r}: copies only change the mix of a merge with sim demos")


_BEYOND = "beyond the paper, which trains its student on simulated demonstrations only"

GLOVE_PRESETS: dict[str, GlovePreset] = {
    p.name: p
    for p in (
        GlovePreset(
            name="glove",
            # 300 passes over ~4000 frames at batch 64 is ~19,000 steps; LR constant for the first tenth.
            student=StudentStage(size="cpu", batch_size=64, epochs=300, constant_lr_epochs=30, num_workers=1),
            sim_demos=False,
            deviations=(
                f"{_BEYOND}: a student on glove teleoperation of the real gripper",
                "300 epochs at batch 64 (Table IV: 2000 at 256, for 89,500 demos): the set is small",
            ),
        ),
        GlovePreset(
            name="sim_plus_glove",
            # The `cpu` preset's student stage on the merge; each glove episode enters 5 times (20 per object ->
            # 100, next to 40-100 curated sim episodes per object).
            student=StudentStage(size="cpu", batch_size=256, steps=5_000, num_workers=1),
            sim_demos=True,
            glove_copies=5,
            deviations=(
                f"{_BEYOND}: sim demos merged with glove teleoperation of the real gripper",
                "the glove episodes enter the merge 5 times (oversampled)",
            ),
        ),
        GlovePreset(
            name="glove_smoke",
            student=StudentStage(size="quick", batch_size=4, steps=4),
            sim_demos=False,
            deviations=("CI plumbing: 4 steps",),
        ),
        GlovePreset(
            name="sim_plus_glove_smoke",
            student=StudentStage(size="quick", batch_size=4, steps=4),
            sim_demos=True,
            glove_copies=2,
            deviations=("CI plumbing: 4 steps",),
        ),
    )
}
