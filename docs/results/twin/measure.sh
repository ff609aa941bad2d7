#!/bin/bash
# The shipped student through the whole real stack on the physics twin: 18 objects x 10 trials, seeds 1000..1009.
#   [OVERLOAD_N=40] docs/results/twin/measure.sh OUT     (from the repository root; about an hour on a shared 2-core machine)
# One lerobot-eval per object. When the real stack's safety latch stops a trial (force overload, stale force data,
# ...), that trial is a failure (stops.jsonl, with the error) and lerobot-eval is started again at the next seed.
# Re-running the script continues where it stopped. Then: python -m lerobot_blindgrasp.twin.report --run=OUT
# The twin and the host run at nice -10: they stand in for a gripper with its own processors and a lab PC that runs
# nothing else; the machine this ran on was shared with other jobs (uptime.log).
set -u
OUT=${1:?output folder}
OVERLOAD_N=${OVERLOAD_N:-80}  # the robot's force_sensor.overload_n (its default since this record: 80 N); see docs/results/twin.md
mkdir -p "$OUT/real"
export HF_HUB_OFFLINE=1 MUJOCO_GL=egl OMP_NUM_THREADS=1
BIN=$(pwd)/.venv/bin
(while true; do echo "$(date -u +%H:%M:%S) $(uptime)"; sleep 60; done) >> "$OUT/uptime.log" &
UPTIME_PID=$!
nice -n -10 "$BIN/blindgrasp-twin" --ports_json="$OUT/ports.json" --socket="$OUT/twin.sock" \
  --trial_log="$OUT/twin_trials.jsonl" --status_every_s=60 >> "$OUT/twin.log" 2>&1 &
TWIN_PID=$!
for _ in $(seq 60); do [ -S "$OUT/twin.sock" ] && break; sleep 1; done
"$BIN/blindgrasp-twin-calibrate" --ports_json="$OUT/ports.json" --robot_id=twin \
  --calibration_dir="$OUT/calibration" > "$OUT/calibrate.log" 2>&1
echo "calibrate rc=$?" >> "$OUT/runs.log"
DXL=$(python3 -c "import json;print(json.load(open('$OUT/ports.json'))['dynamixel_port'])")
FRC=$(python3 -c "import json;print(json.load(open('$OUT/ports.json'))['force_port'])")
OBJECTS=$("$BIN/python" -c "from lerobot_blindgrasp.sim import objects; print(' '.join(objects.PAPER_OBJECTS))")
count() {  # trials of object $1 that ended (trial log) or were stopped (stops.jsonl)
  python3 -c "
import json, os, sys
n = set()
for f in ('$OUT/real_trials.jsonl', '$OUT/stops.jsonl'):
    if os.path.exists(f):
        n |= {json.loads(l)['seed'] for l in open(f) if json.loads(l)['object'] == '$1'}
print(len(n))"
}
for OBJ in $OBJECTS; do
  for attempt in $(seq 12); do
    DONE=$(count "$OBJ"); [ "$DONE" -ge 10 ] && break
    SEED=$((1000 + DONE)); RUN="$OUT/real/$OBJ/from_$SEED"; rm -rf "$RUN"; mkdir -p "$OUT/real/$OBJ"
    timeout 900 nice -n -10 "$BIN/lerobot-eval" --policy.path=models/student_cpu --policy.device=cpu \
      --env.type=blindgrasp_real --env.task="$OBJ" --env.robot.type=blindgrasp_gripper --env.robot.id=twin \
      --env.robot.calibration_dir="$OUT/calibration" --env.robot.port="$DXL" --env.robot.force_sensor.port="$FRC" \
      --env.robot.latency_timer_ms=60 --env.robot.max_overrun_s=0 --env.robot.force_sensor.overload_n=$OVERLOAD_N \
      --env.operator_socket="$OUT/twin.sock" \
      --env.trial_log="$OUT/real_trials.jsonl" --eval.n_episodes=$((10 - DONE)) --eval.batch_size=1 \
      --eval.use_async_envs=false --seed=$SEED --output_dir="$RUN" > "$RUN.log" 2>&1
    echo "$(date -u +%H:%M:%S) $OBJ from seed $SEED rc=$?" >> "$OUT/runs.log"
    if [ ! -f "$RUN/eval_info.json" ]; then
      STOPPED=$((1000 + $(count "$OBJ")))
      ERR=$(grep -o "Error: .*" "$RUN.log" | tail -1 | cut -c8-400)
      python3 -c "import json,sys; print(json.dumps({'object': '$OBJ', 'seed': $STOPPED, 'error': sys.argv[1]}))" \
        "${ERR:-no error line}" >> "$OUT/stops.jsonl"
    fi
  done
done
kill -INT $TWIN_PID; wait $TWIN_PID
kill $UPTIME_PID
echo "done $(date -u +%H:%M:%S)" >> "$OUT/runs.log"
