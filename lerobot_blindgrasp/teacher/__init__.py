"""PPO teacher on privileged observations (paper Sec. III-B), with rsl-rl-lib's OnPolicyRunner."""
