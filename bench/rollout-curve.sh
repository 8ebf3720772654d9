#!/usr/bin/env bash
# What fewer rollouts cost: the forests flown at each rollout count (the work sizer off, so the
# count is pinned), then success, closest approach and timing against the count
# (tools/sitl speed-curve --key mppi.rollouts): the measured basis of the sizer's floor
# (docs/daemon.md, "Work sized to the machine").
#
#   bench/rollout-curve.sh [--rollouts 256,512,1024,2048,4096] [--scenarios forest_4m,forest_4m_sensed]
#                          [--seeds 51-70] [--jobs N] [--realtime] [--backend cpu|cuda] [--out DIR]
#                          [--set KEY=VALUE]...
#
#   default: lock-step, charging each cycle's measured latency (the simulator waits for the
#   command, then applies it as late as the controller took), CPU backend, --jobs 2 flights at
#   once; --realtime flies in real time, one flight at a time; --set adds mppid settings to
#   every flight (e.g. mppi.threads=2: each flight on two cores' worth of threads).
# Writes DIR/<K>/ (one campaign per count), DIR/curve.md, curve.json and curve.png.
set -euo pipefail
ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
cd "$ROOT"
rollouts=256,512,1024,2048,4096 scenarios=forest_4m,forest_4m_sensed seeds=51-70 jobs=2 realtime=0 backend=cpu
out="results/rollout-curve-$(date -u +%Y%m%d-%H%M%S)"
sets=()
while (($#)); do
  case "$1" in
    --rollouts) rollouts="$2"; shift ;;
    --scenarios) scenarios="$2"; shift ;;
    --seeds) seeds="$2"; shift ;;
    --jobs) jobs="$2"; shift ;;
    --realtime) realtime=1 ;;
    --backend) backend="$2"; shift ;;
    --out) out="$2"; shift ;;
    --set) sets+=(--set "$2"); shift ;;
    -h|--help) sed -n '2,14s/^# \{0,1\}//p' "${BASH_SOURCE[0]}"; exit 0 ;;
    *) echo "rollout-curve.sh: unknown argument '$1' (try --help)" >&2; exit 2 ;;
  esac
  shift
done
[[ -x .venv/bin/python ]] || { echo "rollout-curve.sh: no .venv: run tools/setup.sh first" >&2; exit 1; }
mode=(--jobs "$jobs")
((realtime)) && mode=(--realtime)
mkdir -p "$out"
IFS=, read -r -a counts <<<"$rollouts"
for k in "${counts[@]}"; do
  [[ "$k" =~ ^[1-9][0-9]*$ ]] || { echo "rollout-curve.sh: --rollouts: '$k' is not a count" >&2; exit 2; }
  echo "[rollout-curve] K = $k: $scenarios, seeds $seeds"
  tools/sitl campaign --scenarios "$scenarios" --seeds "$seeds" --backend "$backend" "${mode[@]}" --no-plots \
    "${sets[@]}" --set "mppi.rollouts=$k" --set daemon.work.enabled=false --out "$out/$k" >"$out/$k.log" 2>&1 ||
    echo "[rollout-curve] K = $k: the campaign exited non-zero (failed flights count as failures): $out/$k.log"
done
dirs=()
for k in "${counts[@]}"; do dirs+=("$out/$k"); done
tools/sitl speed-curve --key mppi.rollouts "${dirs[@]}" --png "$out/curve.png" --json "$out/curve.json" | tee "$out/curve.md"
