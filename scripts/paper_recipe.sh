#!/usr/bin/env bash
# Table V (the paper's ablations) at a registry preset's sizes: the proposed student, w/o stochastic teacher,
# w/o curation, w/o r_i, and RL w/ o_t. Every number and command line comes from Python (the preset registry,
# lerobot_blindgrasp/presets/, through `blindgrasp-pipeline --print_commands=STAGE`); this script only runs them in
# order and echoes each. Re-running continues: a stage prints only what is not done yet.
#
#   bash scripts/paper_recipe.sh [OUT_DIR]             # PRESET=paper (default) | cpu | quick | smoke
#   DEVICE=cpu PRESET=cpu bash scripts/paper_recipe.sh outputs/table_v_cpu
#
# Notes:
# - The teacher's physics runs on CPU threads (MuJoCo's batch API) unless the teacher is trained with
#   --backend=warp; lerobot-train and lerobot-eval use the GPU with the paper preset's device (cuda).
# - The students' step counts follow from the collected datasets (2000 epochs of their frames for `paper`), so
#   the students stage is printed only after the demos stage has finished.
set -euo pipefail
ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
source "$ROOT/scripts/bootstrap.sh"
PRESET="${PRESET:-paper}"
OUT="${1:-$ROOT/outputs/table_v_$PRESET}"
mkdir -p "$OUT"
device_flag=()
[ -n "${DEVICE:-}" ] && device_flag=(--device="$DEVICE")
# The collector's exit status for "ran, but kept no episode": that row then has no student (said in the log).
EMPTY="$(python -c 'from lerobot_blindgrasp.demos.collect_cli import EXIT_EMPTY; print(EXIT_EMPTY)')"

for stage in teachers teacher_evals demos students evals; do
  cmds="$(blindgrasp-pipeline --preset="$PRESET" --output_dir="$OUT" "${device_flag[@]}" --print_commands="$stage")"
  mapfile -t lines <<< "$cmds"  # read all first: a command reading stdin must not eat the next lines
  for cmd in "${lines[@]}"; do
    [ -z "$cmd" ] && continue
    echo "+ $cmd"
    rc=0
    eval "$cmd" || rc=$?
    if [ "$rc" -ne 0 ] && ! { [ "$stage" = demos ] && [ "$rc" -eq "$EMPTY" ]; }; then
      exit "$rc"
    fi
  done
done
python -m lab.table_v --output_dir="$OUT"   # table_v.md + table_v.png: every row per object, 95 % intervals
echo "Table V runs done under $OUT: teacher evals in *_eval/eval.json, student evals in eval_*/eval_info.json"
