"""The one preset registry: complete entries, one object read by the pipeline, the teacher CLI and the student
policy, the paper's numbers, the Table V rows, and student steps derived from the collected dataset."""

from __future__ import annotations

import dataclasses
import json
import subprocess
import sys
from pathlib import Path

import pytest

from lerobot_blindgrasp import presets
from lerobot_blindgrasp.cli import parse_config
from lerobot_blindgrasp.pipeline import recipe
from lerobot_blindgrasp.pipeline import run as pipeline
from lerobot_blindgrasp.policies.blindgrasp_transformer import configuration_blindgrasp_transformer as student_cfg
from lerobot_blindgrasp.presets import ablations, teacher_configs
from lerobot_blindgrasp.presets import teacher as teacher_presets
from lerobot_blindgrasp.sim import objects, rewards
from lerobot_blindgrasp.teacher.train import TrainTeacherConfig

ROOT = Path(__file__).resolve().parents[2]


def test_every_entry_is_complete():
    assert set(presets.PRESETS) == {
        "smoke",
        "quick",
        "cpu",
        "paper",
        "quick_dagger",
        "cpu_dagger",
        "quick_blind",
        "quick_blind_targeted",
    }
    for name, p in presets.PRESETS.items():
        assert p.name == name
        for part in (p.teacher, p.demos, p.student, p.evaluation):
            for f in dataclasses.fields(part):
                value = getattr(part, f.name)
                optional = f.name in (
                    "iterations",
                    "num_envs",
                    "steps",
                    "epochs",
                    "constant_lr_epochs",
                    "constant_lr_steps",
                    "lr",
                    "shipped_folder",
                )
                assert value is not None or optional, (name, f.name)
        assert p.teacher.settings is teacher_presets.TEACHER_PRESETS[p.teacher.settings.name]
        assert p.student.size in presets.SIZES
        assert p.demos.max_rollouts_per_object >= p.demos.episodes_per_object
        assert p.evaluation.episodes_per_object >= (20 if name != "smoke" else 1)  # the evaluation protocol
        assert objects.resolve_objects(p.evaluation.task)
        for obj, _ in p.demos.extra_episodes:
            assert objects.resolve_objects(obj) == (obj,), name
        if p.dagger is not None:
            assert objects.resolve_objects(p.dagger.objects), name
        assert p.all_deviations and all(isinstance(d, str) and d for d in p.all_deviations), name


def test_pipeline_teacher_and_student_read_the_same_objects():
    assert teacher_configs.Variant is presets.Variant
    for name in ("paper", "cpu", "quick"):
        assert presets.get(name, "teacher") is presets.teacher.TEACHER_PRESETS[name]
    assert student_cfg.SIZES is presets.SIZES
    c = student_cfg.BlindgraspTransformerConfig(size="cpu", device="cpu")
    cpu = presets.SIZES["cpu"]
    assert c.n_layers == cpu["n_layers"] and c.head_hidden_dims == cpu["head_hidden_dims"]
    cfg = parse_config(TrainTeacherConfig, ["--preset=cpu_bc_capsule", "--output_dir=x"])
    # The cpu pipeline trains the shipped teacher's recipe from scratch
    assert presets.get(cfg.preset, "teacher") is presets.PRESETS["cpu"].teacher.settings
    assert presets.PRESETS["cpu"].teacher.settings is presets.SHIPPED_TEACHER_PRESET


def test_paper_is_tables_iii_and_iv():
    p = presets.PRESETS["paper"]
    assert p.teacher.settings is teacher_presets.PAPER and p.teacher.settings.deviations == ()
    assert not p.teacher.shipped and p.teacher.iterations is None and p.teacher.num_envs is None
    assert presets.SIZES["paper"] == {
        "n_layers": 6,
        "embed_dim": 512,
        "n_heads": 8,
        "head_hidden_dims": [1024, 1024],
    }
    s = p.student
    assert (s.size, s.batch_size, s.epochs, s.constant_lr_epochs, s.steps) == ("paper", 256, 2000, 100, None)
    # Table V is on the six medium (in-distribution) shapes.
    assert objects.resolve_objects(p.evaluation.task) == objects.resolve_objects("medium")


