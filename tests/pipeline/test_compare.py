"""`python -m lerobot_blindgrasp.results.compare`: two evaluations paired start state by start state."""

import json

import pytest

from lerobot_blindgrasp.results import compare
from lerobot_blindgrasp.sim import objects


def _lerobot_eval(path, per_object):
    names = list(objects.CATALOGUE)
    tasks = [
        {"task_group": "blindgrasp", "task_id": names.index(o), "metrics": {"successes": s}}
        for o, s in per_object.items()
    ]
    path.mkdir(parents=True)
    (path / "eval_info.json").write_text(json.dumps({"per_task": tasks}))


def _teacher_eval(path, per_object, mode="deterministic"):
    path.mkdir(parents=True)
    modes = {mode: {"per_object": {o: {"successes": s} for o, s in per_object.items()}}}
    (path / "eval.json").write_text(json.dumps({"modes": modes}))


def test_a_student_and_a_teacher_eval_are_paired_episode_by_episode(tmp_path, capsys):
    _teacher_eval(
        tmp_path / "t",
        {"sphere_small": [True, True, False, False], "cuboid_a_large": [True] * 4, "everyday_mug": [True] * 4},
    )
    _lerobot_eval(
        tmp_path / "s",
        {"sphere_small": [True, False, True, True], "cuboid_a_large": [True] * 4, "everyday_mug": [True] * 4},
    )
    compare.main(
        [
            f"--a={tmp_path / 't'}",
            f"--b={tmp_path / 's' / 'eval_info.json'}",
            "--a_label=teacher",
            "--b_label=student",
        ]
    )
    md = capsys.readouterr().out
    # The student alone solved start states 3 and 4 of the small sphere, the teacher alone 2.
    # Rows in the paper's object order, then the everyday objects (held-out evaluations pair too).
    assert md.index("cuboid_a_large") < md.index("sphere_small") < md.index("everyday_mug")
    assert "| sphere_small | 50 % [15-85] (2/4) | 75 % [30-95] (3/4) | 1 | 2 |" in md
    assert "| **all 3** | **83.3 % [55.2-95.3] (10/12)** | **91.7 % [64.6-98.5] (11/12)** | **1** | **2** |" in md
    assert "student minus teacher: +8.3 percentage points over 12 paired episodes; exact McNemar p = 1." in md


def test_unpairable_or_missing_evaluations_are_clear_errors(tmp_path):
    _lerobot_eval(tmp_path / "a", {"sphere_small": [True, False]})
    _lerobot_eval(tmp_path / "b", {"sphere_small": [True, False, True]})
    _teacher_eval(tmp_path / "t", {"sphere_small": [True, False]}, mode="stochastic")
    a = compare.load_successes(tmp_path / "a")
    with pytest.raises(ValueError, match="2 vs 3 episodes"):
        compare.compare_rates(a, compare.load_successes(tmp_path / "b"))
    with pytest.raises(ValueError, match="not 'deterministic'"):
        compare.load_successes(tmp_path / "t")
    assert compare.load_successes(f"{tmp_path / 't'}:stochastic") == {"sphere_small": [True, False]}
    with pytest.raises(FileNotFoundError, match="no eval_info.json"):
        compare.load_successes(tmp_path / "nothing")
    with pytest.raises(SystemExit, match="b"):  # both evaluations are required
        compare.main([f"--a={tmp_path / 'a'}"])
