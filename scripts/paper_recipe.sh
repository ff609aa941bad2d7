#!/usr/bin/env bash
# The paper-scale recipe for a GPU machine (or a big CPU box), including the ablations of Table V.
# Every stage is the same CLI the quick pipeline runs; only the presets and sizes change. Runs resume when re-run.
#
#   bash scripts/paper_recipe.sh [OUT_DIR]
#
# Notes:
# - The teacher's physics runs on CPU threads (MuJoCo's batch API); with many cores set --threads accordingly.
#   The paper used 9000 envs (Table III); on a 16-core box expect roughly 10x the 2-core throughput.
# - lerobot-train uses the GPU when --policy.device=cuda.
set -euo pipefail
ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
source "$ROOT/scripts/bootstrap.sh"
OUT="${1:-$ROOT/outputs/paper}"
DEVICE="${DEVICE:-cuda}"
mkdir -p "$OUT"

# 1. Teachers: the proposed one, the w/o r_i teacher, and the "RL w/ o_t" baseline (Table V).
blindgrasp-train-teacher --preset paper --output-dir "$OUT/teacher"
blindgrasp-train-teacher --preset paper --no-incentive --output-dir "$OUT/teacher_no_ri"
blindgrasp-train-teacher --preset paper --student-obs --output-dir "$OUT/rl_with_ot"
for t in teacher teacher_no_ri rl_with_ot; do
  blindgrasp-eval-teacher "$OUT/$t" --episodes 50 --out "$OUT/$t/eval"
done

# 2. Demonstrations (Sec. III-C): stochastic + curated (proposed), deterministic teacher, no curation, w/o r_i.
N=5000  # episodes per object: ~89,500 curated demos over 18 objects
blindgrasp-collect-demos --teacher "$OUT/teacher" --out "$OUT/demos" --repo-id local/blindgrasp_demos \
  --episodes-per-object $N --num-envs 9000
blindgrasp-collect-demos --teacher "$OUT/teacher" --out "$OUT/demos_deterministic" \
  --repo-id local/blindgrasp_demos_deterministic --deterministic --episodes-per-object $N --num-envs 9000
blindgrasp-collect-demos --teacher "$OUT/teacher" --out "$OUT/demos_uncurated" \
  --repo-id local/blindgrasp_demos_uncurated --no-curation --episodes-per-object $N --num-envs 9000
blindgrasp-collect-demos --teacher "$OUT/teacher_no_ri" --out "$OUT/demos_no_ri" \
  --repo-id local/blindgrasp_demos_no_ri --no-curation --episodes-per-object $N --num-envs 9000

# 3. Students (Table IV: paper size is the default; 2000 epochs of 89.5k samples at batch 256 = 700k steps).
for d in demos demos_deterministic demos_uncurated demos_no_ri; do
  [ -d "$OUT/student_$d/checkpoints/last" ] && continue
  lerobot-train --policy.type=blindgrasp_transformer --dataset.repo_id="local/blindgrasp_$d" \
    --dataset.root="$OUT/$d" --output_dir="$OUT/student_$d" --batch_size=256 --steps=700000 \
    --policy.push_to_hub=false --policy.device="$DEVICE" --wandb.enable=false
done

# 4. Evaluation in sim on the 6 medium (ID) objects, as the paper's ablation table.
for d in demos demos_deterministic demos_uncurated demos_no_ri; do
  lerobot-eval --policy.path="$OUT/student_$d/checkpoints/last/pretrained_model" --env.type=blindgrasp \
    --env.task=medium --eval.n_episodes=50 --policy.device="$DEVICE" --output_dir="$OUT/eval_$d"
done