def test_quick_and_cpu_pipeline_numbers_are_unchanged():
    q, c = presets.PRESETS["quick"], presets.PRESETS["cpu"]
    assert (
        q.demos.episodes_per_object,
        q.demos.max_rollouts_per_object,
        q.demos.num_envs,
        q.demos.min_curated_episodes,
    ) == (40, 400, 720, 18)
    assert (q.student.size, q.student.steps, q.student.batch_size) == ("cpu", 1200, 128)
    assert (q.student.threads, q.student.num_workers) == (1, 1)  # one loader process next to one torch thread
    assert (q.evaluation.episodes_per_object, q.evaluation.teacher_modes) == (20, ("deterministic",))
    # 100 demos per object: ~8 passes of the cpu student over them (measured 2026-11-30)
    assert (
        c.demos.episodes_per_object,
        c.demos.max_rollouts_per_object,
        c.demos.num_envs,
        c.demos.min_curated_episodes,
    ) == (100, 1000, 720, 90)
    assert (c.student.steps, c.student.batch_size) == (5000, 256)


def test_the_main_job_preset_is_the_blind_teacher_and_says_it_goes_beyond_the_paper(tmp_path, monkeypatch):
    """quick_blind: the shipped calibration-blind teacher (its recorded run config is its preset's), the quick demos,
    a shorter student stage at a higher LR that reaches lerobot-train, and every report word says beyond the paper."""
    q, b = presets.PRESETS["quick"], presets.PRESETS["quick_blind"]
    assert pipeline.PipelineConfig().preset == "quick_blind"  # README command 1
    assert b.teacher.shipped and b.teacher.settings is teacher_presets.CPU_BC_CALIB_BLIND
    folder = ROOT / "models" / b.teacher.shipped_folder
    rec = json.loads((folder / "teacher_config.json").read_text())
    assert rec["preset"] == b.teacher.settings.name and rec["runner"] == b.teacher.settings.runner_cfg()
    assert rec["actor_input"] == b.teacher.settings.actor_input.as_record()
    assert rec["deviations"] == list(b.teacher.settings.deviations)
    assert b.blind_teacher and not q.blind_teacher
    assert b.student_recipe.startswith("beyond the paper") and "approaches blind" in b.student_recipe
    assert "reading off by +-0.05 rad" in b.student_recipe
    assert q.student_recipe.startswith("the paper's")
    assert any("teacher_cpu_bc_calib" in d for d in b.deviations.values()) and not any(
        "1200 steps" in d for d in b.deviations.values()
    )
    # only the teacher, the demos' calibration offset (the teacher's training one) and the student stage differ
    assert b.demos == dataclasses.replace(q.demos, joint_calibration_rad=0.05) and b.evaluation == q.evaluation
    assert "--joint_calibration_rad=0.05" in recipe.demos_collect(b, folder, tmp_path / "d", "x/y", 1)
    assert not any("calibration" in c for c in recipe.demos_collect(q, folder, tmp_path / "d", "x/y", 1))
    monkeypatch.delenv("BLINDGRASP_TEACHER", raising=False)
    path, about = pipeline.teacher_for_run(pipeline.Stage(tmp_path, {}), b, tmp_path, 1, given=None)
    assert path == folder and about["source"] == "shipped" and about["preset"] == b.teacher.settings.name
    assert (
        pipeline.teacher_for_run(pipeline.Stage(tmp_path, {}), q, tmp_path, 1, given=None)[0].name
        == "teacher_cpu_bc"
    )
    cmd, sched = recipe.lerobot_train(b.student, tmp_path / "demos", "local/x", tmp_path / "student", seed=1)
    assert (sched.steps, sched.constant_lr_steps) == (700, 350)
    assert {"--steps=700", "--policy.scheduler_constant_steps=350", "--policy.optimizer_lr=0.0005"} <= set(cmd)
    quick_cmd = recipe.lerobot_train(q.student, tmp_path, "x", tmp_path, 1)[0]
    assert "--num_workers=2" in cmd and "--num_workers=1" in quick_cmd
    assert not any(c.startswith("--policy.optimizer_lr") for c in quick_cmd)
    with pytest.raises(ValueError, match="constant_lr_steps needs steps"):
        presets.StudentStage(size="cpu", batch_size=8, epochs=2, constant_lr_steps=3)
    with pytest.raises(ValueError, match="must be > 0"):
        presets.StudentStage(size="cpu", batch_size=8, steps=2, lr=0.0)


