"""The main job's teacher: a shipped one, a given folder, or trained from scratch in the run; and its evaluation,
reused from the shipped teacher's carried one when that was made on the same start states, sim code and CPU family.
"""

from __future__ import annotations

import json
import os
import shutil
from pathlib import Path

from lerobot_blindgrasp import durable, presets, spec
from lerobot_blindgrasp.pipeline import recipe
from lerobot_blindgrasp.pipeline.stage import Stage


def teacher_for_run(
    stage: Stage, preset: presets.Preset, out: Path, seed: int, given: Path | None
) -> tuple[Path, dict]:
    """The teacher folder for this run and what the report says about it."""
    from lerobot_blindgrasp.teacher.policy import TeacherError, TeacherPolicy, default_teacher

    if given is not None or preset.teacher.shipped:
        try:
            path = Path(given) if given is not None else default_teacher(preset.teacher.shipped_folder)
            t = TeacherPolicy(path)
        except TeacherError as e:
            raise SystemExit(f"[pipeline] error: {e}") from None
        shipped = "shipped" if preset.teacher.shipped_folder else "shipped default"
        stage.skip("teacher", f"using {'the given' if given is not None else 'the ' + shipped} teacher {path}")
        source = "given (--teacher)" if given is not None else shipped
        return path, {
            "source": source,
            "path": str(path),
            "file": t.name,
            "sha256": t.sha256,
            "iteration": t.iteration,
            "preset": t.config.get("preset"),
        }
    teacher_dir = out / "teacher"
    if stage.done("teacher"):
        stage.skip("teacher", "trained")
    else:
        spec.check_seeds("teacher_train", seed, preset.teacher.num_envs or preset.teacher.settings.num_envs)
        stage.run("teacher", recipe.teacher_train(preset, teacher_dir, seed))
    t = TeacherPolicy(teacher_dir)
    name = preset.teacher.settings.name
    return teacher_dir, {
        "source": f"trained from scratch in this run (teacher preset `{name}`)",
        "path": str(teacher_dir),
        "file": t.name,
        "sha256": t.sha256,
        "iteration": t.iteration,
        "preset": name,
    }


def reuse_teacher_eval(
    teacher_dir: Path,
    dest: Path,
    preset: presets.Preset,
    eval_seed: int,
    eval_objects: tuple[str, ...],
    note: dict | None = None,
) -> bool:
    """A shipped teacher may carry its eval (`<folder>/eval/eval.json`). Rollouts are functions of (teacher, start
    states, torch seed, sim code, float platform), so an eval of the same weights on the same start states under
    the same sim sources, made on this CPU family, is the paired eval; reuse it rather than spend minutes
    recomputing it. One from another family (its floats drift, and a contact-rich episode can end otherwise) is
    re-run here: `note["eval_rerun_because"]` then says why, for the report."""
    from lerobot_blindgrasp import platform_id
    from lerobot_blindgrasp.teacher.evaluate import sim_fingerprint
    from lerobot_blindgrasp.teacher.policy import TeacherPolicy

    src = teacher_dir / "eval" / "eval.json"
    if not src.is_file():
        return False
    prev = json.loads(src.read_text())
    same = (
        prev.get("checkpoint_sha256") == TeacherPolicy(teacher_dir).sha256
        and prev.get("sim_fingerprint") == sim_fingerprint()
        and prev.get("seed") == eval_seed
        and prev.get("episodes_per_object") == preset.evaluation.episodes_per_object
        and prev.get("objects") == list(eval_objects)
        and set(preset.evaluation.teacher_modes) <= set(prev.get("modes", {}))
    )
    here = platform_id.platform()
    if same and not platform_id.same(prev.get("platform"), here):
        why = (
            f"the carried eval {src} was recorded on {platform_id.describe(prev.get('platform'))}, and this "
            f"machine is {platform_id.describe(here)}"
        )
        print(
            f"[pipeline] {why}: re-running the teacher's eval here, so that teacher and student are paired on "
            "one machine's floats",
            flush=True,
        )
        if note is not None:
            note["eval_rerun_because"] = why
        return False
    if same:  # copied beside dest, then renamed: a kill mid-copy leaves no eval.json that looks finished
        tmp = dest.with_name(f".{dest.name}{durable.TEMP_MARK}copy")
        shutil.rmtree(tmp, ignore_errors=True)
        shutil.copytree(src.parent, tmp)
        shutil.rmtree(dest, ignore_errors=True)
        os.replace(tmp, dest)
    return same
