#!/bin/bash
# A change to the CUDA backend that must not change what it computes nor slow it (issue 28's
# host-side split), on a GPU host in one run: this tree and a base tree built side
# by side (CUDA, no LCM, no SIMD), the CUDA tests of both with their `[parity]` lines compared
# line by line, then mppid-bench (Controller::iterate) and mppid-gpu-timing (the update alone)
# for quadrotor, rate, team3 and team9, base and this interleaved, two rounds.
#   test/gpu/compare-trees.sh BASE_TREE [build] [test] [bench]
# BASE_TREE is a copy of the base commit (e.g. `git archive BASE | tar -x -C base`); of .devdeps
# (tools/gpu/pack-deps.sh) it needs only Random123. ~1 min on an H100 or H200. Builds go to
# $MPPID_BUILD_ROOT/build-cmp-{base,this} (default: this tree), the logs and results to
# $MPPID_RESULTS (default results/compare) and a .tgz of it beside; the summary on stdout.
set -uo pipefail
source "$(dirname "${BASH_SOURCE[0]}")/../../tools/gpu/devdeps.sh"
HERE="$ROOT"
BASE="$(cd "${1:?base tree}" && pwd)"; shift
R="${MPPID_RESULTS:-$HERE/results/compare}"
BR="${MPPID_BUILD_ROOT:-$HERE}"
mkdir -p "$R"
finish() { tar czf "$R.tgz" -C "$R" . ; }
trap finish EXIT
T0=$(date +%s)
stamp() { echo "[$(($(date +%s) - T0)) s] $*"; }
build() {  # tree, build dir, label, targets...
  cmake -S "$1" -B "$2" -G Ninja -DCMAKE_BUILD_TYPE=Release -DMPPID_CUDA=ON -DCMAKE_CUDA_ARCHITECTURES=90 \
    -DMPPID_WERROR=OFF -DMPPID_LCM=OFF -DMPPID_SIMD=OFF -DMPPID_TESTS=ON -DMPPID_BENCH=ON \
    -DRANDOM123_INCLUDE_DIR="$D/usr/include" >"$R/configure-$3.log" 2>&1 &&
    ninja -C "$2" -j8 "${@:4}" >"$R/build-$3.log" 2>&1
}
if [[ " $* " == *" build "* ]]; then
  build "$BASE" "$BR/build-cmp-base" base cuda_backend_tests mppid-bench mppid-gpu-timing & p1=$!
  build "$HERE" "$BR/build-cmp-this" this cuda_backend_tests mppid-bench mppid-gpu-timing launch_plan_tests cuda_settings_tests & p2=$!
  wait $p1 || { echo "BASE BUILD FAILED"; grep -E "error" "$R/build-base.log" "$R/configure-base.log" | head -20; }
  wait $p2 || { echo "THIS BUILD FAILED"; grep -E "error" "$R/build-this.log" "$R/configure-this.log" | head -30; exit 1; }
  stamp "built"
  grep -A4 -E "Compiling entry function '.*rollout_chunked" "$R/build-this.log" | grep -E "registers|spill" | head -4
fi
nvidia-smi --query-gpu=name,driver_version,clocks.sm,clocks.max.sm --format=csv,noheader
if [[ " $* " == *" test "* ]]; then
  for t in base this; do
    # stdout alone: the backend's log line (stderr) must not cut a [parity] line.
    timeout 300 "$BR/build-cmp-$t"/bin/cuda_backend_tests >"$R/tests-$t.log" 2>"$R/tests-$t.err"
    echo "$t cuda_backend_tests rc=$? $(grep -E '^\[  (PASSED|FAILED|SKIPPED)' "$R/tests-$t.log" | tr '\n' ' ')"
    grep -E '^\[  FAILED' "$R/tests-$t.log" | head
  done
  "$BR/build-cmp-this"/bin/launch_plan_tests >"$R/host-tests.log" 2>&1; echo "launch_plan_tests rc=$?"
  "$BR/build-cmp-this"/bin/cuda_settings_tests >>"$R/host-tests.log" 2>&1; echo "cuda_settings_tests rc=$?"
  for t in base this; do grep -E '^\[parity\]' "$R/tests-$t.log" >"$R/parity-$t.txt"; done
  # Tests only this tree has: compare the lines the base has (issue 28: LaunchSwitches).
  grep -vE 'no graph|host.s grid' "$R/parity-this.txt" >"$R/parity-this-common.txt"
  diff "$R/parity-base.txt" "$R/parity-this-common.txt" >"$R/parity-diff.txt"
  echo "parity lines: base $(wc -l <"$R/parity-base.txt"), this $(wc -l <"$R/parity-this.txt") ($(wc -l <"$R/parity-this-common.txt") in common); differing lines: $(grep -c '^[<>]' "$R/parity-diff.txt")"
  grep -m3 "cuda backend:" "$R/tests-this.err"
  stamp "tested"
fi
if [[ " $* " == *" bench "* ]]; then
  for round in 1 2; do
    for t in base this; do
      for m in "quadrotor 16384" "quadrotor_rate 16384" "team3 1200" "team9 6000"; do
        set -- $m
        "$BR/build-cmp-$t"/bin/mppid-bench --model "$1" --backend cuda --rollouts "$2" --horizon 100 --obstacles 32 \
          --iterations 1000 2>>"$R/bench-$t.err" | grep '^{' | sed "s/^{/{\"tree\":\"$t\",\"round\":$round,/" >>"$R/bench.jsonl"
      done
      "$BR/build-cmp-$t"/bin/mppid-gpu-timing --iters 1000 quadrotor_forest:16384 quadrotor_rate_forest:16384 team3_forest:1200 \
        team9_forest:6000 >"$R/timing-$t-$round.json" 2>>"$R/bench-$t.err"
    done
  done
  stamp "benched"
  python3 - "$R" <<'PY'
import json, sys, glob, os
R = sys.argv[1]
rows = [json.loads(l) for l in open(os.path.join(R, "bench.jsonl")) if l.strip()]
def key(r):
    return (r.get("model") or r.get("task"), r.get("rollouts"))
print("mppid-bench (Controller::iterate), median / p99 us:")
cases = []
for r in rows:
    if key(r) not in cases: cases.append(key(r))
for c in cases:
    cells = []
    for t in ("base", "this"):
        v = [r for r in rows if key(r) == c and r["tree"] == t]
        cells.append(" ".join("%s/%s" % (r.get("median_us"), r.get("p99_us")) for r in v))
    print("  %-28s base %s | this %s" % ("%s K=%s" % c, cells[0], cells[1]))
print("mppid-gpu-timing (update alone, test scene), median us:")
for t in ("base", "this"):
    for rnd in (1, 2):
        p = os.path.join(R, "timing-%s-%d.json" % (t, rnd))
        try:
            d = json.load(open(p))
        except Exception as e:
            print("  %s round %d: unreadable (%s)" % (t, rnd, e)); continue
        print("  %s r%d: " % (t, rnd) + ", ".join("%s %.1f" % (x["task"], x["median_us"]) for x in d["results"]))
PY
  head -c 600 "$R/bench.jsonl"; echo
  grep -m2 "cuda backend" "$R/bench-this.err"
fi
stamp "done"
