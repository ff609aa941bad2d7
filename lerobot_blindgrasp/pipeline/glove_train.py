"""`blindgrasp-train-glove`: a student on glove recordings, alone or merged with sim demos, by a named preset.

    blindgrasp-train-glove --preset=glove --glove=[data/glove_s1,data/glove_s2] --output_dir=outputs/glove

Every source is checked for the shared schema (`spec.dataset_features()`, robot type, 20 fps) before anything is
written; sim demos lose their `episode.*` features, the sources are merged and `lerobot-train` trains the preset's
student (`presets/glove.py`). Each dataset is built beside its folder and renamed when complete, so a re-run reuses it.
"""

from __future__ import annotations

import json
import shlex
import subprocess
from dataclasses import dataclass, field
from pathlib import Path

from lerobot_blindgrasp import presets, spec
from lerobot_blindgrasp.cli import parse_config
from lerobot_blindgrasp.pipeline import recipe
from lerobot_blindgrasp.pipeline.stage import console_script
from lerobot_blindgrasp.presets import student as student_presets
from lerobot_blindgrasp.presets.glove import GlovePreset


@dataclass
class GloveTrainConfig:
    # lerobot-record dataset folders (each session's --dataset.root), merged in this order
    glove: list[Path] = field(default_factory=list)
    output_dir: Path | None = None  # where the merged dataset and the student go
    preset: str = "glove"  # a key of presets.glove.GLOVE_PRESETS: glove, sim_plus_glove (and *_smoke for CI)
    # a blindgrasp-collect-demos folder; required by the sim_plus_glove presets, refused by the others
    sim_demos: Path | None = None
    repo_id: str = "local/blindgrasp_glove_train"  # the merged dataset's (a local name; nothing is pushed)
    seed: int = 1000
    device: str | None = None  # lerobot-train --policy.device; None: the preset's (cpu)
    dry_run: bool = False  # print what would run, run nothing

    def __post_init__(self):
        p = presets.get(self.preset, "glove")
        if not self.glove:
            raise ValueError("--glove needs at least one lerobot-record dataset folder, e.g. --glove=[data/glove]")
        if self.output_dir is None:
            raise ValueError("--output_dir is required")
        if p.sim_demos and self.sim_demos is None:
            raise ValueError(
                f"preset {p.name!r} merges sim demos: give --sim_demos=<blindgrasp-collect-demos folder>"
            )
        if not p.sim_demos and self.sim_demos is not None:
            raise ValueError(
                f"preset {p.name!r} trains on glove recordings only; drop --sim_demos or pick "
                "--preset=sim_plus_glove"
            )


def merge_schema_problems(root: Path, extra_ok: tuple[str, ...] = ()) -> list[str]:
    """Why `root` cannot join a merge with the shared schema ([] if it can), from its meta/info.json."""
    info_path = Path(root) / "meta" / "info.json"
    if not info_path.is_file():
        return [f"{root} is not a LeRobotDataset folder (no meta/info.json)"]
    from lerobot_blindgrasp.demos.dataset import check_schema

    info = json.loads(info_path.read_text())
    problems = check_schema(info["features"], info.get("fps"), info.get("robot_type"), spec.dataset_features())
    extra = [k for k, ft in info["features"].items() if k.startswith(("observation.", "action")) and
             k not in spec.dataset_features() and k not in extra_ok]  # fmt: skip
    if extra:
        problems.append(f"extra policy features {extra} (cameras?) that the other sources lack")
    return [f"{root}: {p}" for p in problems]


def _complete(root: Path) -> bool:
    return (root / "meta" / "info.json").is_file()


def sim_without_metadata(sim_root: Path, dest: Path) -> Path:
    """The sim demos without their `episode.*` features (LeRobot's remove_feature), written once."""
    from lerobot.datasets import LeRobotDataset
    from lerobot.datasets.dataset_tools import remove_feature

    from lerobot_blindgrasp.demos.dataset import METADATA_FEATURE_NAMES, built_beside

    if _complete(dest):
        return dest
    ds = LeRobotDataset(f"local/{Path(sim_root).name}", root=sim_root)
    names = [n for n in METADATA_FEATURE_NAMES if n in ds.meta.features]
    if not names:
        return Path(sim_root)  # already in the shared schema
    with built_beside(dest) as tmp:
        remove_feature(ds, names, output_dir=tmp, repo_id=f"local/{dest.name}")
    return dest


