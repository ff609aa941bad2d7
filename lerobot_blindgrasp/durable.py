"""Atomic file writes: a temporary file beside the target, fsynced, `os.replace`d over it, the folder fsynced. A kill
leaves at worst a hidden `.NAME.tmp-*` file (`remove_stale_temps`). A failed write raises `WriteError`, naming the
cause in words; deliberately not an `OSError`, so code that maps OSError to a device fault (the gripper's safety
latch) never relabels a disk problem.
"""

from __future__ import annotations

import contextlib
import errno
import io
import json
import os
import resource
import shutil
import tempfile
from collections.abc import Iterator
from pathlib import Path

TEMP_MARK = ".tmp-"

_CAUSES = {
    errno.ENOSPC: "the disk is full",
    errno.EFBIG: "the file-size limit was reached (ulimit -f / RLIMIT_FSIZE)",
    errno.EDQUOT: "the disk quota is exhausted",
    errno.EROFS: "the filesystem is read-only",
    errno.EACCES: "permission denied",
    errno.EPERM: "operation not permitted",
}


class WriteError(Exception):
    """A file could not be written; the previous file (if any) is unchanged. `errno` as in OSError, or None."""

    def __init__(self, path: Path, cause: str, errno_: int | None = None):
        self.path, self.cause, self.errno = Path(path), cause, errno_
        super().__init__(f"could not write {path}: {cause}; the previous file is unchanged")


def describe_write_error(e: BaseException) -> str:
    """A write failure in words: 'the disk is full (ENOSPC)' rather than an errno number."""
    code = getattr(e, "errno", None)
    if code in _CAUSES:
        return f"{_CAUSES[code]} ({errno.errorcode[code]})"
    return f"{type(e).__name__}: {e}"


def _diagnose(tmp: Path) -> tuple[str, int] | None:
    """Why a third-party writer failed when it reports a generic error (torch.save raises RuntimeError 'file write
    failed'): the temp file at the file-size limit, or no free space left. None when neither holds."""
    soft, _ = resource.getrlimit(resource.RLIMIT_FSIZE)
    with contextlib.suppress(OSError):
        if soft != resource.RLIM_INFINITY and tmp.stat().st_size >= soft:
            return _CAUSES[errno.EFBIG] + " (EFBIG)", errno.EFBIG
    with contextlib.suppress(OSError):
        if shutil.disk_usage(tmp.parent).free == 0:
            return _CAUSES[errno.ENOSPC] + " (ENOSPC)", errno.ENOSPC
    return None


def fsync_dir(folder: Path) -> None:
    """Make a rename in `folder` durable. A no-op where folders cannot be opened (Windows) or fsynced (some
    filesystems): the rename is still atomic."""
    with contextlib.suppress(OSError):
        _fsync_file(folder)


@contextlib.contextmanager
def atomic_path(path: str | os.PathLike, fsync: bool = True) -> Iterator[Path]:
    """Yield a temporary path beside `path`, fsynced and renamed over it (with the old file's permissions, else 0o666
    less the umask) once the block ends normally; on any error it is removed and `path` is untouched. fsync=False:
    atomic against a kill, not a power cut; for files rewritten often whose caller fsyncs at checkpoints."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    try:  # hidden, with the target's suffix: writers pick their format from it; globs like *.pt never match it
        fd, name = tempfile.mkstemp(prefix=f".{path.name}{TEMP_MARK}", suffix=path.suffix, dir=path.parent)
        os.close(fd)
    except OSError as e:
        raise WriteError(path, describe_write_error(e), e.errno) from e
    tmp = Path(name)
    try:
        yield tmp
        if fsync:
            _fsync_file(tmp)
        os.chmod(tmp, _mode_for(path))
        os.replace(tmp, path)
    except OSError as e:
        tmp.unlink(missing_ok=True)
        raise WriteError(path, describe_write_error(e), e.errno) from e
    except BaseException as e:
        why = _diagnose(tmp) if isinstance(e, Exception) else None
        tmp.unlink(missing_ok=True)
        if why is not None:
            raise WriteError(path, f"{why[0]} ({type(e).__name__}: {e})", why[1]) from e
        raise
    if fsync:
        fsync_dir(path.parent)


@contextlib.contextmanager
def atomic_open(path: str | os.PathLike) -> Iterator[io.TextIOBase]:
    """A text file object for writers that want one (draccus.dump); replaced atomically on success."""
    with atomic_path(path) as tmp, open(tmp, "w", encoding="utf-8") as f:
        yield f


def atomic_write_bytes(path: str | os.PathLike, data: bytes, fsync: bool = True) -> Path:
    with atomic_path(path, fsync=fsync) as tmp:
        tmp.write_bytes(data)
    return Path(path)


def atomic_write_text(path: str | os.PathLike, text: str, encoding: str = "utf-8", fsync: bool = True) -> Path:
    return atomic_write_bytes(path, text.encode(encoding), fsync=fsync)


def atomic_write_json(path: str | os.PathLike, obj, fsync: bool = True, **json_kwargs) -> Path:
    """json.dumps(obj, **json_kwargs) written atomically (serialized first: a bad object leaves no temp file)."""
    return atomic_write_text(path, json.dumps(obj, **json_kwargs), fsync=fsync)


def atomic_append_text(path: str | os.PathLike, text: str) -> Path:
    """`text` appended to a small file (a log of trials) by rewriting it whole: a kill never leaves half a line."""
    path = Path(path)
    old = path.read_bytes() if path.exists() else b""
    return atomic_write_bytes(path, old + text.encode())


def fsync_tree(folder: str | os.PathLike, since: float = 0.0) -> None:
    """fsync every file under `folder` modified at or after `since` (a time.time()), and their folders: what a
    checkpoint makes durable against a power cut."""
    folders = set()
    for p in Path(folder).rglob("*"):
        with contextlib.suppress(OSError):
            if p.is_file() and p.stat().st_mtime >= since:
                _fsync_file(p)
                folders.add(p.parent)
    for d in folders:
        fsync_dir(d)


def remove_stale_temps(folder: str | os.PathLike) -> list[Path]:
    """Delete temp files that a killed writer left in `folder`; returns them. Only for folders this process
    owns (another process writing there at the same time would lose its temp file)."""
    folder = Path(folder)
    gone = [p for p in folder.glob(f".*{TEMP_MARK}*") if p.is_file()] if folder.is_dir() else []
    for p in gone:
        p.unlink(missing_ok=True)
    return gone


def _fsync_file(path: Path) -> None:
    fd = os.open(path, os.O_RDONLY)
    try:
        os.fsync(fd)
    finally:
        os.close(fd)


def _mode_for(path: Path) -> int:
    try:
        return path.stat().st_mode & 0o777
    except FileNotFoundError:
        umask = os.umask(0)
        os.umask(umask)
        return 0o666 & ~umask
