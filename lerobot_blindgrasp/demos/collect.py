"""`blindgrasp-collect-demos`: roll out a trained teacher, curate its episodes and write a LeRobotDataset.

    blindgrasp-collect-demos --out runs/demos_cpu --repo-id me/blindgrasp_demos_cpu     # the shipped teacher
    blindgrasp-collect-demos --teacher runs/teacher_cpu --out runs/demos_cpu --repo-id me/blindgrasp_demos_cpu

Paper Sec. III-C: the batched env with the paper's randomization and external pushes off, the teacher sampled from
its Gaussian (`--deterministic`: its mean, the "w/o stochastic teacher" ablation), 5 s episodes, each step logging
the student observation and the teacher's action, then curation (`demos/curation.py`; `--no-curation`: the
"w/o curation" ablation). Kept episodes are whole (the hold that success needs included); `--trim-at-criteria`
ends them where the curation criteria are first met. Env seeds come from the demo range (`spec.SEED_RANGES`), never
the teacher-training or evaluation ranges; `--seed` outside it is refused.

`--episodes-per-object N` is the number of episodes *written* per object: collection runs until every object has
N, or has used `--max-rollouts-per-object` rollouts (default 20 N), so an object the teacher cannot lift ends
the run instead of stalling it. When a quarter of the envs hold finished objects, the env is rebuilt with
the remaining objects (new env seeds), so physics time goes to objects that still need demos.

The output folder is the dataset root. Next to LeRobot's files it holds `collection.json` (provenance),
`yield_report.json` (per-object yield) and `README.md` (the dataset card). Ctrl-C (or SIGTERM) stops after the
current control step and finalizes the dataset; a second Ctrl-C aborts at once, still finalizing. Every written
episode stays readable either way. `--resume` appends to the folder until the targets are met.
"""

from __future__ import annotations

import argparse
import contextlib
import dataclasses
import logging
import re
import signal
import sys
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from datetime import UTC, datetime
from pathlib import Path

from lerobot_blindgrasp import spec
from lerobot_blindgrasp.demos import curation as curation_mod
from lerobot_blindgrasp.demos import dataset as demo_dataset
from lerobot_blindgrasp.demos import provenance, report
from lerobot_blindgrasp.demos.rollout import Episode, run_episodes
from lerobot_blindgrasp.sim import objects as objects_mod
from lerobot_blindgrasp.sim import randomization

log = logging.getLogger("blindgrasp.demos")

# Rebuild the env for the remaining objects once this fraction of envs holds finished objects. A rebuild drops the
# running episodes of the other envs (half an episode each on average) and costs ~1 s; waiting wastes this fraction
# of every step until the next object finishes, usually hundreds of steps later. At 0.5, a 30-minute cpu run spent
# ~19 % of its rollouts on objects that were already done.
REBUILD_WASTE_FRACTION = 0.25
DEFAULT_ROLLOUT_BUDGET_FACTOR = 20
REPO_ID_PATTERN = re.compile(r"^[A-Za-z0-9][A-Za-z0-9_.-]*/[A-Za-z0-9][A-Za-z0-9_.-]*$")


EXIT_EMPTY = 3  # the collection ran but wrote no episode


class CollectError(Exception):
    """A problem found before anything was written (bad teacher, existing output, incompatible resume)."""


@dataclass
class CollectConfig:
    teacher: Path | None  # None: the shipped default teacher
    out: Path
    repo_id: str
    episodes_per_object: int = 20
    max_rollouts_per_object: int | None = None  # None: DEFAULT_ROLLOUT_BUDGET_FACTOR x episodes_per_object
    objects: tuple[str, ...] = objects_mod.PAPER_OBJECTS
    stochastic: bool = True
    curation: curation_mod.CurationConfig = curation_mod.PAPER_CURATION
    num_envs: int = 180  # 18 objects x 10
    seed: int = spec.DEMO_SEED  # first env seed; must lie in spec.SEED_RANGES["demos"]
    threads: int = 0  # physics threads, 0: all CPUs
    resume: bool = False
    progress: bool = True
    command: str = ""

    @property
    def rollout_budget(self) -> int:
        return self.max_rollouts_per_object or DEFAULT_ROLLOUT_BUDGET_FACTOR * self.episodes_per_object


