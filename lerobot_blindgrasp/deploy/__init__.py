"""Deploying a trained policy on the real gripper: `blindgrasp-rollout` (`run_policy.py`, LeRobot's rollout engine
with the fingertip forces kept in the policy input). What a checkpoint was trained for, and the check of it against
the robot before any torque, is `lerobot_blindgrasp/policy_contract.py`. The robot itself is `robots/blindgrasp_gripper/`.
"""
