"""One stage of the main job: a real CLI run as a subprocess, its log kept, its completion marked in pipeline.json
only after its command succeeded (so a stage cut short is never taken for a finished one)."""

from __future__ import annotations

import os
import shlex
import signal
import subprocess
import sys
import time
from pathlib import Path

from lerobot_blindgrasp import durable

COMPLETED = "completed"  # pipeline.json: the stages that finished, in order


class Stage:
    """Runs one CLI with its output in logs/<name>.log, and records command and wall time."""

    def __init__(self, out: Path, record: dict):
        self.out = out
        self.record = record
        (out / "logs").mkdir(parents=True, exist_ok=True)

    def run(self, name: str, cmd: list[str], env: dict | None = None, ok: tuple[int, ...] = (0,)) -> int:
        cmd = [console_script(cmd[0]), *cmd[1:]]
        log_path = self.out / "logs" / f"{name}.log"
        print(f"[pipeline] {name}: {shlex.join(cmd)}", flush=True)
        t = time.time()
        with open(log_path, "w") as log:
            proc = subprocess.run(
                cmd,
                stdout=log,
                stderr=subprocess.STDOUT,
                env={**os.environ, **(env or {})},
                preexec_fn=_die_with_parent,
            )
        wall = time.time() - t
        self.record["stages"][name] = {
            "command": shlex.join(cmd),
            "wall_s": wall,
            "log": str(log_path),
            "returncode": proc.returncode,
        }
        if proc.returncode not in ok:
            self._save()
            tail = log_path.read_text().splitlines()[-25:]
            raise SystemExit(
                f"[pipeline] {name} failed (exit {proc.returncode}); last lines of {log_path}:\n" + "\n".join(tail)
            )
        self.complete(name)
        print(f"[pipeline] {name} done in {wall:.0f} s", flush=True)
        return proc.returncode

    def once(self, name: str, done_note: str, cmd: list[str], **kw) -> None:
        """`run`, unless the stage is marked completed (then it says so, with `done_note`)."""
        if self.done(name):
            self.skip(name, done_note)
        else:
            self.run(name, cmd, **kw)

    def skip(self, name: str, why: str) -> None:
        print(f"[pipeline] {name}: skipped ({why})", flush=True)

    def complete(self, name: str) -> None:
        """Mark a stage finished: the last thing written for it, after all of its output."""
        done = self.record.setdefault(COMPLETED, [])
        if name not in done:
            done.append(name)
        self._save()

    def done(self, name: str) -> bool:
        """Whether a stage finished (its completion mark is in pipeline.json)."""
        return name in self.record.get(COMPLETED, [])

    def _save(self) -> None:
        durable.atomic_write_json(self.out / "pipeline.json", self.record, indent=2)


def _die_with_parent() -> None:
    """In the stage's process, before exec: on Linux, be killed when the pipeline dies, even by SIGKILL. Otherwise
    an orphaned stage would go on writing while the re-run pipeline starts the same stage in the same folder."""
    if sys.platform.startswith("linux"):
        import ctypes

        ctypes.CDLL(None).prctl(1, signal.SIGKILL)  # PR_SET_PDEATHSIG


def console_script(name: str) -> str:
    """The console script next to this interpreter (the venv's), so subprocesses use the same install."""
    cand = Path(sys.executable).parent / name
    return str(cand) if cand.exists() else name
