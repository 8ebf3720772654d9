#!/usr/bin/env bash
# The whole control cycle on a GPU host, this tree against a base tree in the same run
# (issue 24): the cost of Controller::iterate around the update, the daemon's state -> command,
# and the update at the loop rates of tools/gpu/rate_dial.py. Offline (tools/gpu/README.md):
# run from this tree, with .devdeps (tools/gpu/pack-deps.sh) beside it.
#
#   tools/gpu/cycle-compare.sh [--base DIR] [--daemon-seconds 30] [--rate-seconds 60]
#        [--seeds 3] [--first-seed 51] [--time-budget 570] [--archive DIR] STEP...
#   STEP: build cudatest bench daemon rates flights pdl spin400 track
#     build     configure and build the targets below in this tree (and --base) at once
#     cudatest  the CUDA tests of this tree (parity, device obstacle grid)
#     bench     mppid-bench (Controller::iterate) and mppid-gpu-timing (the update alone) on the
#               issue's three configurations, base and this tree interleaved, twice; this tree's
#               update with the host's obstacle grid (mppi.cuda.grid=host: the kernels against
#               the base's) and on mppid-bench's scene (with either grid)
#     daemon    daemon-bench --realtime --backend cuda K = 16384 (state trigger): base, this tree,
#               this tree with daemon.spin
#     rates     mppid-gpu-timing on mppid-bench's scene at the plan lengths of 100-400 Hz, and
#               daemon-bench at 400 Hz (states at 400 Hz) for --rate-seconds
#     flights   real-time SITL campaigns at each loop rate (rate_dial.py; seeds 51..): CUDA at
#               50/100/200/400 Hz on 3 cores each, the CPU backend at 50/100 Hz on 2 cores each,
#               all at once (the CUDA flights share the GPU), until --time-budget seconds after
#               the script's start less 25 s; the table (rate_table.py) in summary.md
#     pdl       this tree's update with and without programmatic dependent launches
#               (mppi.cuda.pdl=off), test and bench scenes
#     spin400   daemon-bench at 400 Hz (as in rates) with daemon.spin
#     track     rate_track_circle_fast alone at 50/100/200/400 Hz on CUDA, 4 cores each, at once
# Results: results/cycle-<time>/ (one log per step, summary.md last); with --archive DIR,
# summary.md and everything as cycle.tgz there too. Builds: $MPPID_BUILD_ROOT/{this,base}
# (default build-cycle/ in this tree; put it where a rebuild is not needed next time).
set -uo pipefail
source "$(dirname "${BASH_SOURCE[0]}")/devdeps.sh"
HERE="$ROOT"
cd "$HERE"
BASE="" DAEMON_S=30 RATE_S=60 SEEDS=3 FIRST_SEED=51 BUDGET_S=570 ARCHIVE="" STEPS=()
while (($#)); do
  case "$1" in
    --base) BASE="$(cd "$2" && pwd)"; shift ;;
    --daemon-seconds) DAEMON_S="$2"; shift ;;
    --rate-seconds) RATE_S="$2"; shift ;;
    --seeds) SEEDS="$2"; shift ;;
    --first-seed) FIRST_SEED="$2"; shift ;;
    --time-budget) BUDGET_S="$2"; shift ;;
    --archive) ARCHIVE="$2"; shift ;;
    -h|--help) other_arg "${BASH_SOURCE[0]}" "$1" ;;
    *) STEPS+=("$1") ;;
  esac
  shift
done
RES="$HERE/results/cycle-$(date -u +%Y%m%d-%H%M%S)"
mkdir -p "$RES"
SUMMARY="$RES/summary.md"
T0=$(date +%s)
status=0
say() { printf '[cycle %4ds] %s\n' $(($(date +%s) - T0)) "$*" | tee -a "$RES/cycle.log"; }
fail() { say "FAILED: $*"; status=1; }
want() { [[ " ${STEPS[*]} " == *" $1 "* ]]; }
BUILD_ROOT="${MPPID_BUILD_ROOT:-$HERE/build-cycle}"
B_THIS="$BUILD_ROOT/this" B_BASE="$BUILD_ROOT/base"

# ---- setup (as tools/gpu/run-all.sh) ----
PY="$(command -v python3)"
"$PY" -c 'import lcm' 2>/dev/null ||
  "$PY" -m pip install -q --no-index --no-deps --no-compile --disable-pip-version-check "$D"/wheels/lcm-*.whl >>"$RES/cycle.log" 2>&1
