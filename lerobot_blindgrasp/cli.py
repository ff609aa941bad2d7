"""What every `blindgrasp-*` command shares: draccus config parsing (as LeRobot's scripts do) and signal handling.

Configs are dataclasses; a command is `parse_config(Cfg)` then a library function that takes the config. So
`--output_dir`, dotted flags and `--config_path cfg.yaml` work as in `lerobot-train`, and `--help` lists every
field with its comment.

The argparse spellings of release 0.1 (`--output-dir`, bare `--no-export`, positional arguments, renamed flags
such as `--out`) are still accepted for one release, with a deprecation message, so recorded commands and the
pipeline's subprocess calls keep working. A command names its own old positionals and renamed flags through
`Legacy`; the generic rules (dashes, bare booleans, `--no-X`, repeated or multi-value list flags) need nothing.
"""

from __future__ import annotations

import contextlib
import dataclasses
import logging
import signal
import sys
import threading
import types
import typing
from collections.abc import Callable, Iterator, Mapping, Sequence

import draccus

log = logging.getLogger("blindgrasp.cli")

T = typing.TypeVar("T")

_BOOL_WORDS = {"true", "false", "yes", "no", "1", "0", "on", "off"}


@dataclasses.dataclass(frozen=True)
class Legacy:
    """A command's release-0.1 spellings that the generic rules cannot guess.

    positionals: field names the old positional arguments fill, in order (`RUN_DIR OUT` -> source, output_dir).
    flags: old flag name (dashes as underscores) -> new flag name (it takes the old flag's value), or
        `name=value` for an old switch without a value (`deterministic` -> `stochastic=false`).
    """

    positionals: Sequence[str] = ()
    flags: Mapping[str, str] = dataclasses.field(default_factory=dict)


def _field_kinds(cls) -> tuple[set[str], set[str], set[str]]:
    """(all field names, bool fields, list/tuple fields) of a config class."""
    hints = typing.get_type_hints(cls)
    names, bools, lists = set(), set(), set()
    for f in dataclasses.fields(cls):
        names.add(f.name)
        tp = hints.get(f.name)
        members = typing.get_args(tp) if typing.get_origin(tp) in (typing.Union, types.UnionType) else (tp,)
        if tp is bool:
            bools.add(f.name)
        elif any(typing.get_origin(m) in (list, tuple) for m in members):
            lists.add(f.name)
    return names, bools, lists


def translate_legacy_args(cls, argv: list[str], legacy: Legacy | None = None) -> tuple[list[str], list[str]]:
    """Old argparse arguments -> draccus flags. Returns (new argv, human-readable translations)."""
    legacy = legacy or Legacy()
    names, bools, lists = _field_kinds(cls)
    positionals = list(legacy.positionals)
    out: list[str] = []
    notes: list[str] = []
    list_values: dict[str, list[str]] = {}  # list flags given argparse-style: emitted once, as `--name=[a,b]`
    list_slots: dict[str, int] = {}  # where in `out` each of them goes
    i = 0

    def is_flag(tok: str) -> bool:
        return tok.startswith("--") or tok in ("-h",)

    while i < len(argv):
        arg = argv[i]
        i += 1
        if arg in ("--help", "-h"):
            out.append(arg)
            continue
        if not is_flag(arg):  # an old positional argument
            if not positionals:
                out.append(arg)  # let draccus report it
                continue
            new = f"--{positionals.pop(0)}={arg}"
            notes.append(f"{arg} -> {new}")
            out.append(new)
            continue
        key, eq, value = arg[2:].partition("=")
        top, dot, rest = key.partition(".")
        norm = top.replace("-", "_") + dot + rest
        renamed = legacy.flags.get(norm)
        if renamed is not None and "=" in renamed:  # an old switch: `--deterministic` -> `--stochastic=false`
            out.append(f"--{renamed}")
            notes.append(f"{arg} -> --{renamed}")
            continue
        new_key = renamed or norm
        bracketed = value if eq else (argv[i] if i < len(argv) else "")
        if new_key in lists and not bracketed.startswith("["):
            # argparse `nargs`/`action="append"`: `--threads 1 2`, `--tag a --tag b` -> `--threads=[1,2]`
            vals = [value] if eq else []
            while not eq and i < len(argv) and not is_flag(argv[i]):
                vals.append(argv[i])
                i += 1
            if new_key not in list_values:
                list_values[new_key], list_slots[new_key] = [], len(out)
                out.append("")  # filled below, once every occurrence is seen
            list_values[new_key].extend(vals)
            notes.append(f"{' '.join([arg, *vals])} -> --{new_key}=[...]")
            continue
        takes_value = True
        if not eq and new_key in bools:
            takes_value = i < len(argv) and argv[i].lower() in _BOOL_WORDS  # draccus style: `--export false`
            new = f"--{new_key}" if takes_value else f"--{new_key}=true"  # argparse store_true
        elif not eq and new_key.startswith("no_") and new_key[3:] in bools:  # `--no-export` -> `--export=false`
            new, takes_value = f"--{new_key[3:]}=false", False
        elif top.replace("-", "_") not in names and top not in names and top != "config_path" and renamed is None:
            new = arg  # unknown: let draccus report it
        else:
            new = f"--{new_key}{eq}{value}"
        if new != arg:
            notes.append(f"{arg} -> {new}")
        out.append(new)
        if takes_value and not eq and i < len(argv) and not is_flag(argv[i]):  # `--teacher DIR`: DIR is a value
            out.append(argv[i])
            i += 1
    for name, vals in list_values.items():
        out[list_slots[name]] = f"--{name}=[{','.join(vals)}]"
    return out, notes