@dataclass
class CollectStats:
    wall_s: float = 0.0
    cpu_s: float = 0.0  # process CPU time, all threads (physics, torch, writer)
    write_s: float = 0.0  # inside LeRobotDataset.save_episode
    env_steps: int = 0
    rollouts: int = 0
    kept: int = 0
    frames: int = 0
    env_builds: int = 0
    stop_reason: str = ""  # "done" | "interrupted" | "error: ..."
    tally: report.Tally = field(default_factory=report.Tally)

    @property
    def demos_per_minute(self) -> float:
        return 60.0 * self.kept / self.wall_s if self.wall_s else 0.0

    @property
    def demos_per_cpu_minute(self) -> float:
        return 60.0 * self.kept / self.cpu_s if self.cpu_s else 0.0

    @property
    def frames_written_per_s(self) -> float:
        return self.frames / self.write_s if self.write_s else 0.0

    def summary(self) -> dict:
        d = {k: v for k, v in dataclasses.asdict(self).items() if k != "tally"}
        d.update(
            demos_per_minute=self.demos_per_minute,
            demos_per_cpu_minute=self.demos_per_cpu_minute,
            frames_written_per_s=self.frames_written_per_s,
        )
        return d


# Called after every finished rollout with (episode, its curation result, written?, stats); the curation result
# is None when the physics failed.
EpisodeCallback = Callable[[Episode, "curation_mod.CurationResult | None", bool, CollectStats], None]


class _StopSignal:
    """First SIGINT/SIGTERM: stop after the current step. Second: KeyboardInterrupt right away, except inside
    `saving()`: an episode interrupted half-way through `save_episode` would leave rows in the data file that the
    metadata does not list, so the abort waits the few milliseconds until the episode is complete."""

    def __init__(self):
        self.requested: int | None = None
        self._previous: dict[int, object] = {}
        self._saving = False
        self._abort_pending = False

    @contextlib.contextmanager
    def saving(self):
        self._saving = True
        try:
            yield
        finally:
            self._saving = False
        if self._abort_pending:
            raise KeyboardInterrupt

    def __enter__(self):
        if threading.current_thread() is threading.main_thread():
            for sig in (signal.SIGINT, signal.SIGTERM):
                self._previous[sig] = signal.signal(sig, self._handle)
        return self

    def _handle(self, signum, frame):
        if self.requested is not None:
            if self._saving:
                self._abort_pending = True
                return
            raise KeyboardInterrupt
        self.requested = signum
        print(
            f"\n{signal.Signals(signum).name}: finishing this step and finalizing the dataset "
            "(again to abort now; written episodes stay readable)",
            file=sys.stderr,
            flush=True,
        )

    def __exit__(self, *exc):
        for sig, handler in self._previous.items():
            signal.signal(sig, handler)
        return False


def _check_inputs(cfg: CollectConfig):
    """Everything that can be refused before touching the output folder. Returns the loaded teacher."""
    from lerobot_blindgrasp.teacher.policy import TeacherError, TeacherPolicy, default_teacher

    if not REPO_ID_PATTERN.match(cfg.repo_id):
        raise CollectError(f"--repo-id must look like USER/NAME, got {cfg.repo_id!r}")
    if cfg.episodes_per_object < 1:
        raise CollectError("--episodes-per-object must be >= 1")
    if cfg.num_envs < 1:
        raise CollectError("--num-envs must be >= 1")
    try:
        spec.check_seeds("demos", cfg.seed, cfg.num_envs)
    except ValueError as e:
        raise CollectError(f"--seed: {e}") from None
    try:
        cfg.objects = objects_mod.resolve_objects(cfg.objects)
    except ValueError as e:
        raise CollectError(str(e)) from None
    out = Path(cfg.out)
    if cfg.resume:
        if not out.is_dir():
            raise CollectError(f"--resume: {out} does not exist; drop --resume to start a new dataset")
        if not provenance.path(out).is_file():
            raise CollectError(f"--resume: {out} was not written by blindgrasp-collect-demos (no collection.json)")
    elif out.exists():
        raise CollectError(f"{out} already exists; pass --resume to append to it, or choose a new --out")
    try:
        if cfg.teacher is None:
            cfg.teacher = default_teacher()
        teacher = TeacherPolicy(cfg.teacher)
    except TeacherError as e:
        raise CollectError(f"cannot load the teacher: {e}") from None
    except (KeyError, RuntimeError, ValueError) as e:
        raise CollectError(f"cannot load the teacher from {cfg.teacher}: {e}") from None
    return teacher


