"""The run records of a demo collection: provenance (`collection.json`), statistics, the yield report and card.
`start_run` and `finish_run` bracket each run (`--resume=true` adds one), so `collection.json` lists every run however
it ended; a killed run cannot record its end, so `checkpoint_run` keeps `collection.json` current instead.
"""

from __future__ import annotations

import dataclasses
import logging
import shutil
from dataclasses import dataclass, field
from datetime import UTC, datetime
from pathlib import Path

from lerobot_blindgrasp import spec
from lerobot_blindgrasp.cards import dataset_cards
from lerobot_blindgrasp.demos import dataset as demo_dataset
from lerobot_blindgrasp.demos import provenance, yield_report
from lerobot_blindgrasp.demos.config import CollectConfig, CollectError
from lerobot_blindgrasp.sim import objects, randomization

log = logging.getLogger("blindgrasp.demos")


@dataclass
class CollectStats:
    wall_s: float = 0.0
    cpu_s: float = 0.0  # process CPU time, all threads (physics, torch, writer)
    write_s: float = 0.0  # inside LeRobotDataset.save_episode (on the writer thread)
    writer_wait_s: float = 0.0  # the loop waiting for the writer thread (a full queue, the final drain)
    env_steps: int = 0
    rollouts: int = 0
    kept: int = 0
    frames: int = 0
    env_builds: int = 0
    stop_reason: str = ""  # "done" | "interrupted" | "error: ..."
    checkpoints: int = 0  # finalize-and-reopen cycles (demos/crash_checkpoints.py)
    checkpoint_s: float = 0.0  # time they took
    tally: yield_report.Tally = field(default_factory=yield_report.Tally)

    @property
    def demos_per_minute(self) -> float:
        return 60.0 * self.kept / self.wall_s if self.wall_s else 0.0

    @property
    def demos_per_cpu_minute(self) -> float:
        return 60.0 * self.kept / self.cpu_s if self.cpu_s else 0.0


def new_provenance(cfg: CollectConfig, teacher, object_names, dr: randomization.DomainRandomization) -> dict:
    return {
        "format": provenance.FORMAT,
        "teacher_sha256": teacher.sha256,
        "teacher": {
            "checkpoint": str(teacher.checkpoint),
            "checkpoint_name": teacher.name,
            "sha256": teacher.sha256,
            "iteration": teacher.iteration,
            "preset": teacher.config.get("preset"),
            "variant": teacher.config.get("variant"),
            "reward": teacher.config.get("reward"),
            "deviations": teacher.config.get("deviations", []),
        },
        "stochastic": cfg.stochastic,
        "curation": cfg.curation.to_dict(),
        "randomization": dataclasses.asdict(dr),
        "objects": list(object_names),
        "robot_type": demo_dataset.ROBOT_TYPE,
        "next_env_seed": cfg.seed,
        "runs": [],
    }


def open_dataset(cfg: CollectConfig, prov_new: dict):
    """Create the dataset folder, or reopen it for --resume after checking it was collected alike.
    Returns (dataset, provenance, tally)."""
    out = cfg.output_dir
    if not cfg.resume or empty_leftover(out):
        if cfg.resume:  # killed between LeRobot's create and the first collection.json: nothing to keep
            log.warning(
                "--resume: %s holds no episode and no collection.json (a run killed while starting); "
                "starting it afresh",
                out,
            )
            shutil.rmtree(out)
        ds = demo_dataset.create(out, cfg.repo_id)
        provenance.save_provenance(out, prov_new)
        return ds, prov_new, yield_report.Tally()
    prov = provenance.load_provenance(out)
    bad = provenance.mismatches(prov, prov_new)
    if bad:
        raise CollectError(f"--resume: {out} was collected with different {', '.join(bad)}; use a new output_dir")
    _repair(out)
    try:
        ds = demo_dataset.resume(out, cfg.repo_id)
    except (ValueError, FileNotFoundError) as e:
        raise CollectError(f"--resume: {e}") from None
    tally = yield_report.load_tally(out)
    last = prov["runs"][-1] if prov["runs"] else {}
    if last.get("stop_reason") == RUNNING:  # the previous run was killed: its last checkpoint has the newest tally
        last["stop_reason"], last["interrupted"] = "killed (resumed from its last checkpoint)", True
        if "tally" in last:
            tally = yield_report.Tally.from_json(last.pop("tally"))
        provenance.save_provenance(out, prov)
    _existing_counts(out, tally)
    return ds, prov, tally


def empty_leftover(out: Path) -> bool:
    """A folder that a collection killed while starting left behind: no collection.json, no data file."""
    return out.is_dir() and not provenance.is_collection(out) and not any((out / "data").rglob("*.parquet"))


def _repair(out: Path) -> None:
    """A crashed collection's folder back to its last checkpoint, saying what was kept and lost."""
    from lerobot_blindgrasp.demos import rebuild_meta, repair

    try:
        result = repair.repair(out)
    except rebuild_meta.RebuildError as e:
        raise CollectError(f"--resume: {e}") from None
    if result.changed:
        log.warning("--resume: the dataset was left unfinished by a crash; repaired it:\n%s", result.summary())