def parse_config(cls: type[T], argv: list[str] | None = None, legacy: Legacy | None = None) -> T:
    """Parse a draccus config from argv (default sys.argv[1:]), accepting the deprecated spellings."""
    args = list(sys.argv[1:] if argv is None else argv)
    args, notes = translate_legacy_args(cls, args, legacy)
    if notes:
        print(
            "deprecated flag spelling (accepted until the next release): " + ", ".join(notes),
            file=sys.stderr,
        )
    try:
        return draccus.parse(config_class=cls, args=args)
    except draccus.utils.ParsingError as e:
        # Our own __post_init__ checks (unknown preset, missing output dir) end up as the cause: show just that.
        cause = e
        while cause.__cause__ is not None:
            cause = cause.__cause__
        raise SystemExit(f"error: {cause}") from None


def parse_config_and_positionals(
    cls: type[T], argv: list[str] | None = None, legacy: Legacy | None = None
) -> tuple[T, list[str]]:
    """For commands that take a list of positional arguments (`LABEL=PATH ...`) next to their config flags:
    (the config parsed by `parse_config` from the flags, the positionals in order). A token starting with `-` is a
    flag; a flag without `=` takes the next token as its value unless that is a flag too, or the flag is a boolean
    field and the token is no boolean word."""
    args = list(sys.argv[1:] if argv is None else argv)
    _, bools, _ = _field_kinds(cls)
    flags: list[str] = []
    positionals: list[str] = []
    i = 0
    while i < len(args):
        arg = args[i]
        i += 1
        if not arg.startswith("-"):
            positionals.append(arg)
            continue
        flags.append(arg)
        if "=" in arg or arg in ("-h", "--help") or i == len(args) or args[i].startswith("-"):
            continue
        if arg[2:].replace("-", "_") not in bools or args[i].lower() in _BOOL_WORDS:
            flags.append(args[i])
            i += 1
    return parse_config(cls, flags, legacy), positionals


def command_line(prog: str, argv: list[str] | None = None) -> str:
    """The command as typed, for run records (`collection.json`, "to continue: ..." hints)."""
    return " ".join([prog, *(sys.argv[1:] if argv is None else argv)])


@contextlib.contextmanager
def _handlers(signals: Sequence[signal.Signals], handler: Callable) -> Iterator[None]:
    """Install `handler` for `signals` within the block and restore the previous ones after it. Python only
    delivers signals to the main thread, so elsewhere (a worker thread running a collection) this does nothing."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    previous = {s: signal.signal(s, handler) for s in signals}
    try:
        yield
    finally:
        for s, h in previous.items():
            signal.signal(s, h)


@contextlib.contextmanager
def interrupts_as_keyboard_interrupt(signals=(signal.SIGTERM, signal.SIGHUP)) -> Iterator[None]:
    """Within the block, SIGTERM/SIGHUP (a job scheduler, `docker stop`, a closed terminal) raise
    KeyboardInterrupt like Ctrl-C, so one `except KeyboardInterrupt` path saves and exits cleanly."""

    def _raise(signum, _frame):
        raise KeyboardInterrupt(f"signal {signal.Signals(signum).name}")

    with _handlers(signals, _raise):
        yield


class GracefulStop:
    """Two-stage Ctrl-C for loops that can stop between steps (demo collection).

    First SIGINT/SIGTERM: `requested` is set and the loop stops after its current step. Second: KeyboardInterrupt
    right away, except inside `saving()`: an episode interrupted half-way through `save_episode` would leave rows
    in the data file that the metadata does not list, so the abort waits the few milliseconds until it is complete.
    """

    def __init__(
        self, note: str = "stopping after this step (again to abort now)", signals=(signal.SIGINT, signal.SIGTERM)
    ):
        self.requested: int | None = None
        self._note = note  # printed on the first signal
        self._signals = signals
        self._stack = contextlib.ExitStack()
        self._saving = False
        self._abort_pending = False

    @contextlib.contextmanager
    def saving(self) -> Iterator[None]:
        self._saving = True
        try:
            yield
        finally:
            self._saving = False
        if self._abort_pending:
            raise KeyboardInterrupt

    def _handle(self, signum, _frame):
        if self.requested is not None:
            if self._saving:
                self._abort_pending = True
                return
            raise KeyboardInterrupt
        self.requested = signum
        print(f"\n{signal.Signals(signum).name}: {self._note}", file=sys.stderr, flush=True)

    def __enter__(self) -> GracefulStop:
        self._stack.enter_context(_handlers(self._signals, self._handle))
        return self

    def __exit__(self, *exc) -> bool:
        self._stack.close()
        return False