def test_the_shipped_students_preset_aims_demos_and_dagger_at_the_small_capsule(tmp_path):
    """quick_blind_targeted: quick_blind with the 1200-step student, 240 more small-capsule demos from their own
    start states, and DAgger on the small capsule only; every word of it says beyond the paper."""
    b, t = presets.PRESETS["quick_blind"], presets.PRESETS["quick_blind_targeted"]
    assert t.teacher == b.teacher and t.evaluation == b.evaluation
    assert t.demos == dataclasses.replace(b.demos, extra_episodes=(("capsule_small", 240),))
    assert t.dagger == presets.DaggerStage(
        episodes_per_object=80, steps=1200, num_envs=80, objects="capsule_small"
    )
    words = t.student_recipe
    assert words.startswith("beyond the paper") and "240 more curated episodes of capsule_small" in words
    assert "80 student episodes of capsule_small" in words and "approaches blind" in words
    assert sum(d.startswith("beyond the paper") for d in t.deviations.values()) == 4
    assert not any(d.startswith("700 steps") for d in t.deviations.values())
    cmd = recipe.lerobot_train(t.student, tmp_path, "x", tmp_path, 1)[0]
    assert {"--steps=1200", "--policy.scheduler_constant_steps=600", "--policy.optimizer_lr=0.0005"} <= set(cmd)
    # The extra collection: one object, the collector's default budget, start states of its own.
    teacher = tmp_path / "teacher"
    extra = recipe.demos_collect(
        t, teacher, tmp_path / "e", "x/e", recipe.extra_demo_seed(1, 0), extra=("capsule_small", 240)
    )
    assert {
        "--objects=capsule_small",
        "--episodes_per_object=240",
        "--max_rollouts_per_object=4800",
        "--joint_calibration_rad=0.05",
    } <= set(extra)
    main = recipe.demos_collect(t, teacher, tmp_path / "d", "x/d", recipe.demo_seed(1))
    assert not any(c.startswith("--objects") for c in main) and "--episodes_per_object=40" in main
    starts = [
        recipe.demo_seed(1),
        recipe.extra_demo_seed(1, 0),
        recipe.extra_demo_seed(1, 3),
        recipe.demo_seed(1) + recipe.DEMO_SEED_BLOCK // 2,
        recipe.extra_demo_seed(1, 0, curated=False),
        recipe.extra_demo_seed(1, 3, curated=False),
        recipe.demo_seed(2),
    ]
    # Each block holds its whole rollout budget, so no two collections share a start state.
    assert all(b - a >= 4800 for a, b in zip(starts, starts[1:]))
    with pytest.raises(ValueError, match="at most 4"):
        recipe.extra_demo_seed(1, 4)
    dag = recipe.dagger(t, tmp_path / "s", teacher, tmp_path / "d", tmp_path / "g", 5)
    assert {"--objects=capsule_small", "--episodes_per_object=80", "--num_envs=80"} <= set(dag)
    assert "--objects=all" in recipe.dagger(
        presets.PRESETS["quick_dagger"], tmp_path, teacher, tmp_path, tmp_path, 5
    )
    with pytest.raises(ValueError, match="at least one episode"):
        dataclasses.replace(t.demos, extra_episodes=(("capsule_small", 0),))
    with pytest.raises(ValueError, match="twice"):
        dataclasses.replace(t.demos, extra_episodes=(("capsule_small", 1), ("capsule_small", 2)))


