"""Table V from a recipe output folder: rows paired per object, intervals, missing rows named, each row's
teacher recipe as its run recorded it."""

import json

from lab import table_v
from lerobot_blindgrasp.presets import TABLE_V
from lerobot_blindgrasp.sim import objects


def _student_eval(path, per_object):
    names = list(objects.CATALOGUE)
    tasks = [
        {"task_group": "blindgrasp", "task_id": names.index(o), "metrics": {"successes": s, "video_paths": []}}
        for o, s in per_object.items()
    ]
    path.mkdir(parents=True)
    (path / "eval_info.json").write_text(json.dumps({"per_task": tasks}))


def test_table_v_reads_student_and_rl_rows_and_names_the_missing(tmp_path):
    _student_eval(
        tmp_path / "eval_proposed",
        {"sphere_medium": [True, True, False, True], "capsule_small": [False, False, False, False]},
    )
    _student_eval(
        tmp_path / "eval_wo_curation",
        {"sphere_medium": [True, False, False, False], "capsule_small": [False, False, False, False]},
    )
    (tmp_path / "demos_proposed").mkdir()
    (tmp_path / "demos_proposed" / "yield_report.json").write_text(
        json.dumps({"total": {"kept": 80, "frames": 7000, "rollouts": 160}})
    )
    # Which teacher made each row, as the runs recorded it: the demos' provenance, the RL teacher's own config.
    (tmp_path / "demos_proposed" / "collection.json").write_text(
        json.dumps(
            {
                "teacher": {
                    "checkpoint_name": "teacher_cpu_bc/teacher.safetensors",
                    "iteration": 2099,
                    "preset": "cpu_bc_capsule",
                    "variant": {"no_incentive": False, "student_obs": False},
                }
            }
        )
    )
    rl = TABLE_V["rl_w_o_t"].teacher
    (tmp_path / f"{rl}_eval").mkdir()
    (tmp_path / f"{rl}_eval" / "eval.json").write_text(
        json.dumps(
            {
                "checkpoint": f"elsewhere/{rl}/model_1397.pt",
                "iteration": 1397,
                "modes": {
                    "deterministic": {
                        "per_object": {
                            "sphere_medium": {"successes": [False] * 4},
                            "capsule_small": {"successes": [False] * 4},
                        }
                    }
                },
            }
        )
    )
    (tmp_path / rl).mkdir()
    (tmp_path / rl / "teacher_config.json").write_text(
        json.dumps({"preset": "cpu", "variant": {"no_incentive": False, "student_obs": True}})
    )

    md = table_v.write_table_v(tmp_path).read_text()
    assert (tmp_path / "table_v.png").stat().st_size > 1000
    # Last column: the object's success averaged over the three rows, (75 + 25 + 0) / 3.
    assert "| sphere_medium | 75 % [30-95] (3/4) | 25 % [5-70] (1/4) | 0 % [0-49] (0/4) | 33.3 % |" in md
    assert "| **all 2** | **37.5 % [13.7-69.4] (3/8)** |" in md  # proposed, pooled over both objects
    assert "| **1 medium** | **75.0 % [30.1-95.4] (3/4)** |" in md
    assert "80 episodes, 7000 frames (from 160 rollouts)" in md and "no demos (PPO on o_t)" in md
    # Each row's teacher recipe, with whether it clones scripted grasps.
    assert (
        "| Student (Proposed) | `cpu_bc_capsule`, iterations 0..2099, PPO with scripted-grasp cloning "
        "(teacher_cpu_bc/teacher.safetensors) | 80 episodes"
    ) in md
    assert (
        "| RL w/ o_t | `cpu` --student_obs=true, iterations 0..1397, PPO only (no cloning) (model_1397.pt) | "
        "no demos (PPO on o_t) |"
    ) in md
    assert "| Student w/o Curation | not collected | not collected |" in md
    assert "Not run yet: Student w/o Stochastic Teacher, Student w/o r_i." in md
    # Paired with the proposed row: w/o curation loses sphere episodes 2 and 4 and wins none (p = 2 x 1/4); RL w/
    # o_t loses all three the proposed student solved (p = 2 x 1/8).
    assert "| Student w/o Curation | -25.0 pp | 2 | 0 | 0.5 |" in md
    assert "| RL w/ o_t | -37.5 pp | 3 | 0 | 0.25 |" in md


def test_a_row_with_other_episode_counts_is_listed_as_not_paired(tmp_path):
    _student_eval(tmp_path / "eval_proposed", {"sphere_medium": [True, True, False, True]})
    _student_eval(tmp_path / "eval_wo_curation", {"sphere_medium": [True, False]})
    md = table_v.write_table_v(tmp_path).read_text()
    assert "| Student w/o Curation | not paired: 2 episodes vs 4 | | | |" in md
