#!/usr/bin/env bash
# The paper preset at the paper's scale on one GPU, in one time-boxed run that writes one JSON
# (lab/bench/paper_bench.py says what each stage measures):
#
#   bash scripts/gpu_run.sh outputs/gpu_run/paper.json               # a GPU machine: 9000 envs, MuJoCo Warp
#   bash scripts/gpu_run.sh outputs/gpu_run/smoke.json --smoke       # anywhere: 18 envs, short stages, same path
#
# Further arguments go to `python -m lab.bench --bench.type=paper` (e.g. --bench.num_envs=4500,
# --bench.stages=[warmup,loop]). Environment:
#   PYTHON              the interpreter (default: .venv/bin/python if there is one, else python3)
#   BLINDGRASP_WHEELS   a folder of wheels to install the gpu extra from, without an index (a machine offline)
#   BLINDGRASP_LIMIT_S  the whole run's limit in seconds (default 570: one 10-minute call with room to spare)
# Stages and their bounds at the defaults: warm-up (Warp compiles its kernels into ~/.cache/warp, or loads them),
# the PPO loop (no timed iteration starts after 120 s of them), demo collection (60 s of collecting, counted once
# the collector has built its env), then the object groups' graphs against one model with per-world geometry
# (lab/bench/onemodel_bench.py: no timing block starts after 60 s of the stage). The JSON is rewritten after each stage, so a run stopped at the limit keeps
# what it finished; the stages it did not reach run in a second call into the same JSON, e.g.
#   bash scripts/gpu_run.sh outputs/gpu_run/paper.json --bench.stages=[demos]
set -euo pipefail
ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
cd "$ROOT"
OUT="${1:?usage: bash scripts/gpu_run.sh OUT.json [--smoke] [--bench.* overrides]}"
shift
SMOKE=()
if [ "${1:-}" = "--smoke" ]; then
  SMOKE=(--bench.num_envs=18 --bench.iterations=1 --bench.env_steps=6 --bench.env_blocks=1 --bench.demo_s=30)
  shift
fi
PY="${PYTHON:-}"
[ -n "$PY" ] || { [ -x .venv/bin/python ] && PY=.venv/bin/python; } || PY=python3
export PYTHONPATH="$ROOT${PYTHONPATH:+:$PYTHONPATH}" MUJOCO_GL="${MUJOCO_GL:-egl}"
export HF_HUB_OFFLINE="${HF_HUB_OFFLINE:-1}" OMP_WAIT_POLICY="${OMP_WAIT_POLICY:-PASSIVE}" PYTHONUNBUFFERED=1

# 1. The gpu extra (MuJoCo Warp), unless this interpreter already has it and the package's own dependencies.
if ! "$PY" -c "import mujoco_warp, warp, rsl_rl, lerobot, lerobot_blindgrasp" >/dev/null 2>&1; then
  echo "installing lerobot_policy_blindgrasp[gpu] into $PY" >&2
  if [ -n "${BLINDGRASP_WHEELS:-}" ]; then
    "$PY" -m pip install -q --no-index --find-links "$BLINDGRASP_WHEELS" -e "$ROOT[gpu]"
  else
    "$PY" -m pip install -q -e "$ROOT[gpu]"
  fi
fi
"$PY" - <<'EOF' >&2
import torch, warp as wp
wp.config.quiet = True
wp.init()
print("torch", torch.__version__, "cuda" if torch.cuda.is_available() else "no cuda",
      torch.cuda.get_device_name(0) if torch.cuda.is_available() else "",
      "| warp", wp.__version__, "kernel cache", wp.config.kernel_cache_dir)
EOF

# 2-5. Warm-up (kernel cache), the PPO loop with raw physics and the env alone, demo collection, one model against
# the groups: one JSON.
mkdir -p "$(dirname "$OUT")"
timeout --signal=INT --kill-after=30 "${BLINDGRASP_LIMIT_S:-570}" \
  "$PY" -m lab.bench --bench.type=paper --bench.backend=warp --bench.output="$OUT" \
  --bench.stages=[warmup,loop,demos,onemodel] "${SMOKE[@]}" "$@"
echo "wrote $OUT" >&2