LCM_DIR="$("$PY" -c 'import lcm,os;print(os.path.join(os.path.dirname(os.path.dirname(lcm.__file__)),"lib","lcm","cmake"))')"
for tree in "$HERE" ${BASE:+"$BASE"}; do
  mkdir -p "$tree/.venv/bin"
  for n in python python3; do printf '#!/bin/sh\nexec %s "$@"\n' "$PY" >"$tree/.venv/bin/$n"; chmod +x "$tree/.venv/bin/$n"; done
done
{
  echo "# control cycle, this tree against the base ($(date -u +%FT%TZ))"
  echo "- GPU: $(nvidia-smi --query-gpu=name,driver_version,clocks.sm,clocks.max.sm --format=csv,noheader 2>&1)"
  echo "- CPU: $(nproc) x $(grep -m1 'model name' /proc/cpuinfo | cut -d: -f2 | sed 's/^ //')"
  echo "- this tree: ${MPPID_COMMIT:-$(git -C "$HERE" rev-parse --short HEAD 2>/dev/null || echo unknown)}; base: ${BASE:-none} ${MPPID_BASE_COMMIT:-}"
} >"$SUMMARY"

build() {  # tree dir
  local cfg=(-S "$1" -B "$2" -G Ninja -DCMAKE_BUILD_TYPE=Release -DMPPID_CUDA=ON -DCMAKE_CUDA_ARCHITECTURES=90
             -DMPPID_WERROR=OFF -DMPPID_LCM=ON -DMPPID_TESTS=ON -DMPPID_BENCH=ON
             -DRANDOM123_INCLUDE_DIR="$D/usr/include" -Dlcm_DIR="$LCM_DIR" -DMPPID_GLIB_LIBRARY="$D/lib/libglib-2.0.so.0")
  [[ -d "$D/usr/lib/x86_64-linux-gnu/cmake" ]] && cfg+=(-DCMAKE_PREFIX_PATH="$D/usr")
  [[ -d "$D/googletest" ]] && cfg+=(-DMPPID_GTEST_SOURCE="$D/googletest")
  cmake "${cfg[@]}" >"$RES/configure-$(basename "$2").log" 2>&1 &&
    ninja -C "$2" -j"$(nproc)" mppid-bench mppid-gpu-timing cuda_backend_tests mppid mppid-peer mppid-sim mppi_lcm_python \
      >"$RES/build-$(basename "$2").log" 2>&1
}

if want build; then
  build "$HERE" "$B_THIS" & p1=$!
  if [[ -n "$BASE" ]]; then build "$BASE" "$B_BASE" & p2=$!; wait $p2 || fail "build base"; fi
  wait $p1 || fail "build this"
  say "build done"
fi

if want cudatest; then
  timeout 300 "$B_THIS/bin/cuda_backend_tests" >"$RES/cudatest.log" 2>&1 || fail "cuda_backend_tests"
  echo "- cuda_backend_tests: $(grep -E '^\[  (PASSED|FAILED)  \]' "$RES/cudatest.log" | tr '\n' ' ')" >>"$SUMMARY"
  grep -E '^\[  FAILED  \]' "$RES/cudatest.log" | sed 's/^/    /' >>"$SUMMARY"
  say "cudatest done"
fi

bench_row() {  # label build: the three configurations of issue 24, one JSON line each
  for m in "quadrotor 16384" "quadrotor_rate 16384" "team3 1200"; do
    set -- $m
    "$B/bin/mppid-bench" --model "$1" --backend cuda --rollouts "$2" --horizon 100 --obstacles 32 --iterations 1000 |
      sed "s/^{/{\"tree\":\"$LABEL\",/"
  done
}
if want bench; then
  cases=(quadrotor_forest:16384 quadrotor_rate_forest:16384 team3_forest:1200 team9_forest:6000)
  bench_cases=(quadrotor_forest:16384 quadrotor_rate_forest:16384 team3_forest:1200)
  for round in 1 2; do
    for LABEL in base this; do
      B=$B_THIS; [[ $LABEL == base ]] && B=$B_BASE
      [[ $LABEL == base && -z "$BASE" ]] && continue
      bench_row >>"$RES/bench.jsonl" 2>>"$RES/bench.err" || fail "mppid-bench $LABEL"
      "$B/bin/mppid-gpu-timing" --iters 1000 "${cases[@]}" | sed "s/^{/{\"tree\": \"$LABEL\", \"round\": $round,/" \
        >>"$RES/gpu-timing.json" 2>>"$RES/bench.err" || fail "gpu-timing $LABEL"
    done
    # The kernels alone, base against this (both search the host's grid): rollout_chunked's phases.
    "$B_THIS/bin/mppid-gpu-timing" --iters 1000 --set mppi.cuda.grid=host "${cases[@]}" |
      sed "s/^{/{\"tree\": \"this\", \"round\": $round,/" >>"$RES/gpu-timing-hostgrid.json" 2>>"$RES/bench.err"
    "$B_THIS/bin/mppid-gpu-timing" --iters 1000 --scene bench "${bench_cases[@]}" |
      sed "s/^{/{\"tree\": \"this\", \"round\": $round,/" >>"$RES/gpu-timing-bench-scene.json" 2>>"$RES/bench.err"
    "$B_THIS/bin/mppid-gpu-timing" --iters 1000 --scene bench --set mppi.cuda.grid=host "${bench_cases[@]}" |
      sed "s/^{/{\"tree\": \"this\", \"round\": $round,/" >>"$RES/gpu-timing-bench-scene-hostgrid.json" 2>>"$RES/bench.err"
  done
  "$PY" tools/gpu/cycle_tables.py bench "$RES" >>"$SUMMARY"
  say "bench done"