def _existing_counts(root: Path, tally: yield_report.Tally) -> None:
    """Kept episodes and frames per object, from the dataset itself (authoritative after a crash)."""
    for o in tally.objects.values():
        o.kept, o.frames = 0, 0
    try:
        table = demo_dataset.episode_table(root)
    except FileNotFoundError:  # no episode written yet (or none survived a crash)
        return
    for name, group in table.groupby("object"):
        t = tally.of(name)
        t.kept, t.frames = len(group), int(group["length"].sum())


def start_run(cfg: CollectConfig, prov: dict, command: str | None) -> dict:
    return {
        "command": command or f"collect(repo_id={cfg.repo_id!r})",
        "started": datetime.now(UTC).isoformat(timespec="seconds"),
        "episodes_per_object": cfg.episodes_per_object,
        "max_rollouts_per_object": cfg.rollout_budget,
        "num_envs": cfg.num_envs,
        "backend": cfg.backend,
        "seed_start": prov["next_env_seed"],
    }


RUNNING = "running"  # the stop_reason of a run in progress; still there after a kill


def checkpoint_run(
    cfg: CollectConfig, prov: dict, run: dict, tally: yield_report.Tally, stats: CollectStats
) -> None:
    """Save collection.json with this run in progress and the tally that goes with the dataset on disk now."""
    record = {**_run_outcome(run, stats, RUNNING), "tally": tally.to_json()}
    provenance.save_provenance(cfg.output_dir, {**prov, "runs": [*prov["runs"], record]})


def _run_outcome(run: dict, stats: CollectStats, stop_reason: str) -> dict:
    return {
        **run,
        "ended": datetime.now(UTC).isoformat(timespec="seconds"),
        "stop_reason": stop_reason,
        "interrupted": stop_reason != "done",
        "wall_s": stats.wall_s,
        "cpu_s": stats.cpu_s,
        "rollouts": stats.rollouts,
        "kept": stats.kept,
        "frames": stats.frames,
        "env_steps": stats.env_steps,
    }


def finish_run(cfg: CollectConfig, prov: dict, run: dict, tally: yield_report.Tally, stats: CollectStats) -> None:
    """Record the run (however it ended) in collection.json, then rewrite the yield report and the card."""
    out = cfg.output_dir
    run.update(_run_outcome(run, stats, stats.stop_reason))
    prov["runs"].append(run)
    provenance.save_provenance(out, prov)
    _write_report(out, cfg, prov, tally)
    try:
        dataset_cards.write_card(out, cfg.repo_id, sim_card_kwargs(out, cfg.repo_id))
    except Exception as e:  # noqa: BLE001  (a card problem must not mask the collection's outcome)
        log.warning("could not write the dataset card: %s", e)


def _write_report(out: Path, cfg: CollectConfig, prov: dict, tally: yield_report.Tally) -> Path:
    runs = prov["runs"]
    wall, cpu, kept = (sum(r[k] for r in runs) for k in ("wall_s", "cpu_s", "kept"))
    return yield_report.write_yield_report(
        out,
        tally,
        {
            "repo_id": cfg.repo_id,
            "teacher_sha256": prov["teacher_sha256"],
            "stochastic": prov["stochastic"],
            "curation": prov["curation"],
            "episodes_per_object": cfg.episodes_per_object,
            "max_rollouts_per_object": cfg.rollout_budget,
            "runs": len(runs),
            "wall_s": wall,
            "cpu_s": cpu,
            "demos_per_minute": 60.0 * kept / wall if wall else 0.0,
            "demos_per_cpu_minute": 60.0 * kept / cpu if cpu else 0.0,
            "object_order": list(prov["objects"]),
        },
    )


def _sim_context(root: Path, repo_id: str, meta) -> dict:
    """The card's template context, from the collection's own records."""
    prov = provenance.load_provenance(root)
    tally = yield_report.load_tally(root)
    rows = []
    for name in prov["objects"]:
        o = tally.of(name)
        rows.append({"name": name, "task": objects.get_object(name).task, "yield": o.yield_rate, **vars(o)})
    total = tally.total()
    return {
        **dataset_cards.dataset_fields(repo_id, meta),
        "objects": rows,
        "total": {"yield": total.yield_rate, **vars(total)},
        "stochastic": prov["stochastic"],
        "curation": prov["curation"],
        "teacher": prov["teacher"],
        "randomization": dataset_cards.randomization_rows(prov["randomization"]),
        "runs": prov["runs"],
        "state_names": list(spec.STATE_NAMES),
        "action_names": list(spec.ACTION_NAMES),
        "metadata_features": demo_dataset.EPISODE_FEATURES,
        "merge_hint": demo_dataset.MERGE_HINT.format(
            repo_id=repo_id, root="<root>", names=list(demo_dataset.METADATA_FEATURE_NAMES)
        ),
        **dataset_cards.versions(),
    }


def sim_card_kwargs(root: Path, repo_id: str, **kw) -> dict:
    """`dataset_cards.card_kwargs` of the collection in `root`."""
    from lerobot.datasets.dataset_metadata import LeRobotDatasetMetadata

    meta = LeRobotDatasetMetadata(repo_id, root=Path(root))
    return dataset_cards.card_kwargs(repo_id, "sim", _sim_context(Path(root), repo_id, meta), meta, **kw)
