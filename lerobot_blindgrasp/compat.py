"""Every place the plugin reaches into LeRobot's internals or installs a process-wide hook, and nowhere else
(`tests/policies/test_compat.py` scans the package for strays): LeRobot's dataset reader and writers, lerobot-record's
episode announcement, LeRobot's command line, and the process's signal handlers and excepthook. Each was read against
LeRobot `WRITTEN_FOR`; under another version the first reach used logs, once, what `check_lerobot()` finds missing,
and a reach whose target is gone leaves LeRobot's own behaviour in place.
"""

from __future__ import annotations

import contextlib
import dataclasses
import functools
import importlib
import importlib.metadata
import importlib.util
import logging
import operator
import signal
import sys
from collections.abc import Callable, Iterator

from lerobot_blindgrasp import durable

WRITTEN_FOR = "0.6.1"  # the LeRobot release every reach below was read against
ANNOUNCEMENT = "Recording episode"  # the text of lerobot-record's log_say before every episode
_WRAPPED = "_blindgrasp_compat"  # marks a DatasetReader method this module has wrapped
logger = logging.getLogger(__name__)
_warned = False


def installed_version() -> str | None:
    try:
        return importlib.metadata.version("lerobot")
    except importlib.metadata.PackageNotFoundError:
        return None


def _source(module: str) -> str:
    """A LeRobot module's source text, read from its file (importing lerobot_record would load every robot)."""
    try:
        spec = importlib.util.find_spec(module)
        with open(spec.origin) as f:  # type: ignore[union-attr, arg-type]
            return f.read()
    except (ImportError, AttributeError, TypeError, ValueError, OSError):
        return ""


def _has(module: str, *names: str) -> list[str]:
    try:
        mod = importlib.import_module(module)
    except ImportError as e:
        return [f"{module} cannot be imported ({e})"]
    gone = []
    for name in names:
        try:
            operator.attrgetter(name)(mod)
        except AttributeError:
            gone.append(f"{module}.{name} is gone")
    return gone


def _mentions(module: str, *texts: str) -> list[str]:
    source = _source(module)
    return [f"{module} no longer contains {text!r}" for text in texts if text not in source]


def check_lerobot() -> list[str]:
    """What the reaches rely on that the installed LeRobot lacks: one line each; empty when all is there."""
    reader, writer, meta = (f"lerobot.datasets.dataset_{m}" for m in ("reader", "writer", "metadata"))
    io_utils = "lerobot.datasets.io_utils"
    problems = _has(reader, "DatasetReader.try_load", "DatasetReader.load_and_activate", "DatasetReader.get_item")
    problems += _mentions(reader, *(f"self.{a} =" for a in ("_meta", "hf_dataset", "delta_indices")))
    problems += _mentions(reader, "self._image_transforms =", "self._absolute_to_relative_idx =")
    problems += _has(writer, "embed_images", "DatasetWriter._save_episode_data")
    problems += _mentions(writer, "embed_images(ep_dataset)")
    problems += _has("datasets.features.features", "require_storage_embed")
    problems += _has(io_utils, "write_json", "write_info", "write_stats")
    problems += _mentions(io_utils, "    write_json(info.to_dict()", "    write_json(serialized")
    problems += _has(meta, "write_tasks")
    problems += _mentions(meta, "write_tasks(self.tasks, self.root)")
    problems += _has("lerobot.utils.utils", "log_say")
    problems += _mentions("lerobot.utils.utils", "logging.info(text)")
    problems += _mentions("lerobot.scripts.lerobot_record", f'log_say(f"{ANNOUNCEMENT} {{dataset.num_episodes}}"')
    problems += _has("lerobot.configs.parser", "get_path_arg", "parse_arg")
    # The writers' private state that demos/crash_checkpoints.py and demos/collection_loop.py read and reset.
    problems += _mentions(writer, *(f"self.{a} =" for a in ("_finalized", "_pq_writer", "_latest_episode")))
    problems += _mentions(
        meta, *(f"self.{a} =" for a in ("_finalized", "_pq_writer", "latest_episode", "episodes"))
    )
    problems += _mentions(meta, "self._metadata_buffer")
    problems += _mentions("lerobot.datasets.lerobot_dataset", "self._is_finalized =", "self.writer =")
    return problems


def _used(reach: str) -> None:
    """On a LeRobot other than `WRITTEN_FOR`, say once (the first reach used) what `check_lerobot()` finds."""
    global _warned
    if _warned:
        return
    _warned = True
    version = installed_version()
    if version == WRITTEN_FOR:
        return
    problems = check_lerobot()
    logger.warning(
        "lerobot_blindgrasp was written for LeRobot %s, found %s (first used: %s); %s",
        WRITTEN_FOR,
        version,
        reach,
        "what it relies on is there" if not problems else "changed: " + "; ".join(problems),
    )


