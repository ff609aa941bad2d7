"""Deploying a trained policy on the real gripper: `blindgrasp-rollout` (`run_policy.py`, LeRobot's rollout engine
with the fingertip forces kept in the policy input) and the record of what a checkpoint was trained for
(`policy_contract.py`), which the robot checks before any torque. The robot itself is `robots/blindgrasp_gripper/`.
"""