def _provenance(cfg: CollectConfig, teacher, dr: randomization.DomainRandomization) -> dict:
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
        "objects": list(cfg.objects),
        "robot_type": demo_dataset.ROBOT_TYPE,
        "next_env_seed": cfg.seed,
        "runs": [],
    }


def _existing_counts(root: Path, tally: report.Tally) -> None:
    """Kept episodes and frames per object, from the dataset itself (authoritative after a crash)."""
    try:
        table = demo_dataset.episode_table(root)
    except FileNotFoundError:  # no episode written yet
        return
    for o in tally.objects.values():
        o.kept, o.frames = 0, 0
    for name, group in table.groupby("object"):
        t = tally.of(name)
        t.kept, t.frames = len(group), int(group["length"].sum())


def collect(cfg: CollectConfig, on_episode: EpisodeCallback | None = None) -> CollectStats:
    """Run a collection. Raises CollectError (nothing touched) for bad inputs; any later exception propagates
    after the dataset is finalized and the reports are written."""
    import datasets
    import torch
    from tqdm import tqdm

    from lerobot_blindgrasp.sim import rewards
    from lerobot_blindgrasp.sim.env import BatchedGraspEnv, GraspEnvConfig

    teacher = _check_inputs(cfg)
    try:  # the teacher's own reward settings: r_t must be the task reward it was trained on
        reward_cfg = rewards.RewardConfig(**teacher.config["reward"])
    except (KeyError, TypeError) as e:
        raise CollectError(f"teacher config has no usable reward settings: {e}") from None
    out = Path(cfg.out)
    dr = randomization.PAPER_DR.without_external_force()
    prov_new = _provenance(cfg, teacher, dr)
    if cfg.resume:
        prov = provenance.load(out)
        bad = provenance.mismatches(prov, prov_new)
        if bad:
            raise CollectError(f"--resume: {out} was collected with different {', '.join(bad)}; use a new --out")
        try:
            ds = demo_dataset.resume(out, cfg.repo_id)
        except (ValueError, FileNotFoundError) as e:
            raise CollectError(f"--resume: {e}") from None
        tally = report.load_tally(out)
        _existing_counts(out, tally)
    else:
        ds = demo_dataset.create(out, cfg.repo_id)
        prov, tally = prov_new, report.Tally()
        provenance.save(out, prov)

    target, budget = cfg.episodes_per_object, cfg.rollout_budget
    stats = CollectStats(tally=tally)
    run = {
        "command": cfg.command or f"collect(repo_id={cfg.repo_id!r})",
        "started": datetime.now(UTC).isoformat(timespec="seconds"),
        "episodes_per_object": target,
        "max_rollouts_per_object": budget,
        "num_envs": cfg.num_envs,
        "seed_start": prov["next_env_seed"],
    }
    torch.manual_seed(prov["next_env_seed"])  # the stochastic teacher's samples

    def done(name: str) -> bool:
        o = tally.of(name)
        return o.kept >= target or o.rollouts >= budget

    # `datasets` draws a progress bar for every map LeRobot runs while saving; one per episode is noise here.
    bars_were_off = datasets.are_progress_bars_disabled()
    datasets.disable_progress_bars()
    t_wall, t_cpu = time.perf_counter(), time.process_time()
    bar = tqdm(
        total=target * len(cfg.objects),
        initial=sum(min(tally.of(n).kept, target) for n in cfg.objects),
        desc="demos",
        unit="ep",
        dynamic_ncols=True,
        disable=not cfg.progress,
    )
    env = None
    try:
        with _StopSignal() as stop:
            while stop.requested is None:
                todo = [n for n in cfg.objects if not done(n)]
                if not todo:
                    stats.stop_reason = "done"
                    break
                spec.check_seeds("demos", prov["next_env_seed"], cfg.num_envs)  # a long --resume stays in range
                env = BatchedGraspEnv(
                    GraspEnvConfig(
                        num_envs=cfg.num_envs,
                        objects=tuple(todo),
                        seed=prov["next_env_seed"],
                        episode_s=cfg.curation.episode_s,
                        dr=dr,
                        reward=reward_cfg,
                        nthread=cfg.threads,
                        autoreset=True,
                    )
                )
                prov["next_env_seed"] += cfg.num_envs  # later envs (and --resume) never repeat a draw
                stats.env_builds += 1
                env_objects = env.object_names
                stale = {"now": False}

                def act(obs, _env=env):
                    stats.env_steps += _env.num_envs
                    return teacher(obs, stochastic=cfg.stochastic)

                episodes = run_episodes(env, act, lambda s=stale: stop.requested is not None or s["now"])
                for ep in episodes:
                    with stop.saving():
                        cut, written = _handle_episode(ds, ep, cfg.curation, tally, stats, target, bar)
                    if on_episode is not None:
                        on_episode(ep, cut, written, stats)
                    if done(ep.object_name):
                        finished = sum(done(n) for n in env_objects)
                        stale["now"] = finished >= REBUILD_WASTE_FRACTION * len(env_objects)
                env.close()
                env = None
            else:
                stats.stop_reason = "interrupted"
    except BaseException as e:
        stats.stop_reason = (
            "interrupted" if isinstance(e, KeyboardInterrupt) else f"error: {type(e).__name__}: {e}"
        )
        raise
    finally:
        bar.close()
        if not bars_were_off:
            datasets.enable_progress_bars()
        ds.finalize()  # closes the parquet writers: every saved episode is readable from here on
        stats.wall_s = time.perf_counter() - t_wall
        stats.cpu_s = time.process_time() - t_cpu
        run.update(
            ended=datetime.now(UTC).isoformat(timespec="seconds"),
            stop_reason=stats.stop_reason,
            interrupted=stats.stop_reason != "done",
            wall_s=stats.wall_s,
            cpu_s=stats.cpu_s,
            rollouts=stats.rollouts,
            kept=stats.kept,
            frames=stats.frames,
            env_steps=stats.env_steps,
        )
        prov["runs"].append(run)
        provenance.save(out, prov)
        _write_report(out, cfg, prov, tally)
        try:
            from lerobot_blindgrasp.demos import cards

            cards.write_card(out, cfg.repo_id)
        except Exception as e:  # noqa: BLE001  (a card problem must not mask the collection's outcome)
            log.warning("could not write the dataset card: %s", e)
    return stats


