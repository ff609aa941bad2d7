"""How far from the training randomization the blind student still grasps: the robustness sweep
(`python -m lab.robustness.sweep`, `sweep.py`), its factors (`factors.py`), and the envelope it measures (`envelope.py`,
importable without MuJoCo, which the real gripper's connect-time check reads)."""
