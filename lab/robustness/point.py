"""One point of the sweep: the student and its teacher under one `DomainRandomization`, on the same start states.

Every object's episodes run in one batch, the student's in the first half and the teacher's (privileged
observation, deterministic mean action) in the second, each episode on exactly the start state lerobot-eval gives
that `--seed` and object (`rollout.envs`: the "robustness" purpose). The student runs as lerobot-eval runs it
(`rollout.actors.StudentActor`). Episodes whose outcome is final are no longer simulated.
"""

from __future__ import annotations

from lerobot_blindgrasp.rollout.actors import SideBySide, StudentActor, TeacherActor
from lerobot_blindgrasp.rollout.envs import make_batched_env
from lerobot_blindgrasp.rollout.loop import run_batch
from lerobot_blindgrasp.sim import randomization


def run_point(
    dr: randomization.DomainRandomization,
    student: StudentActor | None,
    teacher,
    object_names: tuple[str, ...],
    episodes: int,
    seed: int,
    nthread: int = 0,
) -> dict[str, dict[str, list[bool]]]:
    """{"student": {object: [success per episode]}, "teacher": {...}} on the same start states (episode k of
    every object is evaluation index seed + k). Either policy may be None (then left out)."""
    roles = [(r, a) for r, a in (("student", student), ("teacher", teacher and TeacherActor(teacher))) if a]
    env = make_batched_env(
        "robustness", object_names, episodes=episodes, seed=seed, copies=len(roles), dr=dr, nthread=nthread
    )
    if student is not None:
        student.reset()
    n = env.num_envs // len(roles)
    actor = SideBySide([a for _, a in roles], rows_each=n)
    done = run_batch(env, actor, skip_final=True)
    return {
        role: {
            name: [ep.success for ep in done[actor.block(k)] if ep.object_name == name] for name in object_names
        }
        for k, (role, _) in enumerate(roles)
    }