def serve_dataset_readers_with(choose: Callable) -> None:
    """From now on in this process, after `DatasetReader.try_load` or `load_and_activate` loads a table,
    `choose(reader)` may return a `DatasetReader` subclass the reader becomes (None: it stays as it is). LeRobot
    0.6.1 has no hook to choose a dataset's reader (docs/upstream/low-dimensional-cache.md). Idempotent."""
    try:
        from lerobot.datasets.dataset_reader import DatasetReader
    except ImportError:
        return
    _used("serve_dataset_readers_with")
    for name in ("try_load", "load_and_activate"):
        method = getattr(DatasetReader, name, None)
        if method is not None and not getattr(method, _WRAPPED, False):
            setattr(DatasetReader, name, _choose_after(method, choose))


def _choose_after(load: Callable, choose: Callable) -> Callable:
    @functools.wraps(load)
    def wrapper(self, *args, **kwargs):
        result = load(self, *args, **kwargs)
        if (cls := choose(self)) is not None:
            self.__class__ = cls
        return result

    setattr(wrapper, _WRAPPED, True)
    return wrapper


@contextlib.contextmanager
def skip_empty_image_embedding() -> Iterator[None]:
    """Within the block, the dataset writer's `embed_images` returns a dataset unchanged when no column needs
    embedding (`datasets`' `require_storage_embed`): LeRobot 0.6.1 runs this per-row pass even for state-only
    datasets (docs/upstream/skip-image-embedding.md). Same files written."""
    try:
        from datasets.features.features import require_storage_embed
        from lerobot.datasets import dataset_writer
    except ImportError:
        yield
        return
    original = getattr(dataset_writer, "embed_images", None)
    if original is None:
        yield
        return
    _used("skip_empty_image_embedding")

    def embed_images_if_needed(dataset):
        if any(require_storage_embed(f) for f in dataset.features.values()):
            return original(dataset)
        return dataset

    dataset_writer.embed_images = embed_images_if_needed
    try:
        yield
    finally:
        dataset_writer.embed_images = original


@contextlib.contextmanager
def atomic_lerobot_metadata() -> Iterator[None]:
    """Within the block, LeRobot's dataset metadata writers write atomically (temp name + rename, not fsynced):
    LeRobot 0.6.1 rewrites info.json, stats.json (`io_utils.write_json`) and tasks.parquet (`write_tasks`) in place
    after every episode, so a kill during one leaves a truncated file, and a repair cannot re-derive info.json."""
    try:
        from lerobot.datasets import dataset_metadata, io_utils
    except ImportError:
        yield
        return
    _used("atomic_lerobot_metadata")
    saved = {}

    def write_json(data, fpath):
        durable.atomic_write_json(fpath, data, fsync=False, indent=4, ensure_ascii=False)

    def write_tasks(tasks, local_dir):
        with durable.atomic_path(local_dir / "meta" / "tasks.parquet", fsync=False) as tmp:
            tasks.to_parquet(tmp)

    for module, name, fn in ((io_utils, "write_json", write_json), (dataset_metadata, "write_tasks", write_tasks)):
        if hasattr(module, name):
            saved[(module, name)] = getattr(module, name)
            setattr(module, name, fn)
    try:
        yield
    finally:
        for (module, name), fn in saved.items():
            setattr(module, name, fn)


def is_episode_announcement(record: logging.LogRecord) -> bool:
    """Whether a log record is lerobot-record announcing the episode about to start. LeRobot 0.6.1's Robot
    interface has no call at an episode's start, but lerobot-record (and lerobot-rollout's episodic strategy) runs
    `log_say(f"Recording episode {n}")` before each, which logs the text at INFO whether or not sounds are on."""
    if record.funcName == "log_say" and isinstance(record.msg, str) and record.msg.startswith(ANNOUNCEMENT):
        _used("is_episode_announcement")
        return True
    return False


def cli_policy_path() -> str | None:
    """`--policy.path` of this process's command line, as LeRobot's `@parser.wrap()` reads it (None: not given)."""
    from lerobot.configs import parser

    _used("cli_policy_path")
    return parser.get_path_arg("policy")


def cli_arg(name: str) -> str | None:
    """`--<name>` of this process's command line (e.g. `dataset.root`), as LeRobot's parser reads it."""
    from lerobot.configs import parser

    _used("cli_arg")
    return parser.parse_arg(name)


@dataclasses.dataclass(frozen=True)
class CommandLine:
    """What a LeRobot script's command line says that the script never hands the robot it builds."""

    policy_path: str | None = None  # --policy.path
    fps: float | None = None  # the loop's rate, from the last of --fps, --env.fps, --dataset.fps given
    fps_flag: str | None = None  # which flag gave it
    dataset_repo_id: str | None = None  # --dataset.repo_id: a recording is made
    dataset_root: str | None = None
    dataset_fps: float | None = None
    episode_time_s: float | None = None


