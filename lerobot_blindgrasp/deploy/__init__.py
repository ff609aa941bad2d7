"""Deploying a trained policy on the real gripper: `blindgrasp-rollout` (`run_policy.py`)."""
