"""How far from the training randomization the blind student still grasps: the robustness sweep
(`python -m lab.robustness.sweep`, `sweep.py`), its factors and presets (`factors.py`), and the envelope it measures
(`envelope.py`, without MuJoCo, which writes the robustness section of a student's card). A lab tool, run from a
clone: the sweep is a measurement campaign, not part of the wheel."""