def read_command_line() -> CommandLine:
    """The one read of this process's command line for the gripper, called where its config is parsed: LeRobot
    0.6.1's scripts build the robot (lerobot-eval: the env) before they load `--policy.path`, and never tell it the
    dataset or the rate they record at (LeRobot's `EvalPipelineConfig` re-reads `--policy.path` the same way)."""
    fps, flag = None, None
    for name in ("fps", "env.fps", "dataset.fps"):
        if (value := cli_arg(name)) is not None:
            fps, flag = float(value), name
    number = lambda name: None if (v := cli_arg(name)) is None else float(v)  # noqa: E731
    return CommandLine(cli_policy_path(), fps, flag, cli_arg("dataset.repo_id"), cli_arg("dataset.root"),
                       number("dataset.fps"), number("dataset.episode_time_s"))  # fmt: skip


def set_lerobot_argv(argv: list[str]) -> None:
    """Make `argv` the command line LeRobot's parser reads: LeRobot 0.6.1's `@parser.wrap()` parses `sys.argv[1:]`
    and takes no argument list, so a command called from Python with its arguments sets `sys.argv` first."""
    sys.argv = [sys.argv[0], *argv]


def set_signal_handler(signum: int, handler) -> object:
    """Install `handler` for `signum` (main thread only); returns the previous handler. The robot's, while a gripper
    is connected, make a scheduler's stop unwind through the script's cleanup (torque off)."""
    return signal.signal(signum, handler)


def set_excepthook(hook: Callable) -> Callable:
    """Make `hook` the process's `sys.excepthook`; returns the one it replaced. The robot's hook stops the servos
    of a script whose cleanup never reaches its `disconnect`, which would otherwise exit with them torqued."""
    previous, sys.excepthook = sys.excepthook, hook
    return previous


# The dataset writers' private state (LeRobotDataset, DatasetWriter, LeRobotDatasetMetadata; check_lerobot names it).
_WRITER_FIELDS = ("_finalized", "_latest_episode", "_pq_writer")
_META_FIELDS = ("_finalized", "latest_episode", "episodes", "_pq_writer", "_metadata_buffer")


def reopen_finalized(ds) -> bool:
    """Make a finalized LeRobotDataset accept episodes again, as `LeRobotDataset.resume` would leave it (both writers
    closed, `meta.episodes[-1]` naming the last episode's files and frame range) but from what LeRobot holds in
    memory, not by re-reading meta/episodes (seconds on a large dataset). False (nothing changed) when LeRobot's
    internals are not as expected or the dataset is not finalized."""
    w, m = getattr(ds, "writer", None), getattr(ds, "meta", None)
    expected = ((ds, ("_is_finalized",)), (w, _WRITER_FIELDS), (m, _META_FIELDS))  # None has none of them
    if not all(hasattr(obj, f) for obj, names in expected for f in names):
        return False
    if w._pq_writer is not None or m._pq_writer is not None or m._metadata_buffer:
        return False  # not finalized
    if m.latest_episode is None or w._latest_episode is None:
        return w._latest_episode is None and m.latest_episode is None and _unfinalize(ds)  # nothing written yet
    last = {
        "meta/episodes/chunk_index": int(m.latest_episode["meta/episodes/chunk_index"][0]),
        "meta/episodes/file_index": int(m.latest_episode["meta/episodes/file_index"][0]),
        "dataset_to_index": int(m.latest_episode["dataset_to_index"][0]),
        "data/chunk_index": int(w._latest_episode["data/chunk_index"]),
        "data/file_index": int(w._latest_episode["data/file_index"]),
    }
    m.episodes, m.latest_episode, w._latest_episode = [last], None, None
    return _unfinalize(ds)


def _unfinalize(ds) -> bool:
    ds.meta._finalized = ds.writer._finalized = ds._is_finalized = False
    return True


def finalize_or_abandon(ds) -> None:
    """LeRobot's finalize; if it fails, its writers are abandoned (their garbage-collection safety net would retry the
    write at interpreter shutdown, where pyarrow aborts the process instead of raising) and `--resume` repairs."""
    try:
        ds.finalize()
    except BaseException:
        for part in (ds.writer, ds.meta):
            if part is None:
                continue
            with contextlib.suppress(Exception):
                writer = getattr(part, "_pq_writer", None)
                if writer is not None:
                    writer.is_open = False  # pyarrow's __del__ would try the footer write again
                part._pq_writer = None
                getattr(part, "_metadata_buffer", []).clear()
            part._finalized = True
        ds._is_finalized = True
        raise
