"""The collection loop: teacher rollouts -> curation -> dataset episodes, until every object has its quota (paper
Sec. III-C: the paper's randomization without pushes, the teacher's Gaussian or its mean, 5 s episodes). An object
stops at `episodes_per_object` written episodes or `max_rollouts_per_object` rollouts, so one the teacher cannot
lift never stalls the run. Kept episodes and crash checkpoints go through one writer thread in order. A first
SIGINT/SIGTERM stops after the current step, a second at once; either way the queued episodes are written, the
dataset finalized and the run recorded.
"""

from __future__ import annotations

import contextlib
import dataclasses
import functools
import logging
import sys
import time
from collections.abc import Callable

from lerobot_blindgrasp import compat, durable, spec
from lerobot_blindgrasp.cli import GracefulStop
from lerobot_blindgrasp.demos import crash_checkpoints as checkpoint_mod
from lerobot_blindgrasp.demos import curation as curation_mod
from lerobot_blindgrasp.demos import dataset as demo_dataset
from lerobot_blindgrasp.demos import provenance, records, yield_report
from lerobot_blindgrasp.demos.config import CollectConfig, CollectError
from lerobot_blindgrasp.demos.episode_writer import EpisodeWriter
from lerobot_blindgrasp.demos.records import CollectStats
from lerobot_blindgrasp.project import REPO_ID_PATTERN
from lerobot_blindgrasp.rollout.actors import TeacherActor
from lerobot_blindgrasp.rollout.envs import make_batched_env
from lerobot_blindgrasp.rollout.loop import Episode, stream
from lerobot_blindgrasp.sim import randomization

logger = logging.getLogger(__name__)

# Rebuild the env for the remaining objects once this fraction of envs holds finished objects: a rebuild drops the
# other envs' running episodes and costs ~1 s, waiting wastes this fraction of every step until the next one is done.
REBUILD_WASTE_FRACTION = 0.25

# What a demo episode keeps of each step: o_t, the commanded targets, r_t and the forces (for curation).
DEMO_TRACES = ("state", "action", "task_reward", "uniaxial_force")

STOP_NOTE = "finishing this step and finalizing the dataset (again to abort now; written episodes stay readable)"

# Called after every finished rollout with (episode, its curation result, kept?, stats); the curation result is
# None when the physics failed. A kept episode is queued for the writer thread, on disk by the end of the run.
EpisodeCallback = Callable[[Episode, "curation_mod.CurationResult | None", bool, CollectStats], None]


def _check_inputs(cfg: CollectConfig):
    """Everything that can be refused before touching the output folder. Returns (teacher, object names)."""
    from lerobot_blindgrasp.teacher.policy import TeacherError, TeacherPolicy, default_teacher

    if not REPO_ID_PATTERN.match(cfg.repo_id):
        raise CollectError(f"--repo_id must look like USER/NAME, got {cfg.repo_id!r}")
    if cfg.episodes_per_object < 1:
        raise CollectError("--episodes_per_object must be >= 1")
    if cfg.num_envs < 1:
        raise CollectError("--num_envs must be >= 1")
    try:
        spec.check_seeds("demos", cfg.seed, cfg.num_envs)
    except ValueError as e:
        raise CollectError(f"--seed: {e}") from None
    try:
        object_names = cfg.object_names
    except ValueError as e:
        raise CollectError(str(e)) from None
    out = cfg.output_dir
    if cfg.resume:
        if not out.is_dir():
            raise CollectError(f"--resume: {out} does not exist; drop --resume to start a new dataset")
        if not provenance.is_collection(out) and not records.empty_leftover(out):
            raise CollectError(f"--resume: {out} was not written by blindgrasp-collect-demos (no collection.json)")
    elif out.exists():
        raise CollectError(f"{out} already exists; pass --resume=true to append to it, or a new --output_dir")
    source = cfg.teacher
    try:
        if source is None:
            source = default_teacher()
        teacher = TeacherPolicy(source)
    except TeacherError as e:
        raise CollectError(f"cannot load the teacher: {e}") from None
    except (KeyError, RuntimeError, ValueError) as e:
        raise CollectError(f"cannot load the teacher from {source}: {e}") from None
    return teacher, object_names


def collect_demos(
    cfg: CollectConfig, on_episode: EpisodeCallback | None = None, *, command: str | None = None
) -> CollectStats:
    """Run a collection. Raises CollectError (nothing touched) for bad inputs; any later exception propagates
    after the dataset is finalized and the run is recorded. `command` is recorded as the run's command line."""
    with compat.atomic_lerobot_metadata():  # LeRobot's info/stats/tasks files, atomically
        return _collect(cfg, on_episode, command)


