#!/bin/bash
# Device cells of docs/results/paper_scale_plan.md, in two calls that share one warm machine:
#   bash .gpu/a/run.sh student   (carry .gpu/a: half of warp.so, LeRobot's wheels, the package, the dataset)
#   bash .gpu/b/run.sh teacher   (carry .gpu/b: the other half of warp.so, MuJoCo, MuJoCo Warp, rsl-rl)
# Every result goes to $OUT as soon as it exists, so a run cut short still returns what it measured.
set -u
phase=$1
R=$PWD
G=$R/.gpu
S=${SITE:-/tmp/site48}
# Knobs for a dry run on a CPU machine (defaults: the device run)
DEV=${DEV:-cuda} SIZE=${SIZE:-paper} BATCH=${BATCH:-256} TRAIN_STEPS=${TRAIN_STEPS:-200}
BACKEND=${BACKEND:-warp} NENVS=${NENVS:-9000} ITERS=${ITERS:-3}
export PYTHONUNBUFFERED=1 HF_HUB_OFFLINE=1 OMP_WAIT_POLICY=PASSIVE
PKG=$G/a/pkg
[ -d $G/b/pkg ] && PKG=$G/b/pkg
export PYTHONPATH=$PKG:$S:$G/a/stubs
t0=$(date +%s)
log() { echo "[$(date -u +%T) +$(($(date +%s) - t0))s] $*"; }
install() { python3 -m pip install -q --no-index --no-deps --no-compile --no-cache-dir --upgrade --target $S "$@" 2>&1 | grep -v WARNING | tail -3; }
bench() {  # bench NAME TIMEOUT ARGS...: one blindgrasp-bench run, JSON to $OUT/NAME.json, log to $OUT/NAME.log
  local name=$1 limit=$2; shift 2
  log "bench $name: $*"
  (cd /tmp && timeout $limit python3 -c "import sys; from lerobot_blindgrasp.bench import main; main(sys.argv[1:])" \
    "$@" --bench.json=true > $OUT/$name.json 2> $OUT/$name.log)
  log "bench $name: rc $? ; $(tail -c 300 $OUT/$name.log | tr '\n' ' ')"
}

{
  echo "phase $phase, $(date -u -Is)"
  nvidia-smi --query-gpu=name,memory.total,driver_version,clocks.max.sm --format=csv
  echo "cpus $(nproc)"; free -g | head -2; uname -r
  python3 -c "import torch, numpy; print('torch', torch.__version__, 'numpy', numpy.__version__, torch.cuda.get_device_name())"
} > $OUT/${phase}_machine.txt 2>&1
cat $OUT/${phase}_machine.txt

[ -f $S/.a_done ] || { install $G/a/wheels/*.whl && touch $S/.a_done; }
log "installed LeRobot's wheels"

if [ "$phase" = student ]; then
  # the update and each data path on the device's CPU, then the real lerobot-train on both paths (each its own JSON)
  bench student_${SIZE}_$DEV 240 --bench.type=student --bench.dataset_root=$G/a/ds --bench.size=$SIZE \
    --bench.device=$DEV --bench.batch_size=$BATCH --bench.load_samples=200 --bench.update_steps=20 \
    --bench.loader_batches=8 --bench.loader_workers=[0,4] --bench.prefetch_factors=[4] --bench.num_workers=4
  bench student_${SIZE}_${DEV}_lerobot_train 240 --bench.type=student --bench.dataset_root=$G/a/ds \
    --bench.size=$SIZE --bench.device=$DEV --bench.batch_size=$BATCH --bench.load_samples=30 --bench.update_steps=2 \
    --bench.loader_batches=0 --bench.train_steps=$TRAIN_STEPS --bench.log_freq=50 --bench.num_workers=4
  exit 0
fi

# teacher: warp.so from its two halves, then MuJoCo, MuJoCo Warp, warp's Python part and rsl-rl
if [ ! -f $G/a/w1.part ]; then log "FATAL: .gpu/a is gone (a fresh machine): warp cannot be assembled"; exit 3; fi
install $G/b/wheels/*.whl
tar -xJf $G/b/warp_py.tar.xz -C $S
mkdir -p $S/warp/bin
cat $G/a/w1.part $G/b/w2.part | python3 -c "import lzma, shutil, sys; shutil.copyfileobj(lzma.open(sys.stdin.buffer), sys.stdout.buffer)" > $S/warp/bin/warp.so
sha256sum $S/warp/bin/warp.so | tee $OUT/warp_so.sha256
log "warp assembled; expected $(cat $G/b/warp_so.sha256)"
(cd /tmp && python3 -c "import warp as wp; wp.init(); print(wp.__version__, wp.get_cuda_devices())") 2>&1 | tail -3
if [ "$BACKEND" = batch ]; then rm -rf $S/warp; fi  # dry run: the CPU machine's own warp, if any
# the teacher bench first: raw physics and the whole PPO loop at the paper preset's 9000 envs (it compiles Warp's
# kernels into ~/.cache/warp, which the sim bench then reuses for env steps/s)
bench teacher_${BACKEND}_paper 360 --bench.type=teacher --bench.backend=$BACKEND --bench.preset=paper \
  --bench.num_envs=$NENVS --bench.iterations=$ITERS
bench sim_${BACKEND}_$NENVS 200 --bench.type=sim --bench.backend=$BACKEND --bench.num_envs=$NENVS --bench.steps=24 \
  --bench.blocks=2
log "done"
