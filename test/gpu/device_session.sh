#!/bin/bash
# One GPU-machine session: build, parity/determinism tests, timings of the three targets in
# every noise mode, the Fig. 11 sweep through mppid-bench, and a short Nsight Compute look
# at the latency-bound rollout kernels. Everything lands in $OUT (at most 8 files).
#   test/gpu/device_session.sh [quick]
set -u
OUT=${OUT:-/tmp/out}
B=build-dev
T0=$(date +%s)
stamp() { echo "[$(($(date +%s) - T0)) s] $*"; }
nvidia-smi --query-gpu=name,driver_version,clocks.sm,clocks.max.sm --format=csv,noheader > "$OUT/gpu.txt" 2>&1
stamp "$(cat "$OUT/gpu.txt")"
bash test/gpu/device_run.sh "$B" || exit 1
stamp built
export LD_LIBRARY_PATH=$PWD/.devdeps/lib/x86_64-linux-gnu:${LD_LIBRARY_PATH:-}

# Parity and determinism: the contract.
"$B/bin/cuda_backend_tests" > "$OUT/tests.log" 2>&1
rc=$?
grep -E '^\[parity\]|FAILED|PASSED|^\[  ' "$OUT/tests.log" | grep -vE '^\[ RUN|^\[       OK' | tail -40
stamp "tests rc=$rc"

# The targets (test scenario: sigma 20, 32 obstacles): the default choice, then the variants.
TM="$B/bin/mppid-gpu-timing"
{
  echo "== auto"
  $TM --iters 1000 quadrotor_forest:16384 team3_forest:1200 team9_forest:6000 quadrotor_forest:65536
  $TM --iters 200 --warmup 20 quadrotor_forest:262144 quadrotor_forest:655360 quadrotor_forest:786432 quadrotor_forest:1048576
  for g in 1 2 4 8; do
    echo "== lanes $g"
    MPPID_CUDA_LANES=$g $TM --iters 1000 quadrotor_forest:4096 quadrotor_forest:16384
  done
  echo "== noise inline"
  MPPID_CUDA_NOISE=inline $TM --iters 1000 team3_forest:1200 team9_forest:6000
} > "$OUT/timing.log" 2>&1
grep -E '^==|"task"' "$OUT/timing.log" | sed 's/"mean_us.*//'
stamp timings

# Fig. 11: the public bench on the task configs (config/tasks/*.yaml).
BN="$B/bin/mppid-bench"
{
  for m in quadrotor team3 team9; do
    $BN --model $m --backend cuda --rollouts 256,1024,4096,16384,65536 --horizon 100 --iterations 1000 --json
    $BN --model $m --backend cuda --rollouts 262144,1048576 --horizon 100 --iterations 100 --warmup 5 --json
  done
} > "$OUT/bench.jsonl" 2> "$OUT/bench.err"
sed 's/,"startup_host_bytes.*//' "$OUT/bench.jsonl"
stamp bench

if [ "${1:-}" != quick ] && command -v ncu > /dev/null; then
  for c in quadrotor_forest:16384 team3_forest:1200; do
    timeout 90 ncu --kernel-name regex:'rollout_(single|team)' --launch-skip 3 --launch-count 1 \
      --section SpeedOfLight --section WarpStateStats --section SchedulerStats --section Occupancy \
      "$TM" --iters 5 --warmup 0 $c
  done > "$OUT/ncu.txt" 2>&1
  grep -E 'rollout_|Duration|Issue Slots Busy|No Eligible|Stall|Warp Cycles Per Issued|Achieved Occupancy' "$OUT/ncu.txt" | head -40
  stamp ncu
fi
