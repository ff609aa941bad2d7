"""The lab: benchmarks, the physics twin's measurement campaign, research diagnosis tools and one-off experiments.

Not part of the wheel (setup.py packages `lerobot_blindgrasp` alone): everything here runs from a clone, at the
repository root, as `python -m lab.<tool>`. The lab imports the package; the package never imports the lab
(tests/repo/test_layout.py checks both).

    python -m lab.bench --bench.type=sim --bench.num_envs=36       # benchmarks (lab/bench/)
    python -m lab.twin_campaign.measure --output_dir=OUT           # the shipped student on the physics twin
    python -m lab.robustness.sweep --preset=smoke --output_dir=OUT # the student beyond its training randomization
    python -m lab.table_v --output_dir=OUT                         # Table V from scripts/paper_recipe.sh's folder
    python -m lab.diagnosis.student_diagnosis --help               # why a student trails its teacher
    python -m lab.structure                                        # lines per folder, files, import arrows
    python -m lab.run_records --unpack=REC.json --to=DIR            # a recorded run's folder from its one-file record
    python -m lab.contact_settings_sweep --help                    # the sim's contact settings against creep
"""