# The one recorded run that is not resumable: its object allocation was tried under the `cpu` name and not kept
# (teacher_cpu_v2.md of the research record, docs/research.md), so no preset holds it any more.
def test_the_shipped_teachers_record_matches_its_preset():
    """`blindgrasp-train-teacher` resumes only when these keys match, and the registry must still describe the
    shipped teacher: its recorded run config (models/teacher_cpu_bc/teacher_config.json) is its preset's."""
    old = json.loads((ROOT / "models" / "teacher_cpu_bc" / "teacher_config.json").read_text())
    preset = teacher_configs.Variant(**old["variant"]).apply(presets.get(old["preset"], "teacher"))
    assert old["preset"] == presets.SHIPPED_TEACHER_PRESET.name
    assert old["runner"] == preset.runner_cfg()
    assert old["reward"] == preset.reward.as_record()
    assert rewards.RewardConfig.from_record(old["reward"]) == preset.reward
    assert old["object_weights"] == (preset.object_weights and list(preset.object_weights))
    assert old["num_envs"] == preset.num_envs


def test_table_v_rows_and_the_no_r_i_teacher():
    assert [a.label for a in presets.TABLE_V.values()] == [
        "Student (Proposed)",
        "Student w/o Stochastic Teacher",
        "Student w/o Curation",
        "Student w/o r_i",
        "RL w/ o_t",
    ]
    rows = presets.TABLE_V
    assert not rows["wo_stochastic_teacher"].stochastic_demos and rows["wo_stochastic_teacher"].curated_demos
    assert not rows["wo_curation"].curated_demos and not rows["wo_r_i"].curated_demos  # paper: no selection
    assert not rows["rl_w_o_t"].student
    assert all(a.doc for a in rows.values()) and "reach" in rows["wo_r_i"].doc.lower()
    no_ri = presets.TEACHERS[rows["wo_r_i"].teacher].apply(teacher_presets.CPU)
    for term in teacher_configs.CONTACT_REWARD_TERMS:
        assert no_ri.reward.weight(term) == 0.0
    assert no_ri.reward.weight("reach") == teacher_presets.CPU.reward.weight("reach")
    assert no_ri.reward.weight("task") == 1.0
    assert teacher_presets.CPU.reward.weight("touch") > 0  # the preset itself is untouched


def test_paper_student_steps_come_from_the_collected_frames(tmp_path):
    stage = presets.PRESETS["paper"].student
    s = presets.schedule(stage, total_frames=9_000_000)
    assert s.steps_per_epoch == 35_157  # ceil(9e6 / 256)
    assert (s.steps, s.constant_lr_steps) == (2000 * 35_157, 100 * 35_157)
    assert presets.schedule(stage, total_frames=256).steps == 2000  # one step per epoch
    with pytest.raises(ValueError, match="total_frames"):
        presets.schedule(stage, total_frames=None)
    fixed = presets.schedule(presets.PRESETS["quick"].student, total_frames=None)
    assert (fixed.steps, fixed.constant_lr_steps) == (1200, None)  # the policy default: constant lr
    import torch

    opt = torch.optim.AdamW([torch.nn.Parameter(torch.zeros(1))], lr=1e-4)
    sched_default = student_cfg.BlindgraspTransformerConfig(device="cpu").get_scheduler_preset().build(opt, 10)
    assert sched_default.lr_lambdas[0](9) == 1.0  # no decay unless the constant steps are given
    # The lerobot-train command reads total_frames from the dataset's meta/info.json.
    (tmp_path / "meta").mkdir()
    (tmp_path / "meta" / "info.json").write_text(json.dumps({"total_frames": 1000}))
    cmd, sched = recipe.lerobot_train(
        presets.PRESETS["paper"].student, tmp_path, "local/x", tmp_path / "s", seed=1
    )
    assert sched.steps_per_epoch == 4 and "--steps=8000" in cmd and "--batch_size=256" in cmd
    assert "--policy.scheduler_constant_steps=400" in cmd and "--policy.size=paper" in cmd