fi

daemon_run() {  # label tree build [mppid args...]
  local label=$1 tree=$2 b=$3; shift 3
  "$tree/drivers/daemon/tools/daemon-bench" --build "$b" --seconds "$DAEMON_S" --realtime --backend cuda "$@" \
    >"$RES/daemon-$label.json" 2>"$RES/daemon-$label.err" || fail "daemon-bench $label"
  "$PY" tools/gpu/cycle_tables.py daemon "$label" "$RES/daemon-$label.json" >>"$RES/daemon-table.md" 2>>"$RES/daemon-$label.err"
}
if want daemon; then
  k=(-- --set mppi.rollouts=16384 --set daemon.trigger=state)
  [[ -n "$BASE" ]] && daemon_run base "$BASE" "$B_BASE" "${k[@]}"
  daemon_run this "$HERE" "$B_THIS" "${k[@]}"
  daemon_run this-spin "$HERE" "$B_THIS" "${k[@]}" --set daemon.spin=true
  say "daemon done"
fi

if want rates; then
  {
    "$B_THIS/bin/mppid-gpu-timing" --iters 300 --scene bench quadrotor_forest:16384:200 quadrotor_forest:8192:400 \
      quadrotor_forest:16384:400 quadrotor_forest:4096:800 quadrotor_forest:8192:800 team3_forest:1200:100 \
      team3_forest:1200:200 team3_forest:1200:400 quadrotor_rate_track:4096:150 quadrotor_rate_track:4096:300 \
      quadrotor_rate_track:4096:600
  } >"$RES/gpu-timing-rates.json" 2>>"$RES/bench.err" || fail "gpu-timing rates"
  mapfile -t sets < <("$PY" tools/gpu/rate_dial.py sets quadrotor_forest 400 --rollouts 4096)
  args=(--); for s in "${sets[@]}"; do args+=(--set "$s"); done
  DAEMON_S=$RATE_S daemon_run this-400hz "$HERE" "$B_THIS" --rate-in 400 "${args[@]}"
  {
    echo; echo "| gpu-timing (bench scene), plan lengths of the rates | K | T | median us | p99 |"; echo "|---|---:|---:|---:|---:|"
    grep '"task"' "$RES/gpu-timing-rates.json" |
      sed -E 's/.*"task": "([^"]*)", "rollouts": ([0-9]*), "horizon": ([0-9]*), "median_us": ([0-9.]*), "p99_us": ([0-9.]*).*/| \1 | \2 | \3 | \4 | \5 |/'
  } >>"$SUMMARY"
  say "rates done"
fi

