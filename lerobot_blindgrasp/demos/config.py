"""What a demo collection is asked to do: `CollectConfig`, the draccus config of `blindgrasp-collect-demos`."""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field
from pathlib import Path

from lerobot_blindgrasp import spec
from lerobot_blindgrasp.demos import curation as curation_mod
from lerobot_blindgrasp.sim import objects as objects_mod
from lerobot_blindgrasp.sim.backends import check_backend

DEFAULT_ROLLOUT_BUDGET_FACTOR = 20


class CollectError(Exception):
    """A problem found before anything was written (bad teacher, existing output, incompatible resume)."""


@dataclass
class CollectConfig:
    """Roll out a trained teacher, curate its episodes and write a LeRobotDataset (paper Sec. III-C).

    Ablations: --stochastic=false (teacher mean: "w/o stochastic teacher"), --curation.enabled=false ("w/o
    curation"). --curation.trim_to_success=true ends kept episodes where the curation criteria are first met.
    """

    # teacher folder (teacher.safetensors, or a training run dir: its latest model_<it>.pt) or checkpoint file;
    # default: the shipped teacher
    teacher: Path | None = None
    output_dir: Path | None = None  # dataset folder to create (must not exist unless --resume=true)
    repo_id: str | None = None  # USER/NAME, the dataset's Hub id
    episodes_per_object: int = 20  # episodes to write per object
    max_rollouts_per_object: int | None = None  # rollout budget per object (default 20 x episodes_per_object)
    objects: str = "all"  # 'all', 'medium' or a comma list of catalogue names
    stochastic: bool = True  # sample the teacher's Gaussian; false: its mean ('w/o stochastic teacher' ablation)
    curation: curation_mod.CurationConfig = field(default_factory=curation_mod.CurationConfig)
    # Beyond the paper: roll out with every joint reading off by +-this (rad; sign per env and joint, as
    # the robustness sweep's calibration factor) so that the demos show the teacher correcting for it. The actions
    # are recorded in the measured frame, as a gripper homed off by that much is commanded. 0: the paper's demos.
    joint_calibration_rad: float = 0.0
    num_envs: int = 180  # parallel envs (18 objects x 10)
    # first env seed, in spec.SEED_RANGES["demos"] (a resumed run continues after the last)
    seed: int = spec.DEMO_SEED
    threads: int = 0  # physics threads (0: all CPUs)
    # physics: batch (mujoco.batch, CPU) or warp (MuJoCo Warp on this process's GPU, else its CPU device;
    # pip install .[gpu]). The same task, draws and curation either way.
    backend: str = "batch"
    resume: bool = False  # append to output_dir until the targets are met (repairs a crashed one first)
    # Crash safety: the dataset is finalized and reopened (LeRobot rolls to fresh parquet files) at least every
    # checkpoint_s seconds and every num_envs written episodes, so a kill loses at most that much. 0: only at the
    # end (a kill then loses every episode of the run).
    checkpoint_s: float = 60.0
    # Kept episodes waiting for the writer thread, which saves them off the rollout loop; the loop waits only when
    # this many are queued (about 15 kB each). Envs finish their episodes together, so a queue as long as the kept
    # share of num_envs never stalls the loop. A kill loses the queued ones too. 0: save in the loop.
    writer_queue: int = 256
    progress: bool = True  # progress bar

    def __post_init__(self):
        if self.output_dir is None:
            raise ValueError("--output_dir is required (the dataset folder to create)")
        if self.repo_id is None:
            raise ValueError("--repo_id is required (USER/NAME, the dataset's Hub id)")
        self.output_dir = Path(self.output_dir)
        check_backend(self.backend)  # a clear error before the teacher is loaded
        if not 0 <= self.joint_calibration_rad < 0.5:
            raise ValueError(
                "--joint_calibration_rad is a reading offset in rad, >= 0 and well under a joint's range"
            )
        if self.writer_queue < 0:
            raise ValueError("--writer_queue must be >= 0 (0: save each episode in the rollout loop)")
        if self.checkpoint_s < 0:
            raise ValueError("--checkpoint_s must be >= 0 (0: finalize only at the end)")
        if not self.curation.enabled and self.curation.trim_to_success:
            # Nothing is trimmed without curation; one spelling in the provenance, so --resume compares alike.
            self.curation = dataclasses.replace(self.curation, trim_to_success=False)

    @property
    def rollout_budget(self) -> int:
        return self.max_rollouts_per_object or DEFAULT_ROLLOUT_BUDGET_FACTOR * self.episodes_per_object

    @property
    def object_names(self) -> tuple[str, ...]:
        """The catalogue names `objects` stands for (ValueError for unknown ones)."""
        return objects_mod.resolve_objects(self.objects)
