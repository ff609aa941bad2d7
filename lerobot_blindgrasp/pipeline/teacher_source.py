"""The main job's teacher: a shipped one, a given folder, or trained from scratch in the run."""

from __future__ import annotations

from pathlib import Path

from lerobot_blindgrasp import presets, spec
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
        preset_name = t.config.get("preset")
    else:
        path, preset_name = out / "teacher", preset.teacher.settings.name
        source = f"trained from scratch in this run (teacher preset `{preset_name}`)"
        if stage.done("teacher"):
            stage.skip("teacher", "trained")
        else:
            spec.check_seeds("teacher_train", seed, preset.teacher.num_envs or preset.teacher.settings.num_envs)
            stage.run("teacher", recipe.teacher_train(preset, path, seed))
        t = TeacherPolicy(path)
    return path, {
        "source": source,
        "path": str(path),
        "file": t.name,
        "sha256": t.sha256,
        "iteration": t.iteration,
        "preset": preset_name,
    }