def test_pipeline_config_spellings():
    new = parse_config(pipeline.PipelineConfig, ["--preset=smoke", "--output_dir=o", "--eval_seed=1001"])
    spaced = parse_config(
        pipeline.PipelineConfig, ["--preset", "smoke", "--output_dir", "o", "--eval_seed", "1001"]
    )
    assert new == spaced and new.output_dir == Path("o") and new.eval_seed == 1001
    assert parse_config(pipeline.PipelineConfig, []).output_dir == Path("outputs/pipeline_quick_blind")
    with pytest.raises(SystemExit, match="unknown preset"):
        parse_config(pipeline.PipelineConfig, ["--preset=huge"])


def test_table_v_commands_for_the_recipe(tmp_path):
    p = presets.PRESETS["smoke"]
    teachers = recipe.table_v(p, tmp_path, "teachers")
    assert [c[-1] for c in teachers[1:]] == ["--no_incentive=true", "--student_obs=true"]
    demos = recipe.table_v(p, tmp_path, "demos")
    seeds = {a for c in demos for a in c if a.startswith("--seed=")}
    assert len(demos) == 4 and len(seeds) == 1  # the same start states for every row
    assert "--stochastic=false" in demos[1]
    assert "--curation.enabled=false" in demos[2] and "--curation.enabled=false" in demos[3]
    with pytest.raises(ValueError, match="demos stage first"):
        recipe.table_v(p, tmp_path, "students")
    # A row whose collection kept nothing has no student: a comment line, and the other rows go on.
    for row in presets.TABLE_V.values():
        root = tmp_path / f"demos_{row.name}"
        (root / "meta").mkdir(parents=True)
        (root / "yield_report.json").write_text("{}")
        (root / "meta" / "info.json").write_text(json.dumps({"total_frames": 0 if row.name == "proposed" else 50}))
    lines = recipe.shell_lines(recipe.table_v(p, tmp_path, "students")).splitlines()
    assert lines[0].startswith("# proposed: skipped") and len(lines) == 4
    assert all(line.startswith("lerobot-train ") for line in lines[1:])


def test_report_does_not_import_the_pipeline():
    code = "import sys, lerobot_blindgrasp.pipeline.job_report; sys.exit('lerobot_blindgrasp.pipeline.run' in sys.modules)"
    assert subprocess.run([sys.executable, "-c", code]).returncode == 0


def test_paper_recipe_script_takes_its_commands_from_the_pipeline(tmp_path, capsys):
    script = (ROOT / "scripts" / "paper_recipe.sh").read_text()
    assert "--print_commands" in script
    for restated in ("--episodes", "--steps", "--num-envs", "--batch_size", "9000", "5000", "700000"):
        assert restated not in script, restated
    pipeline.main(["--preset=paper", f"--output_dir={tmp_path}", "--print_commands=teachers"])
    lines = capsys.readouterr().out.splitlines()
    assert len(lines) == 3 and all(line.startswith("blindgrasp-train-teacher --preset=paper") for line in lines)


