"""What every `blindgrasp-*` command shares: draccus config parsing (as LeRobot's scripts do) and interrupt handling.

Configs are dataclasses; a command is `parse_config(Cfg)` then a library function that takes the config. So
`--output_dir`, dotted flags and `--config_path cfg.yaml` work as in `lerobot-train`, and `--help` lists every
field with its comment.

The argparse spellings of release 0.1 (`--output-dir`, bare `--no-export`) are still accepted for one release, with
a deprecation message, so recorded commands keep working.
"""

from __future__ import annotations

import contextlib
import dataclasses
import logging
import signal
import sys
import typing
from collections.abc import Iterator

import draccus

log = logging.getLogger("blindgrasp.cli")

T = typing.TypeVar("T")


def _bool_fields(cls) -> set[str]:
    hints = typing.get_type_hints(cls)
    return {f.name for f in dataclasses.fields(cls) if hints.get(f.name) is bool}


def translate_legacy_args(cls, argv: list[str]) -> tuple[list[str], list[str]]:
    """Old argparse flags -> draccus flags. Returns (new argv, human-readable translations)."""
    names = {f.name for f in dataclasses.fields(cls)}
    bools = _bool_fields(cls)
    out, notes = [], []
    for arg in argv:
        if not arg.startswith("--") or arg == "--help":
            out.append(arg)
            continue
        key, eq, value = arg[2:].partition("=")
        top, dot, rest = key.partition(".")
        new_key = top.replace("-", "_") + dot + rest
        new = f"--{new_key}{eq}{value}"
        if not eq and new_key in bools:  # argparse store_true: `--no-incentive` -> `--no_incentive=true`
            new = f"--{new_key}=true"
        elif not eq and new_key.startswith("no_") and new_key[3:] in bools:  # `--no-export` -> `--export=false`
            new = f"--{new_key[3:]}=false"
        elif top.replace("-", "_") not in names and top not in names and top != "config_path":
            out.append(arg)  # let draccus report the unknown flag
            continue
        if new != arg:
            notes.append(f"{arg} -> {new}")
        out.append(new)
    return out, notes


def parse_config(cls: type[T], argv: list[str] | None = None) -> T:
    """Parse a draccus config from argv (default sys.argv[1:]), accepting the deprecated spellings."""
    args = list(sys.argv[1:] if argv is None else argv)
    args, notes = translate_legacy_args(cls, args)
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


@contextlib.contextmanager
def interrupts_as_keyboard_interrupt(signals=(signal.SIGTERM, signal.SIGHUP)) -> Iterator[None]:
    """Within the block, SIGTERM/SIGHUP (a job scheduler, `docker stop`, a closed terminal) raise
    KeyboardInterrupt like Ctrl-C, so one `except KeyboardInterrupt` path saves and exits cleanly."""

    def _raise(signum, _frame):
        raise KeyboardInterrupt(f"signal {signal.Signals(signum).name}")

    previous = {s: signal.signal(s, _raise) for s in signals}
    try:
        yield
    finally:
        for s, h in previous.items():
            signal.signal(s, h)