def _collect(cfg: CollectConfig, on_episode: EpisodeCallback | None, command: str | None) -> CollectStats:
    import datasets

    run = _Run(cfg, on_episode, command)
    # `datasets` draws a progress bar for every map LeRobot runs while saving; one per episode is noise here.
    bars_were_off = datasets.are_progress_bars_disabled()
    datasets.disable_progress_bars()
    try:
        with GracefulStop(STOP_NOTE) as stop:
            while stop.requested is None:
                todo = [n for n in run.object_names if not run.done(n)]
                if not todo:
                    run.stats.stop_reason = "done"
                    break
                run.one_env(todo, stop)
            else:
                run.stats.stop_reason = "interrupted"
                run.note_queued()
            run.writer.flush()  # a write error ends the run here, as it would have in the loop
    except BaseException as e:
        run.stats.stop_reason = (
            "interrupted" if isinstance(e, KeyboardInterrupt) else f"error: {type(e).__name__}: {e}"
        )
        raise
    finally:
        try:  # the error that ended the run, if any: a cleanup failure must not mask it
            run.finish(sys.exc_info()[1])
        finally:  # after the queued saves
            if not bars_were_off:
                datasets.enable_progress_bars()
    return run.stats


class _Run:
    """One run of a collection: its dataset, provenance, tally and statistics, and the teacher rolling out."""

    def __init__(self, cfg: CollectConfig, on_episode: EpisodeCallback | None, command: str | None):
        import torch
        from tqdm import tqdm

        from lerobot_blindgrasp.sim import rewards

        self.cfg, self.on_episode = cfg, on_episode
        teacher, self.object_names = _check_inputs(cfg)
        try:  # the teacher's own reward settings: r_t must be the task reward it was trained on
            self.reward_cfg = rewards.RewardConfig.from_record(teacher.config["reward"])
        except (KeyError, TypeError) as e:
            raise CollectError(f"teacher config has no usable reward settings: {e}") from None
        self.teacher = TeacherActor(teacher, stochastic=cfg.stochastic)
        self.dr = dataclasses.replace(randomization.EVAL_DR, joint_calibration_rad=cfg.joint_calibration_rad)
        ds, self.prov, self.tally = records.open_dataset(
            cfg, records.new_provenance(cfg, teacher, self.object_names, self.dr)
        )
        self.stats = CollectStats(tally=self.tally)
        self.run = records.start_run(cfg, self.prov, command)
        self.t_wall, self.t_cpu = time.perf_counter(), time.process_time()
        self.saved = checkpoint_mod.Checkpoints(
            ds, cfg.output_dir, cfg.repo_id, cfg.checkpoint_s, cfg.num_envs, self.record_checkpoint
        )
        # Everything that touches the dataset or collection.json runs on it, in order.
        self.writer = EpisodeWriter(cfg.writer_queue)
        torch.manual_seed(self.prov["next_env_seed"])  # the stochastic teacher's samples
        target = cfg.episodes_per_object
        self.bar = tqdm(
            total=target * len(self.object_names),
            initial=sum(min(self.tally.of(n).kept, target) for n in self.object_names),
            desc="demos",
            unit="ep",
            dynamic_ncols=True,
            disable=not cfg.progress,
        )

    def done(self, name: str) -> bool:
        o = self.tally.of(name)
        return o.kept >= self.cfg.episodes_per_object or o.rollouts >= self.cfg.rollout_budget

    def snapshot(self) -> _Counts:
        """The run's counts now: a checkpoint taken after the episodes submitted so far records these."""
        tally = yield_report.Tally({k: dataclasses.replace(o) for k, o in self.tally.objects.items()})
        return _Counts(dict(self.prov), tally, dataclasses.replace(self.stats, tally=tally))

    def record_checkpoint(self, counts: _Counts) -> None:
        """collection.json with the run in progress (on the writer thread, after the episodes `counts` counts)."""
        counts.stats.wall_s = time.perf_counter() - self.t_wall
        counts.stats.cpu_s = time.process_time() - self.t_cpu
        records.checkpoint_run(self.cfg, counts.prov, self.run, counts.tally, counts.stats)

    def write(self, ep: Episode, cut: curation_mod.CurationResult, counts: _Counts) -> None:
        """One kept episode into the dataset (on the writer thread), then a checkpoint if one is due."""
        t0 = time.perf_counter()
        demo_dataset.write_episode(self.saved.ds, ep, cut)
        self.stats.write_s += time.perf_counter() - t0
        self.saved.written(counts)

    def one_env(self, todo: list[str], stop: GracefulStop) -> None:
        """Envs for the objects still short of demos, rolled out until the run stops or enough of them are done."""
        cfg, prov, stats = self.cfg, self.prov, self.stats
        spec.check_seeds("demos", prov["next_env_seed"], cfg.num_envs)  # a long --resume stays in range
        env = make_batched_env(
            "demos",
            tuple(todo),
            num_envs=cfg.num_envs,
            seed=prov["next_env_seed"],  # env i: seed + i
            dr=self.dr,
            episode_s=cfg.curation.episode_s,
            reward=self.reward_cfg,
            nthread=cfg.threads,
            backend=cfg.backend,
        )
        prov["next_env_seed"] += cfg.num_envs  # later envs (and --resume) never repeat a draw
        # On disk before any episode of these envs is: a resume after a kill never repeats their draws.
        self.writer.submit(functools.partial(self.record_checkpoint, self.snapshot()))
        stats.env_builds += 1
        stale = {"now": False}

        def act(obs, env):
            stats.env_steps += env.num_envs
            return self.teacher(obs, env)

        for ep in stream(env, act, lambda: stop.requested is not None or stale["now"], record=DEMO_TRACES):
            cut, kept = _handle_episode(ep, cfg.curation, self.tally, stats, cfg.episodes_per_object, self.bar)
            if kept:
                with stop.saving():  # --writer_queue=0 saves right here; a save is never cut short
                    self.writer.submit(functools.partial(self.write, ep, cut, self.snapshot()))
            if self.on_episode is not None:
                self.on_episode(ep, cut, kept, stats)
            if self.done(ep.object_name):
                finished = sum(self.done(n) for n in env.object_names)
                stale["now"] = finished >= REBUILD_WASTE_FRACTION * len(env.object_names)
        env.close()

    def note_queued(self) -> None:
        if self.writer.pending:
            logger.warning("writing the %d queued episodes (Ctrl-C to drop them)", self.writer.pending)

    def finish(self, first: BaseException | None) -> None:
        """Write what is queued, finalize the dataset and record the run, however it ended; `first` is the error
        that ended it."""
        self.bar.close()
        if isinstance(first, KeyboardInterrupt):
            self.note_queued()
        try:
            with _cleanup("writing the queued episodes", first):
                self.writer.close()  # an interrupted run keeps every episode it finished
        except BaseException as e:  # a Ctrl-C while the queue is written, or a write error the loop did not see
            if first is None:
                interrupted = isinstance(e, KeyboardInterrupt)
                self.stats.stop_reason = "interrupted" if interrupted else f"error: {type(e).__name__}: {e}"
                first = e
            raise
        finally:
            with _cleanup("finalizing the dataset", first):  # footers written: every saved episode is readable
                compat.finalize_or_abandon(self.saved.ds)
            self.stats.wall_s = time.perf_counter() - self.t_wall
            self.stats.cpu_s = time.process_time() - self.t_cpu
            self.stats.checkpoints, self.stats.checkpoint_s = self.saved.count, self.saved.seconds
            self.stats.writer_wait_s = self.writer.wait_s
            with _cleanup("recording the run", first):
                records.finish_run(self.cfg, self.prov, self.run, self.tally, self.stats)


