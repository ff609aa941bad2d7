#!/bin/bash
# The same objects and start states in the sim env: --env.type=blindgrasp, seed 1000, 10 episodes per object.
#   docs/results/twin/sim_eval.sh OUT      (from the repository root; 26 min on the shared 2-core machine)
export HF_HUB_OFFLINE=1 MUJOCO_GL=egl OMP_NUM_THREADS=1
exec nice -n 10 .venv/bin/lerobot-eval --policy.path=models/student_cpu --policy.device=cpu --env.type=blindgrasp \
  --env.task=all --eval.n_episodes=10 --eval.batch_size=10 --eval.use_async_envs=false --seed=1000 \
  --env.render_stride=20 --env.render_episodes=0 --output_dir="${1:?output folder}"
