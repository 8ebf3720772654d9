#!/bin/bash
# The distance field (issue 30) on the GPU machine in one device call: build this tree's CUDA
# targets as kernel_session.sh does (LCM off, SIMD off: the parity reference is the scalar CPU
# backend), run every CUDA test, then time one update (mppid-gpu-timing, test scene) of the
# forest tasks without the field, with it beside the cylinders, with it alone (a sensed forest)
# and alone with a new map every 5 updates (a 10 Hz mapper at 50 Hz: the cells copied again),
# each twice, interleaved. With --base DIR, DIR's tree is built and timed without a field in
# the same rounds (the field-less path must not have slowed down).
#   test/gpu/field_session.sh [--base DIR]
# Results: $OUT/field_session.txt (the summary), $OUT/parity.txt, $OUT/timing.json.
set -uo pipefail
ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/../.." && pwd)"
cd "$ROOT"
BASE=""
if [[ "${1:-}" == "--base" ]]; then BASE="$(cd "$2" && pwd)"; fi
D="${MPPID_DEVDEPS:-$ROOT/.devdeps}"
DEST="${OUT:-$ROOT/results/field}"
W="$ROOT/results/field-work"
rm -rf "$W" && mkdir -p "$W" "$DEST"
export LD_LIBRARY_PATH="$D/lib:${LD_LIBRARY_PATH:-}"
T0=$(date +%s)
stamp() { echo "[$(($(date +%s) - T0)) s] $*"; }

build() {  # source dir, build dir
  cmake -S "$1" -B "$2" -G Ninja -DCMAKE_BUILD_TYPE=Release -DMPPID_CUDA=ON -DCMAKE_CUDA_ARCHITECTURES=90 \
    -DMPPID_WERROR=OFF -DMPPID_LCM=OFF -DMPPID_SIMD=OFF -DMPPID_BENCH=OFF -DMPPID_TESTS=ON \
    -DRANDOM123_INCLUDE_DIR="$D/usr/include" >"$W/configure-$(basename "$2").log" 2>&1 &&
    ninja -C "$2" -j"$(nproc)" cuda_backend_tests mppid-gpu-timing >"$W/build-$(basename "$2").log" 2>&1
}

{
  nvidia-smi --query-gpu=name,driver_version,clocks.sm,clocks.max.sm --format=csv,noheader
  stamp "build"
  build "$ROOT" /root/build-field & p1=$!
  if [[ -n "$BASE" ]]; then build "$BASE" /root/build-base & p2=$!; wait $p2 || echo "base build failed"; fi
  wait $p1 || { echo "build failed"; tail -30 "$W/build-build-field.log"; }
  stamp "CUDA tests"
  timeout 400 /root/build-field/bin/cuda_backend_tests >"$W/parity.log" 2>&1
  echo "cuda_backend_tests rc $?: $(grep -E '^\[  (PASSED|FAILED) ' "$W/parity.log" | tr '\n' ' ')"
  grep -E '^\[parity\] .*(field|K=)|FAILED|Failure' "$W/parity.log" | grep -v ' cycle ' >"$DEST/parity.txt"
  grep -E 'field' "$DEST/parity.txt" | head -20
  stamp "timing"
  for round in 1 2; do
    for mode in none both only only5; do
      args=(--field "${mode%5}")
      [[ "$mode" == only5 ]] && args+=(--map-every 5)
      /root/build-field/bin/mppid-gpu-timing --iters 1000 "${args[@]}" quadrotor_forest:16384 quadrotor_forest:4096 \
        quadrotor_rate_forest:16384 team3_forest:1200 >"$W/t-$mode-$round.json" 2>>"$W/timing.err"
      sed -nE 's/^ *\{"task": "([^"]*)", "rollouts": ([0-9]*), .*"median_us": ([0-9.]*), "p99_us": ([0-9.]*).*/'"round $round field $mode"' \1 K=\2 median \3 p99 \4/p' "$W/t-$mode-$round.json"
    done
    if [[ -n "$BASE" ]]; then
      /root/build-base/bin/mppid-gpu-timing --iters 1000 quadrotor_forest:16384 quadrotor_forest:4096 \
        quadrotor_rate_forest:16384 team3_forest:1200 >"$W/t-base-$round.json" 2>>"$W/timing.err"
      sed -nE 's/^ *\{"task": "([^"]*)", "rollouts": ([0-9]*), .*"median_us": ([0-9.]*), "p99_us": ([0-9.]*).*/'"round $round base (no field)"' \1 K=\2 median \3 p99 \4/p' "$W/t-base-$round.json"
    fi
  done
  stamp "done"
} 2>&1 | tee "$DEST/field_session.txt"
cat "$W"/t-*.json >"$DEST/timing.json" 2>/dev/null
tail -5 "$W/timing.err" 2>/dev/null
