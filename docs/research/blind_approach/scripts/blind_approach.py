"""A teacher fine-tuned to approach blind: its actor sees nothing of the object until a fingertip reads a force.

The mask now lives in the package (lerobot_blindgrasp/teacher/blind_approach.py, preset cpu_bc_blind_approach);
this script is how the shipped teacher_cpu_bc_blind was made, and it names the masked vector "privileged".

The student cannot see where the object stands, nor which object it is, before a fingertip touches it; the shipped
teacher sees both from step 0 and steers its approach by them (docs/research/student_gmm.md). Here the teacher's
ACTOR reads the object's pose, velocities and planar distance as 0 while no load cell reads above TOUCH_N (the
student's own uniaxial reading, so the reveal happens exactly when the student too could know of a contact). The
critic still sees everything (asymmetric actor-critic). PPO continues the shipped teacher's run from its iteration
2099 with this actor input, the `cpu` PPO settings and `cpu_bc_capsule`'s object weights.

    python blind_approach.py train OUT_DIR ITERATIONS [ARGS]  fine-tune (resumes like blindgrasp-train-teacher)
    python blind_approach.py eval TEACHER OBJECTS OUT.json   masked teacher, same start states as lerobot-eval
    python blind_approach.py collect <blindgrasp-collect-demos arguments>   demos of the masked teacher
"""
import dataclasses
import json
import shutil
import subprocess
import sys
from pathlib import Path

import torch

sys.path.insert(0, str(Path(__file__).resolve().parents[2] / "student_gmm" / "scripts"))
from episodes import successes  # noqa: E402  (the shared episode loop of the student_gmm scripts)

from lerobot_blindgrasp.sim import objects
from lerobot_blindgrasp.teacher.blind_approach import TOUCH_N, mask_before_touch
from lerobot_blindgrasp.teacher.policy import TeacherPolicy

START = "docs/research/teacher_runs/shipped_from_scratch/model_2099.pt"  # at git tag teacher-experiments


class BlindApproachTeacher(TeacherPolicy):
    def __call__(self, obs, stochastic: bool = False):
        return super().__call__({**obs, "privileged": mask_before_touch(obs["privileged"])}, stochastic=stochastic)


def train(out: Path, iterations: int, extra: list[str]) -> None:
    from lerobot_blindgrasp.presets import teacher as presets
    from lerobot_blindgrasp.teacher import train as trainer
    from lerobot_blindgrasp.teacher.vecenv import RslRlGraspEnv

    runner = presets.CPU.runner_cfg()
    runner["obs_groups"] = {"actor": ["privileged"], "critic": ["privileged_full"]}
    preset = dataclasses.replace(
        presets.CPU_BC_CAPSULE, name="cpu_bc_blind_approach", max_iterations=iterations, continues=None,
        runner=runner,
        deviations=presets.CPU_BC_CAPSULE.deviations + (
            "from iteration 2100 (the shipped teacher), the actor reads the object's pose, velocities and planar "
            f"distance as 0 while no load cell reads above {TOUCH_N} N; the critic sees everything",),
    )
    presets.PRESETS[preset.name] = preset
    to_td = RslRlGraspEnv._to_td

    def masked_to_td(self, obs):
        return to_td(self, {**obs, "privileged": mask_before_touch(obs["privileged"]), "privileged_full": obs["privileged"]})

    RslRlGraspEnv._to_td = masked_to_td
    out.mkdir(parents=True, exist_ok=True)
    if not list(out.glob("model_*.pt")):
        blob = subprocess.run(["git", "show", f"teacher-experiments:{START}"], capture_output=True, check=True).stdout
        (out / "model_2099.pt.tmp").write_bytes(blob)
        shutil.move(out / "model_2099.pt.tmp", out / "model_2099.pt")
    trainer.main([f"--output_dir={out}", f"--preset={preset.name}", "--threads=2", *extra])


if __name__ == "__main__" and sys.argv[1] == "train":
    train(Path(sys.argv[2]), int(sys.argv[3]), sys.argv[4:])

if __name__ == "__main__" and sys.argv[1] == "eval":
    torch.set_num_threads(1)
    teacher, names, out = BlindApproachTeacher(sys.argv[2]), objects.resolve_objects(sys.argv[3]), sys.argv[4]
    res = {}
    for name in names:
        res[name] = successes(name, lambda t, obs, env: teacher(obs))
        print(name, sum(res[name]), flush=True)
    print("all", sum(map(sum, res.values())), "/", sum(map(len, res.values())))
    Path(out).write_text(json.dumps(res, separators=(",", ":")))

if __name__ == "__main__" and sys.argv[1] == "collect":
    import lerobot_blindgrasp.teacher.policy as teacher_policy
    from lerobot_blindgrasp.demos.collect import main

    teacher_policy.TeacherPolicy = BlindApproachTeacher
    main(sys.argv[2:])