@dataclasses.dataclass
class _Counts:
    """A copy of the run's provenance, tally and statistics, for a checkpoint taken later on the writer thread."""

    prov: dict
    tally: yield_report.Tally
    stats: CollectStats


@contextlib.contextmanager
def _cleanup(what: str, first: BaseException | None):
    """A cleanup step: with an error already ending the run, its own failure (a full disk fails the footer write
    too) is logged in one line and the first error goes on; without one, its failure is the error."""
    try:
        yield
    except Exception as e:
        if first is None:
            raise
        logger.error(
            "%s also failed (%s); the first error stands.", what.capitalize(), durable.describe_write_error(e)
        )


def _handle_episode(ep: Episode, cur: curation_mod.CurationConfig, tally, stats, target: int, bar):
    """Curate and count one episode. Returns (curation result or None, kept: to be written)."""
    o = tally.of(ep.object_name)
    if ep.physics_failed:
        o.physics_failed += 1
        return None, False
    cut = curation_mod.judge_episode(ep.task_reward, ep.uniaxial_force, cur)
    stats.rollouts += 1
    o.rollouts += 1
    o.passed += cut.passed
    o.success += ep.success
    o.left_workspace += ep.left_workspace
    o.force_sum_n_total += cut.force_sum_n
    if not cut.keep or o.kept >= target:
        return cut, False
    frames = cut.keep_steps  # what write_episode writes
    o.kept += 1
    o.frames += frames
    stats.kept += 1
    stats.frames += frames
    bar.update(1)
    bar.set_postfix(rollouts=stats.rollouts, refresh=False)
    return cut, True
