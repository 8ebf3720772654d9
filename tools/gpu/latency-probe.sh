#!/usr/bin/env bash
# Where the CUDA daemon's state -> command time goes, on a GPU host (offline is fine):
#   tools/gpu/latency-probe.sh [--seconds 60] [--runs 1] [--rollouts 16384] [--results DIR] [--archive DIR]
# 1. builds the stack (tools/gpu/run-all.sh --stages build, into build-gpu/ unless it is there);
# 2. mppid-gpu-timing quadrotor_forest:K back to back, then one update every 20 ms with the GPU
#    and the thread idle in between (--period-us 20000, as in the daemon);
# 3. --runs times daemon-bench --realtime --backend cuda at K, trigger state: state in -> command out, split
#    into the state's wait for its cycle ("wake") and the optimizer's update ("optimize"), with
#    the daemon's threads (top -H) and the GPU's clock sampled during the run.
# Results (JSON, logs, a summary) land in DIR; with --archive A, summary.md and latency-probe.tgz in A too.
set -uo pipefail
source "$(dirname "${BASH_SOURCE[0]}")/devdeps.sh"
cd "$ROOT"
ARCHIVE="" SECONDS_RUN=60 RUNS=1 K=16384 RES="$ROOT/results/latency-$(date -u +%Y%m%d-%H%M%S)"
while (($#)); do
  case "$1" in
    --seconds) SECONDS_RUN="$2"; shift ;;
    --rollouts) K="$2"; shift ;;
    --runs) RUNS="$2"; shift ;;
    --results) RES="$2"; shift ;;
    --archive) ARCHIVE="$2"; shift ;;
    *) other_arg "${BASH_SOURCE[0]}" "$1" ;;
  esac
  shift
done
mkdir -p "$RES"
B="${MPPID_GPU_BUILD:-$ROOT/build-gpu}"
T0=$(date +%s)
say() { printf '[probe %4ds] %s\n' $(($(date +%s) - T0)) "$*" | tee -a "$RES/probe.log"; }

if [[ ! -x "$B/bin/mppid" || ! -x "$B/bin/mppid-gpu-timing" ]]; then
  tools/gpu/run-all.sh --stages build --results "$RES/build" >/dev/null 2>&1 || { say "build failed"; tail -30 "$RES/build/build.log"; exit 1; }
fi
say "built ($B)"
{
  echo "# latency probe ($(date -u +%FT%TZ)), K = $K, ${SECONDS_RUN} s"
  echo "- GPU: $(nvidia-smi --query-gpu=name,driver_version,persistence_mode,clocks.sm,clocks.max.sm,pstate --format=csv,noheader 2>&1)"
  echo "- CPU: $(nproc) x $(grep -m1 'model name' /proc/cpuinfo | cut -d: -f2 | sed 's/^ //'); load $(cut -d' ' -f1-3 /proc/loadavg)"
  echo "- commit: ${MPPID_COMMIT:-unknown}"
} >"$RES/summary.md"

"$B/bin/mppid-gpu-timing" --iters 1000 "quadrotor_forest:$K" >"$RES/timing-back-to-back.json" 2>&1
"$B/bin/mppid-gpu-timing" --iters 1000 --warmup 20 --period-us 20000 "quadrotor_forest:$K" >"$RES/timing-every-20ms.json" 2>&1
for f in timing-back-to-back timing-every-20ms; do
  echo "- $f: $(grep -o '"median_us.*max_us": [0-9.]*' "$RES/$f.json")" >>"$RES/summary.md"
done
say "timing done"

bench() {  # label, extra env...
  local label=$1; shift
  (
    sleep $((SECONDS_RUN / 2))
    pid=$(pidof mppid | cut -d' ' -f1) && top -b -H -n 2 -d 5 -p "$pid" >"$RES/top-$label.txt" 2>&1
    nvidia-smi --query-gpu=clocks.sm,pstate,utilization.gpu --format=csv,noheader >"$RES/gpu-$label.txt" 2>&1
  ) &
  env "$@" drivers/daemon/tools/daemon-bench --build "$B" --seconds "$SECONDS_RUN" --realtime --backend cuda \
    -- --set mppi.rollouts="$K" --set daemon.trigger=state >"$RES/daemon-$label.json" 2>"$RES/daemon-$label.err"
  wait
  python3 - "$RES/daemon-$label.json" "$label" >>"$RES/summary.md" <<'PY'
import json, sys
d = json.load(open(sys.argv[1]))["daemon"]
f = lambda k: "p50~mean {mean_ms:.3f} p99 {p99_ms:.3f} max {max_ms:.3f}".format(**d[k]) if k in d else "n/a"
print(f"- daemon {sys.argv[2]}: misses {d['misses']} of {d['cycles']}; state->command {f('latency')}; "
      f"age {f('age')}; wake {f('wake')}; optimize {f('optimize')}; compute {f('compute')}")
PY
  say "daemon-bench $label done"
}
for ((r = 1; r <= RUNS; r++)); do bench "run$r"; done
cat "$RES/summary.md"
if [[ -n "$ARCHIVE" ]]; then mkdir -p "$ARCHIVE" && tar czf "$ARCHIVE/latency-probe.tgz" -C "$RES" . && cp "$RES/summary.md" "$ARCHIVE/"; fi
