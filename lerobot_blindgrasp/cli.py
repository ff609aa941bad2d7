"""What every `blindgrasp-*` command shares: draccus config parsing (as LeRobot's scripts do, so dotted flags,
`--config_path` and `--help` work as in `lerobot-train`; every input is a named flag), signal handling, and the
OpenMP setting of the commands that train.
"""

from __future__ import annotations

import contextlib
import os
import signal
import sys
import threading
from collections.abc import Callable, Iterator, Sequence

import draccus


def parse_config[T](cls: type[T], argv: list[str] | None = None) -> T:
    """Parse a draccus config from argv (default sys.argv[1:]); a bad value is one line, not a traceback."""
    args = list(sys.argv[1:] if argv is None else argv)
    try:
        return draccus.parse(config_class=cls, args=args)
    except draccus.utils.ParsingError as e:
        # Our own __post_init__ checks (unknown preset, missing output dir) end up as the cause: show just that.
        cause = e
        while cause.__cause__ is not None:
            cause = cause.__cause__
        raise SystemExit(f"error: {cause}") from None


def sleeping_openmp_threads(restart: bool) -> None:
    """Make idle OpenMP threads sleep instead of spin (`OMP_WAIT_POLICY=PASSIVE`), unless the user chose a policy:
    on a shared machine spinning threads steal the cores the others need. Call it first thing in `main(argv)`.
    OpenMP reads the setting once, when torch loads, which has happened by then: with `restart` (pass `argv is
    None`) the command starts over with it set (`os.execv`); without, it holds for the processes this one starts."""
    if "OMP_WAIT_POLICY" in os.environ:
        return
    os.environ["OMP_WAIT_POLICY"] = "PASSIVE"
    if restart and "torch" in sys.modules:
        sys.stdout.flush()
        sys.stderr.flush()
        os.execv(sys.executable, [sys.executable, *sys.orig_argv[1:]])


def command_line(prog: str, argv: list[str] | None = None) -> str:
    """The command as typed, for run records (`collection.json`, "to continue: ..." hints)."""
    return " ".join([prog, *(sys.argv[1:] if argv is None else argv)])


@contextlib.contextmanager
def _handlers(signals: Sequence[signal.Signals], handler: Callable) -> Iterator[None]:
    """Install `handler` for `signals` within the block, then restore the previous ones. Python delivers signals
    to the main thread only, so elsewhere this does nothing."""
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
def interrupts_as_keyboard_interrupt() -> Iterator[None]:
    """Within the block, SIGTERM/SIGHUP (a job scheduler, `docker stop`, a closed terminal) raise
    KeyboardInterrupt like Ctrl-C, so one `except KeyboardInterrupt` path saves and exits cleanly."""

    def _raise(signum, _frame):
        raise KeyboardInterrupt(f"signal {signal.Signals(signum).name}")

    with _handlers((signal.SIGTERM, signal.SIGHUP), _raise):
        yield


class GracefulStop:
    """Two-stage Ctrl-C for loops that can stop between steps (demo collection). First SIGINT/SIGTERM: `requested`
    is set and the loop stops after its current step. Second: KeyboardInterrupt at once, except inside `saving()`:
    an episode half-saved would leave rows the metadata does not list, so the abort waits until it is complete."""

    def __init__(self, note: str = "stopping after this step (again to abort now)"):
        self.requested: int | None = None
        self._note = note  # printed on the first signal
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
        self._stack.enter_context(_handlers((signal.SIGINT, signal.SIGTERM), self._handle))
        return self

    def __exit__(self, *exc) -> bool:
        self._stack.close()
        return False
