"""A teacher run's checkpoints: atomic saves, the newest that loads (a corrupt one set aside), the actor's export."""

from __future__ import annotations

import logging
import os
import re
from pathlib import Path

import torch

from lerobot_blindgrasp import durable
from lerobot_blindgrasp.teacher import distributed

log = logging.getLogger("blindgrasp.teacher")


def atomic_save(save):
    """rsl-rl's `OnPolicyRunner.save(path, infos)` (an in-place torch.save) made atomic: temp file, then rename."""

    def save_atomically(path, infos=None):
        with durable.atomic_path(path) as tmp:
            save(str(tmp), infos)

    return save_atomically


def newest_loadable_checkpoint(run_dir: Path) -> Path | None:
    """The newest model_<it>.pt that torch can read. Newer unreadable ones are set aside as `<name>.corrupt` with a
    warning, and killed saves' temp files go (by rank 0 only; the other ranks skip the same files)."""
    lead = distributed.world()[1] == 0
    if lead:
        for stale in durable.remove_stale_temps(run_dir):
            log.info("removed %s, the temp file of a save that was killed", stale)
    ckpts = sorted(Path(run_dir).glob("model_*.pt"), key=lambda p: int(re.findall(r"\d+", p.stem)[-1]))
    for ckpt in reversed(ckpts):
        try:
            torch.load(ckpt, map_location="cpu", weights_only=False)
            return ckpt
        except Exception as e:  # noqa: BLE001  (truncated zip, bad pickle, I/O error: all mean "cannot resume here")
            why = f"{type(e).__name__}: {str(e).splitlines()[0][:200] if str(e) else ''}"
            if lead:
                aside = ckpt.with_name(ckpt.name + ".corrupt")
                os.replace(ckpt, aside)
                msg = "checkpoint %s cannot be read (%s); set aside as %s, resuming from the one before"
                log.warning(msg, ckpt, why, aside.name)
    return None


def export_actor(runner, path: Path) -> None:
    """TorchScript and ONNX of the actor's mean (the deterministic teacher), via rsl-rl's exporters."""
    # rsl-rl's exporters write in place; they write temp files here that are renamed once complete.
    with durable.atomic_path(path / "teacher.pt") as tmp:
        runner.export_policy_to_jit(str(path), tmp.name)
    try:
        with durable.atomic_path(path / "teacher.onnx") as tmp:
            runner.export_policy_to_onnx(str(path), tmp.name)
    except Exception as e:  # ONNX export depends on optional onnxscript versions; JIT is enough for us
        log.warning("ONNX export failed: %s", e)