def _handle_episode(ds, ep: Episode, cur: curation_mod.CurationConfig, tally, stats, target: int, bar):
    """Curate, count and maybe write one episode. Returns (curation result or None, written)."""
    o = tally.of(ep.object_name)
    if ep.physics_failed:
        o.physics_failed += 1
        return None, False
    cut = curation_mod.evaluate(ep.task_reward, ep.uniaxial_force, cur)
    stats.rollouts += 1
    o.rollouts += 1
    o.passed += cut.passed
    o.success += ep.success
    o.left_workspace += ep.left_workspace
    o.force_sum_n_total += cut.force_sum_n
    if not cut.keep or o.kept >= target:
        return cut, False
    t0 = time.perf_counter()
    frames = demo_dataset.write_episode(ds, ep, cut)
    stats.write_s += time.perf_counter() - t0
    o.kept += 1
    o.frames += frames
    stats.kept += 1
    stats.frames += frames
    bar.update(1)
    bar.set_postfix(rollouts=stats.rollouts, refresh=False)
    return cut, True


def _write_report(out: Path, cfg: CollectConfig, prov: dict, tally: report.Tally) -> Path:
    runs = prov["runs"]
    wall = sum(r["wall_s"] for r in runs)
    cpu = sum(r["cpu_s"] for r in runs)
    kept_now = sum(r["kept"] for r in runs)
    return report.write_report(
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
            "demos_per_minute": 60.0 * kept_now / wall if wall else 0.0,
            "demos_per_cpu_minute": 60.0 * kept_now / cpu if cpu else 0.0,
            "object_order": list(prov["objects"]),
        },
    )