def merged(sources: list[Path], dest: Path, repo_id: str) -> Path:
    """One dataset of all `sources` (LeRobot's aggregate_datasets); the source itself if there is one."""
    from lerobot_blindgrasp.demos.dataset import aggregate

    if len(sources) == 1:
        return sources[0]
    if _complete(dest):
        return dest
    aggregate([f"local/{p.name}_{k}" for k, p in enumerate(sources)], sources, repo_id, dest)
    return dest


def train_command(
    p: GlovePreset, dataset: Path, repo_id: str, out: Path, seed: int, device: str | None = None
) -> list[str]:
    """lerobot-train of the preset's student on the merged recordings (the venv's lerobot-train, as run here)."""
    cmd, _ = recipe.lerobot_train(p.student, dataset, repo_id, out, seed, device)
    return [console_script(cmd[0]), *cmd[1:]]


def train_on_glove(cfg: GloveTrainConfig) -> Path:
    """Merge and train; returns the student's checkpoint folder (`.../pretrained_model`)."""
    p = presets.get(cfg.preset, "glove")
    out = Path(cfg.output_dir)
    problems = [q for g in cfg.glove for q in merge_schema_problems(g)]
    if cfg.sim_demos is not None:
        from lerobot_blindgrasp.demos.dataset import METADATA_FEATURE_NAMES

        problems += merge_schema_problems(cfg.sim_demos, extra_ok=METADATA_FEATURE_NAMES)
    if problems:
        raise SystemExit("error: cannot merge:\n  " + "\n  ".join(problems))
    student = out / "student"
    if student.exists() and not cfg.dry_run:
        raise SystemExit(f"error: {student} exists; to go on training use LeRobot's --resume=true "
                         f"--config_path={student}/checkpoints/last/pretrained_model/train_config.json, or pick "
                         "another --output_dir")  # fmt: skip
    sources = [Path(g) for g in cfg.glove] * (p.glove_copies if p.sim_demos else 1)
    plan = [f"glove recordings: {', '.join(map(str, cfg.glove))}" + (f" (x{p.glove_copies})" if p.glove_copies > 1
                                                                          else "")]  # fmt: skip
    if cfg.sim_demos is not None:
        plan.append(f"sim demos: {cfg.sim_demos} without episode.* -> {out / 'sim_schema'}")
    if cfg.dry_run:
        many = len(sources) + (cfg.sim_demos is not None) > 1
        dataset = out / "dataset" if many else Path(cfg.glove[0])
        plan.append(f"merge -> {dataset}" if many else f"train on {dataset}")
        cmd = train_command(p, dataset, cfg.repo_id, student, cfg.seed, cfg.device)
        print("\n".join([*plan, shlex.join(cmd)]))
        return student
    out.mkdir(parents=True, exist_ok=True)
    if cfg.sim_demos is not None:
        sources.insert(0, sim_without_metadata(Path(cfg.sim_demos), out / "sim_schema"))
    dataset = merged(sources, out / "dataset", cfg.repo_id)
    cmd = train_command(p, dataset, cfg.repo_id, student, cfg.seed, cfg.device)
    print("\n".join([*plan, f"[glove-train] {shlex.join(cmd)}"]), flush=True)
    if (rc := subprocess.run(cmd).returncode) != 0:
        raise SystemExit(f"error: lerobot-train failed (exit {rc})")
    steps = student_presets.schedule(p.student, student_presets.dataset_frames(dataset)).steps
    return student / "checkpoints" / f"{steps:06d}" / "pretrained_model"


def main(argv: list[str] | None = None) -> None:
    print(train_on_glove(parse_config(GloveTrainConfig, argv)))


if __name__ == "__main__":
    main()
