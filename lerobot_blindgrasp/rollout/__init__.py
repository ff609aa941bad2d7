"""The rollout layer between `sim/` + `policies/` and the tools that run episodes: the env factory (`envs.py`), the
episode loop and its outcome record (`loop.py`), and the actors it runs, student and teacher (`actors.py`)."""