def test_quick_table_v_teacher_ablations_are_the_recorded_ones(tmp_path):
    """The proposed rows use the shipped teacher; w/o r_i and RL w/ o_t train the shipped recipe's PPO-only prefix
    (`cpu`, iterations 0..1397) with their switch flipped: the commands and checkpoints of the recorded table."""
    from lerobot_blindgrasp import shipped as shipped_files
    from lerobot_blindgrasp.teacher import policy

    shipped = json.loads((shipped_files.path(policy.SHIPPED_TEACHER) / policy.CONFIG_NAME).read_text())
    iterations = shipped["weights"]["iteration"] + 1  # model_<it>.pt holds iterations 0..it
    assert presets.SHIPPED_TEACHER_ITERATIONS == iterations
    assert (
        presets.SHIPPED_TEACHER_PRESET.name == shipped["preset"] == presets.PRESETS["quick"].teacher.settings.name
    )
    teachers = recipe.table_v(presets.PRESETS["quick"], tmp_path, "teachers")
    assert len(teachers) == 2  # the proposed rows use the shipped teacher itself
    assert [c[1:] for c in teachers] == [
        ["--preset=cpu", f"--output_dir={tmp_path / name}", "--seed=1", "--iterations=1398", flag]
        for name, flag in (("teacher_no_ri", "--no_incentive=true"), ("rl_with_ot", "--student_obs=true"))
    ]
    # The recorded table's teacher ablations were made exactly so (their run configs, by row; the exported actors
    # are at git tag research-record-2026-12-05).
    recorded = json.loads((ROOT / "docs" / "results" / "table_v_teachers.json").read_text())
    for row in ("wo_r_i", "rl_w_o_t"):
        run = recorded[row]
        variant = presets.TEACHERS[presets.TABLE_V[row].teacher]
        stage = presets.PRESETS["quick"].teacher_stage(variant)
        assert (run["preset"], run["variant"], run["weights"]["iteration"] + 1, run["seed"]) == (
            stage.settings.name,
            dataclasses.asdict(variant),
            stage.iterations,
            1,
        )
        assert run["runner"] == variant.apply(stage.settings).runner_cfg()


def _teacher_recipe(p: presets.Preset, variant: presets.Variant = presets.Variant()) -> str:
    """Which teacher a row with `variant` uses in preset `p`, in the words the Table V report uses."""
    t = p.teacher_stage(variant)
    words = ablations.teacher_words(t.settings.name, variant, (t.iterations or t.settings.max_iterations) - 1)
    return f"the shipped teacher: {words}" if t.shipped else f"trained by the recipe: {words}"


def test_no_teacher_ablation_clones_scripted_grasps_and_every_row_names_its_teacher():
    assert ablations.has_scripted_cloning(presets.SHIPPED_TEACHER_PRESET)  # staged: both stages clone
    assert ablations.has_scripted_cloning(presets.teacher.CPU_BC_JOINT)
    assert not any(
        ablations.has_scripted_cloning(t)
        for t in (presets.teacher.CPU, presets.teacher.PAPER, presets.teacher.QUICK)
    )
    assert ablations.cloning_start(presets.SHIPPED_TEACHER_PRESET) == 1398  # cpu_bc_joint's cloning begins
    assert ablations.cloning_start(presets.teacher.CPU) is None
    for p in presets.PRESETS.values():
        for row in presets.TABLE_V.values():
            variant = presets.TEACHERS[row.teacher]
            stage, words = p.teacher_stage(variant), _teacher_recipe(p, variant)
            assert f"`{stage.settings.name}`" in words and "iterations 0.." in words, (p.name, row.name)
            if ablations.is_teacher_ablation(variant):
                assert not stage.shipped and not ablations.has_scripted_cloning(stage.settings), (p.name, row.name)
                assert "PPO only (no cloning)" in words and words.startswith("trained by the recipe")
                assert f"--{'no_incentive' if variant.no_incentive else 'student_obs'}=true" in words
            else:
                assert stage is p.teacher
    assert _teacher_recipe(presets.PRESETS["quick"]).startswith("the shipped teacher: `cpu_bc_capsule`")
    assert "scripted-grasp cloning" in _teacher_recipe(presets.PRESETS["quick"])
    # A preset whose teacher ablations would clone is refused where it is defined.
    with pytest.raises(ValueError, match="clones scripted grasps"):
        dataclasses.replace(presets.PRESETS["cpu"], ablation_teacher=None)
    with pytest.raises(ValueError, match="clones scripted grasps"):
        dataclasses.replace(
            presets.PRESETS["paper"], ablation_teacher=presets.TeacherStage(settings=presets.teacher.CPU_BC_JOINT)
        )
