"""How far from the training randomization the blind student still grasps: the robustness sweep
(`blindgrasp-robustness`, `sweep.py`), its factors (`presets/robustness.py`), and the envelope it measures (`envelope.py`,
importable without MuJoCo, which the real gripper's connect-time check reads)."""