# One (backend, rate) on its own cores: its three task groups' campaigns in turn, each stopped
# at the flights' deadline (--time-budget) (finished flights are kept).
fly_rate() {  # backend rate cores forest_rollouts [groups, default: forest track team3]
  local be=$1 rate=$2 cores=$3 k_forest=$4 groups=${5:-forest track team3} dir="$RES/flights/$1-$2" scen="$RES/scenarios-$2"
  mkdir -p "$dir" "$scen"
  for s in forest_4m forest_4m_robust team3_fixed rate_track_circle_fast; do
    "$PY" tools/gpu/rate_dial.py scenario "$s" "$rate" "$scen/$s.yaml"
  done
  local group task scenarios k line sets
  while read -r group task scenarios k; do
    [[ " $groups " == *" $group "* ]] || continue
    sets=()
    local dial=("$PY" tools/gpu/rate_dial.py sets "$task" "$rate" --backend "$be")
    [[ $be == cuda ]] && dial+=(--rollouts "$k")
    while read -r line; do sets+=(--set "$line"); done < <("${dial[@]}")
    [[ $be == cuda ]] && sets+=(--set daemon.trigger=state)
    local left=$((FLIGHT_END - $(date +%s)))
    ((left > 20)) || break
    taskset -c "$cores" timeout -s INT -k 20 "$left" tools/sitl campaign --realtime --backend "$be" --realtime-jobs 1 \
      --scenarios "$scenarios" --seeds "$SEEDS" --first-seed "$FIRST_SEED" --no-plots "${sets[@]}" --out "$dir/$group" \
      >"$dir/$group.log" 2>&1 || say "campaign $be-$rate $group: exit $? (see its log)"
  done <<LIST
forest quadrotor_forest $scen/forest_4m.yaml,$scen/forest_4m_robust.yaml $k_forest
track quadrotor_rate_track $scen/rate_track_circle_fast.yaml 4096
team3 team3_forest $scen/team3_fixed.yaml 1200
LIST
}
if want flights; then
  export MPPID_BUILD_DIR="$B_THIS"
  FLIGHT_END=$((T0 + BUDGET_S - 25))
  fly_rate cuda 50 0-2 16384 & fly_rate cuda 100 3-5 16384 & fly_rate cuda 200 6-8 8192 & fly_rate cuda 400 9-11 4096 &
  fly_rate cpu 50 12-13 0 & fly_rate cpu 100 14-15 0 &
  wait
  { echo; echo "## Loop rates (real time, seeds $FIRST_SEED-$((FIRST_SEED + SEEDS - 1)), all flights at once)"; echo
    "$PY" tools/gpu/rate_table.py "$RES/flights"; } >>"$SUMMARY" 2>>"$RES/cycle.log"
  say "flights done"
fi

if want pdl; then
  for pdl in 1 0; do
    sw=on; [[ $pdl == 0 ]] && sw=off
    "$B_THIS/bin/mppid-gpu-timing" --iters 1000 --set mppi.cuda.pdl=$sw quadrotor_forest:16384 quadrotor_rate_forest:16384 \
      team3_forest:1200 | sed "s/^{/{\"tree\": \"this-pdl$pdl\", \"round\": 1,/" >>"$RES/gpu-timing-pdl.json"
    "$B_THIS/bin/mppid-gpu-timing" --iters 1000 --scene bench --set mppi.cuda.pdl=$sw quadrotor_forest:16384 \
      quadrotor_rate_forest:16384 team3_forest:1200 | sed "s/^{/{\"tree\": \"this-pdl$pdl\", \"round\": 2,/" >>"$RES/gpu-timing-pdl.json"
  done 2>>"$RES/bench.err"
  "$PY" tools/gpu/cycle_tables.py bench "$RES" >>"$SUMMARY"
  say "pdl done"
fi

if want spin400; then
  sets=(); while read -r line; do sets+=(--set "$line"); done < <("$PY" tools/gpu/rate_dial.py sets quadrotor_forest 400 --rollouts 4096)
  DAEMON_S=$RATE_S daemon_run this-400hz-spin "$HERE" "$B_THIS" --rate-in 400 -- "${sets[@]}" --set daemon.spin=true
  say "spin400 done"
fi

if want track; then
  export MPPID_BUILD_DIR="$B_THIS"
  FLIGHT_END=$((T0 + BUDGET_S - 25))
  fly_rate cuda 50 0-3 0 track & fly_rate cuda 100 4-7 0 track & fly_rate cuda 200 8-11 0 track & fly_rate cuda 400 12-15 0 track &
  wait
  { echo; echo "## rate_track_circle_fast alone (real time, CUDA, seeds $FIRST_SEED-$((FIRST_SEED + SEEDS - 1)), four rates at once)"; echo
    "$PY" tools/gpu/rate_table.py "$RES/flights"; } >>"$SUMMARY" 2>>"$RES/cycle.log"
  say "track done"
fi

if [[ -f "$RES/daemon-table.md" ]]; then
  {
    echo; echo "| daemon-bench ($DAEMON_S s; 400 Hz: $RATE_S s) | Hz | K | cycles | misses | state->command mean / p99 ms | age | wake | optimize | compute |"
    echo "|---|---:|---:|---:|---:|---|---|---|---|---|"
    cat "$RES/daemon-table.md"
  } >>"$SUMMARY"
fi
say "all done, status $status"
cat "$SUMMARY"
if [[ -n "$ARCHIVE" ]]; then
  mkdir -p "$ARCHIVE" && cp "$SUMMARY" "$ARCHIVE/"
  tar -C "$(dirname "$RES")" --exclude='*.lcmlog' --exclude='truth.jsonl' --exclude='*.png' --exclude='build-*.log' -czf "$ARCHIVE/cycle.tgz" "$(basename "$RES")"
fi
exit $status
