#!/bin/bash
# Kernel measurements on a GPU host, after tools/gpu/run-all.sh has built build-gpu/:
# every rollout-kernel variant on the kernel target sizes (the test scenario: sigma 20, 32
# obstacles, T = 100), a build with denormals flushed (MPPID_CUDA_FTZ) checked for parity
# and timed, then Nsight Compute on one update's kernels. gpu/NOTES.md holds the predictions
# these are checked against. Logs land in $MPPID_RESULTS (default results/).
#   test/gpu/kernel-variants.sh build-ftz     (first, or beside run-all.sh's build)
#   test/gpu/kernel-variants.sh [quick]
set -u
B=${B:-build-gpu}
RES=${MPPID_RESULTS:-results}
mkdir -p "$RES"
export LD_LIBRARY_PATH=$PWD/.devdeps/lib:${LD_LIBRARY_PATH:-}
T0=$(date +%s)
stamp() { echo "[$(($(date +%s) - T0)) s] $*"; }
row() {  # label, mppi.cuda.FIELD=VALUE..., -- timing-tool arguments
  local label=$1; shift
  local sets=()
  while [ "$1" != "--" ]; do sets+=(--set "$1"); shift; done
  shift
  "$TM" "${sets[@]}" "$@" 2>&1 | grep -E '"task"|timing:' | sed -E "s/^ *\{\"task\": \"([^\"]*)\", \"rollouts\": ([0-9]*), .*\"median_us\": ([0-9.]*), \"p99_us\": ([0-9.]*).*/$label \1 K=\2 median \3 us p99 \4 us/"
}
if [ "${1:-}" = build-ftz ]; then
  # The flushed-denormal variant (no LCM: only the tests and the timing tool); may run beside
  # run-all.sh's build.
  cmake -S . -B build-ftz -G Ninja -DCMAKE_BUILD_TYPE=Release -DMPPID_CUDA=ON -DCMAKE_CUDA_ARCHITECTURES=90 \
    -DMPPID_WERROR=OFF -DMPPID_LCM=OFF -DMPPID_CUDA_FTZ=ON -DRANDOM123_INCLUDE_DIR="$PWD/.devdeps/usr/include" &&
    ninja -C build-ftz -j8 cuda_backend_tests mppid-gpu-timing
  exit
fi
TM="$B/bin/mppid-gpu-timing"
[ -x "$TM" ] || { echo "kernel-variants: $TM missing (run tools/gpu/run-all.sh --stages build first)"; exit 1; }
{
  stamp "variants (median of the iterations)"
  row "lanes   " mppi.cuda.kernel=lanes -- --iters 500 quadrotor_forest:16384 quadrotor_rate_forest:16384 quadrotor_forest:4096
  row "chunked " mppi.cuda.kernel=chunked -- --iters 500 quadrotor_forest:16384 quadrotor_rate_forest:16384 quadrotor_forest:4096
  for c in 2 4 8 16; do
    for w in 2 4 8; do
      row "chunk=$c warps=$w" mppi.cuda.chunk_steps=$c mppi.cuda.warps=$w -- --iters 300 quadrotor_forest:16384
    done
  done
  row "redraw  " mppi.cuda.controls=redraw -- --iters 300 quadrotor_forest:16384 quadrotor_rate_forest:16384
  row "keep    " mppi.cuda.controls=keep -- --iters 100 quadrotor_forest:65536 quadrotor_forest:262144
  row "redraw  " mppi.cuda.controls=redraw -- --iters 100 quadrotor_forest:65536 quadrotor_forest:262144
  row "chunked " -- --iters 300 quadrotor_track:16384 quadrotor_rate_track:16384 racecar_ellipse:16384 cartpole_swingup:16384
  row "lanes   " mppi.cuda.kernel=lanes -- --iters 30 --warmup 3 quadrotor_forest:1048576
  for c in 2 4 8; do
    for w in 4 8; do
      row "chunk=$c warps=$w" mppi.cuda.chunk_steps=$c mppi.cuda.warps=$w -- --iters 30 --warmup 3 quadrotor_forest:1048576
    done
  done
  row "chunked " -- --iters 1000 quadrotor_forest:16384 quadrotor_forest:1024 quadrotor_forest:256
  row "graph off" mppi.cuda.graph=false -- --iters 500 quadrotor_forest:16384
  stamp "variants done"
} 2>&1 | tee "$RES/variants.txt"

if [ -x build-ftz/bin/cuda_backend_tests ]; then
  {
    stamp "flushed denormals (MPPID_CUDA_FTZ=ON)"
    build-ftz/bin/cuda_backend_tests --gtest_filter='CudaParity.*:CudaDeterminism.*' 2>&1 |
      grep -E '^\[parity\] [a-z_0-9]+ +cost|FAILED|PASSED|tests ran'
    TM=build-ftz/bin/mppid-gpu-timing
    row "ftz     " -- --iters 500 quadrotor_forest:16384 quadrotor_rate_forest:16384 team3_forest:1200 team9_forest:6000
    row "ftz     " -- --iters 30 --warmup 3 quadrotor_forest:1048576
  } 2>&1 | tee "$RES/ftz.txt"
else
  echo "no build-ftz/ (test/gpu/kernel-variants.sh build-ftz makes it)"
fi

if [ "${1:-}" != quick ] && command -v ncu > /dev/null; then
  # One update's kernels (after the warm-up updates), K = 16384 and 1M.
  for c in quadrotor_forest:16384 quadrotor_forest:1048576; do
    timeout 120 ncu --kernel-name regex:'rollout|weigh|finalize|partial_min' --launch-skip 12 --launch-count 3 \
      --section SpeedOfLight --section WarpStateStats --section SchedulerStats --section Occupancy --section LaunchStats \
      --section InstructionStats "$TM" --iters 5 --warmup 5 $c
  done > "$RES/ncu.txt" 2>&1
  grep -E '^  [a-z_]+.*\(|Duration|Executed Ipc A|Issued Warp Per|No Eligible|Warp Cycles Per Issued|Achieved Occupancy|Executed Instructions  |Block Limit (Sh|Reg)' \
    "$RES/ncu.txt" | head -80
  stamp ncu
fi