def parse_args(argv=None) -> argparse.Namespace:
    p = argparse.ArgumentParser(
        prog="blindgrasp-collect-demos", description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    p.add_argument(
        "--teacher", type=Path, default=None,
        help="teacher folder (teacher.safetensors, or a training run dir: its latest model_<it>.pt) or checkpoint "
        "file; default: the shipped teacher",
    )
    p.add_argument("--out", required=True, type=Path, help="dataset folder to create (must not exist)")
    p.add_argument("--repo-id", required=True, help="USER/NAME, the dataset's Hub id")
    p.add_argument("--episodes-per-object", type=int, default=20, help="episodes to write per object")
    p.add_argument("--max-rollouts-per-object", type=int, default=None, help="rollout budget per object (20 N)")
    p.add_argument("--objects", default="all", help="'all', 'medium' or a comma list of catalogue names")
    p.add_argument(
        "--deterministic", action="store_true", help="teacher mean: the 'w/o stochastic teacher' ablation"
    )
    p.add_argument(
        "--no-curation", action="store_true", help="keep every episode whole: the 'w/o curation' ablation"
    )
    p.add_argument(
        "--trim-at-criteria", action="store_true",
        help="end kept episodes at the step where the curation criteria are first met (default: keep them whole)",
    )
    p.add_argument("--resume", action="store_true", help="append to an existing --out until the targets are met")
    p.add_argument("--num-envs", type=int, default=180, help="parallel envs (default 180 = 18 objects x 10)")
    p.add_argument(
        "--seed", type=int, default=spec.DEMO_SEED,
        help=f"first env seed, in the demo range [{spec.SEED_RANGES['demos'].start}, "
        f"{spec.SEED_RANGES['demos'].stop}) (a resumed run continues after the last)",
    )
    p.add_argument("--threads", type=int, default=0, help="physics threads (0: all CPUs)")
    p.add_argument("--no-progress", action="store_true")
    return p.parse_args(argv)


def config_from_args(args: argparse.Namespace, command: str = "") -> CollectConfig:
    if args.no_curation:
        cur = curation_mod.NO_CURATION
    else:
        cur = dataclasses.replace(curation_mod.PAPER_CURATION, trim_to_success=args.trim_at_criteria)
    return CollectConfig(
        teacher=args.teacher,
        out=args.out,
        repo_id=args.repo_id,
        episodes_per_object=args.episodes_per_object,
        max_rollouts_per_object=args.max_rollouts_per_object,
        objects=args.objects,
        stochastic=not args.deterministic,
        curation=cur,
        num_envs=args.num_envs,
        seed=args.seed,
        threads=args.threads,
        resume=args.resume,
        progress=not args.no_progress,
        command=command,
    )


def main(argv=None) -> None:
    logging.basicConfig(level=logging.INFO, format="%(message)s")
    args = parse_args(argv)
    command = " ".join(["blindgrasp-collect-demos", *(sys.argv[1:] if argv is None else argv)])
    cfg = config_from_args(args, command)
    try:
        stats = collect(cfg)
    except CollectError as e:
        print(f"error: {e}", file=sys.stderr)
        raise SystemExit(2) from None
    except KeyboardInterrupt:
        print(f"\naborted; the dataset in {cfg.out} is finalized and readable", file=sys.stderr)
        raise SystemExit(130) from None
    tally = report.load_tally(cfg.out)
    print(report.format_table(tally, list(cfg.objects)))
    s = stats.summary()
    print(
        f"\n{s['kept']} episodes written ({s['frames']} frames) from {s['rollouts']} rollouts in "
        f"{s['wall_s'] / 60:.1f} min: {s['demos_per_minute']:.1f} demos/min, "
        f"{s['demos_per_cpu_minute']:.1f} demos/CPU-min; dataset: {cfg.out}"
    )
    if tally.total().kept == 0 and stats.stop_reason != "interrupted":
        # LeRobot cannot load a dataset without episodes (it then tries the Hub), so stop anything downstream here.
        print(
            f"error: {cfg.out} is empty: no episode met the curation criteria, so LeRobot cannot load it; use a "
            "better teacher, a larger --max-rollouts-per-object or --no-curation, with --resume to append",
            file=sys.stderr,
        )
        raise SystemExit(EXIT_EMPTY)
    if stats.stop_reason == "interrupted":
        again = command if cfg.resume else f"{command} --resume"
        print(f"interrupted; every written episode is readable. To continue: {again}", file=sys.stderr)
        raise SystemExit(130)


if __name__ == "__main__":
    main()
