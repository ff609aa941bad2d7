"""The one rollout layer, between `sim/` + `policies/` and the tools that run episodes.

- `envs.py`: the env factory. A purpose (train, demos, dagger, eval, robustness), the objects and the seeds in; the
  randomization and the seed range that purpose has (`spec.SEED_RANGES`) chosen in one place.
- `loop.py`: the episode loop (`run_batch` for one episode per env, `stream` for auto-resetting envs) and its one
  outcome record, `Episode`.
- `actors.py`: the student as lerobot-eval runs it, and the teacher; the student's absolute targets become the
  env's steps in one place, through the env's calibration-aware conversion.

Teacher evaluation, demo collection, DAgger, the student diagnosis and the robustness sweep all run through it.
"""
