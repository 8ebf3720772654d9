#!/bin/bash
# The distance field (issue 30) on a GPU host in one run: build this tree's CUDA
# targets as kernel-probe.sh does (LCM off, SIMD off: the parity reference is the scalar CPU
# backend), run every CUDA test, then time one update (mppid-gpu-timing, test scene) of the
# forest tasks without the field, with it beside the cylinders, with it alone (a sensed forest)
# and alone with a new map every 5 updates (a 10 Hz mapper at 50 Hz: the cells copied again),
# each twice, interleaved. With --base DIR, DIR's tree is built and timed without a field in
# the same rounds (the field-less path must not have slowed down); --also LABEL=DIR (repeatable)
# builds and times another tree the same way (a variant of this one).
#   test/gpu/field-timing.sh [--base DIR] [--also LABEL=DIR]...
# Results in $MPPID_RESULTS (default results/field): field-timing.txt (the summary), parity.txt,
# timing.json. Builds: $MPPID_BUILD_ROOT/build-field{,-base,-LABEL} (default: this tree).
set -uo pipefail
source "$(dirname "${BASH_SOURCE[0]}")/../../tools/gpu/devdeps.sh"
cd "$ROOT"
BASE=""
ALSO=()
while (($#)); do
  case "$1" in
    --base) BASE="$(cd "$2" && pwd)"; shift 2 ;;
    --also) ALSO+=("$2"); shift 2 ;;
    *) other_arg "${BASH_SOURCE[0]}" "$1" ;;
  esac
done
DEST="${MPPID_RESULTS:-$ROOT/results/field}"
BR="${MPPID_BUILD_ROOT:-$ROOT}"
BUILT=("$BR/build-field")
W="$ROOT/results/field-work"
rm -rf "$W" && mkdir -p "$W" "$DEST"
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
  build "$ROOT" "$BR/build-field" & p1=$!
  if [[ -n "$BASE" ]]; then BUILT+=("$BR/build-field-base"); build "$BASE" "$BR/build-field-base" & p2=$!; wait $p2 || echo "base build failed"; fi
  for a in "${ALSO[@]}"; do BUILT+=("$BR/build-field-${a%%=*}"); build "${a#*=}" "$BR/build-field-${a%%=*}" || echo "${a%%=*} build failed"; done
  wait $p1 || { echo "build failed"; tail -30 "$W/build-build-field.log"; }
  for b in "${BUILT[@]}"; do
    echo "$b registers: $(cuobjdump --dump-resource-usage "$b/bin/cuda_backend_tests" 2>/dev/null |
      grep -A1 "Function.*rollout_chunked" | grep -oE "REG:[0-9]+ STACK:[0-9]+" | sort | uniq -c | tr '\n' ' ')"
  done
  stamp "CUDA tests"
  timeout 400 "$BR/build-field"/bin/cuda_backend_tests >"$W/parity.log" 2>&1
  echo "cuda_backend_tests rc $?: $(grep -E '^\[  (PASSED|FAILED) ' "$W/parity.log" | tr '\n' ' ')"
  grep -E '^\[parity\] .*(field|K=)|FAILED|Failure' "$W/parity.log" | grep -v ' cycle ' >"$DEST/parity.txt"
  grep -E 'field' "$DEST/parity.txt" | head -20
  stamp "timing"
  for round in 1 2; do
    for mode in none both only only5; do
      args=(--field "${mode%5}")
      [[ "$mode" == only5 ]] && args+=(--map-every 5)
      "$BR/build-field"/bin/mppid-gpu-timing --iters 1000 "${args[@]}" quadrotor_forest:16384 quadrotor_forest:4096 \
        quadrotor_rate_forest:16384 team3_forest:1200 >"$W/t-$mode-$round.json" 2>>"$W/timing.err"
      sed -nE 's/^ *\{"task": "([^"]*)", "rollouts": ([0-9]*), .*"median_us": ([0-9.]*), "p99_us": ([0-9.]*).*/'"round $round field $mode"' \1 K=\2 median \3 p99 \4/p' "$W/t-$mode-$round.json"
    done
    if [[ -n "$BASE" ]]; then
      "$BR/build-field-base"/bin/mppid-gpu-timing --iters 1000 quadrotor_forest:16384 quadrotor_forest:4096 \
        quadrotor_rate_forest:16384 team3_forest:1200 >"$W/t-base-$round.json" 2>>"$W/timing.err"
      sed -nE 's/^ *\{"task": "([^"]*)", "rollouts": ([0-9]*), .*"median_us": ([0-9.]*), "p99_us": ([0-9.]*).*/'"round $round base (no field)"' \1 K=\2 median \3 p99 \4/p' "$W/t-base-$round.json"
    fi
    for a in "${ALSO[@]}"; do
      l="${a%%=*}"
      for mode in none only; do
        "$BR/build-field-$l/bin/mppid-gpu-timing" --iters 1000 --field "$mode" quadrotor_forest:16384 quadrotor_forest:4096 \
          quadrotor_rate_forest:16384 team3_forest:1200 >"$W/t-$l-$mode-$round.json" 2>>"$W/timing.err"
        sed -nE 's/^ *\{"task": "([^"]*)", "rollouts": ([0-9]*), .*"median_us": ([0-9.]*), "p99_us": ([0-9.]*).*/'"round $round $l field $mode"' \1 K=\2 median \3 p99 \4/p' "$W/t-$l-$mode-$round.json"
      done
    done
  done
  stamp "done"
} 2>&1 | tee "$DEST/field-timing.txt"
cat "$W"/t-*.json >"$DEST/timing.json" 2>/dev/null
tail -5 "$W/timing.err" 2>/dev/null
