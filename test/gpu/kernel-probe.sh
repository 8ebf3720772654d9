#!/bin/bash
# Kernel work on a GPU host in one run: build only the CUDA targets (no LCM, no
# SIMD CPU kernels: the parity reference is the scalar CPU backend), then the steps named.
#   test/gpu/kernel-probe.sh STEP...
# Steps:
#   build        build-k/ (or $B): cuda_backend_tests, mppid-gpu-timing (ptxas resource report
#                of the rollout kernels into ptxas.txt)
#   build-ftz    the same with MPPID_CUDA_FTZ=ON into $B-ftz
#   parity       CudaParity.* and CudaDeterminism.* and the allocation tests (parity.txt)
#   parity-ftz   the same on the FTZ build
#   build-fast, parity-fast, timing-fast: the same with MPPID_CUDA_FAST_MATH=ON ($B-fast)
#   build-fmad, parity-fmad, timing-fmad: the same with MPPID_CUDA_FMAD=ON ($B-fmad)
#   timing       the kernel targets (mppid-gpu-timing, test scenario, obstacle grid), one JSON
#   timing2      the same again (the spread between two runs)
#   timing-ftz   the same on the FTZ build
#   variants     block shapes and kernels at K = 16,384 (mppi.cuda settings)
#   ncu          Nsight Compute, full set with per-instruction samples, on the chunked kernel
#   ncu-others   Nsight Compute on one update's kernels of each other target (ncu-*.txt)
#   sass         cuobjdump -sass of the quadrotor_forest instantiation (sass.txt.gz)
# Logs and results are written to results/kernel-work; one archive of them, kernel.tgz, lands in
# $MPPID_RESULTS (default results/kernel). Build: $B (default build-k/ in this tree).
set -uo pipefail
source "$(dirname "${BASH_SOURCE[0]}")/../../tools/gpu/devdeps.sh"
cd "$ROOT"
B="${B:-$ROOT/build-k}"
# Everything goes to a work folder; at the end one archive of it lands in $DEST.
DEST="${MPPID_RESULTS:-$ROOT/results/kernel}"
WORK="$ROOT/results/kernel-work"
rm -rf "$WORK" && mkdir -p "$WORK" "$DEST"
T0=$(date +%s)
stamp() { echo "[$(($(date +%s) - T0)) s] $*"; }
TARGETS=(quadrotor_forest:16384 quadrotor_rate_forest:16384 team3_forest:1200 team9_forest:6000)

build() {  # dir, extra cmake args...
  local dir=$1; shift
  cmake -S . -B "$dir" -G Ninja -DCMAKE_BUILD_TYPE=Release -DMPPID_CUDA=ON -DCMAKE_CUDA_ARCHITECTURES=90 \
    -DMPPID_WERROR=OFF -DMPPID_LCM=OFF -DMPPID_SIMD=OFF -DMPPID_BENCH=OFF -DMPPID_TESTS=ON \
    -DRANDOM123_INCLUDE_DIR="$D/usr/include" -DCMAKE_CUDA_FLAGS="-Xptxas=-v" "$@" >"$WORK/configure-$(basename "$dir").log" 2>&1 &&
    ninja -C "$dir" -j"$(nproc)" cuda_backend_tests mppid-gpu-timing >"$WORK/build-$(basename "$dir").log" 2>&1
}
parity() {  # build dir, label
  timeout 300 "$1/bin/cuda_backend_tests" --gtest_filter='CudaParity.*:CudaDeterminism.*:CudaErrors.*:CudaBackend.*' \
    >"$WORK/parity-$2.log" 2>&1
  local rc=$?
  grep -E '^\[parity\] [a-z_0-9+ ,]+ +cost|^\[parity\] chunked K=|FAILED|PASSED|tests ran|Failure|error' "$WORK/parity-$2.log" |
    grep -v '^\[parity\] .*cycle' | head -60 >"$WORK/parity-$2.txt"
  echo "parity $2: rc $rc; $(grep -E 'PASSED|FAILED' "$WORK/parity-$2.log" | tr '\n' ' ')"
}
timing() {  # build dir, label
  {
    "$1/bin/mppid-gpu-timing" --iters 1000 "${TARGETS[@]}" quadrotor_forest:4096
    "$1/bin/mppid-gpu-timing" --iters 100 --warmup 5 quadrotor_forest:1048576
  } >"$WORK/timing-$2.json" 2>&1
  sed -nE 's/^ *\{"task": "([^"]*)", "rollouts": ([0-9]*), .*"median_us": ([0-9.]*), "p99_us": ([0-9.]*).*/'"$2"' \1 K=\2 median \3 p99 \4/p' "$WORK/timing-$2.json"
}
row() {  # label, mppi.cuda.FIELD=VALUE..., -- timing args
  local label=$1; shift
  local sets=()
  while [ "$1" != "--" ]; do sets+=(--set "$1"); shift; done
  shift
  "$B/bin/mppid-gpu-timing" "${sets[@]}" "$@" 2>&1 |
    sed -nE "s/^ *\{\"task\": \"([^\"]*)\", \"rollouts\": ([0-9]*), .*\"median_us\": ([0-9.]*), \"p99_us\": ([0-9.]*).*/$label \1 K=\2 median \3 p99 \4/p"
}

for step in "$@"; do
  case $step in
    build)
      stamp "build $B"
      build "$B" || { echo "BUILD FAILED"; grep -E 'error|warning' "$WORK/build-$(basename "$B").log" | head -30; exit 1; }
      grep -cE "warning" "$WORK/build-$(basename "$B").log" | sed "s/^/warnings in the build log: /"
      grep -A4 -E "Compiling entry function '.*(rollout|finalize|weigh)" "$WORK/build-$(basename "$B").log" |
        grep -E "Compiling|registers|spill" >"$WORK/ptxas.txt" || true
      stamp "built" ;;
    build-ftz)
      stamp "build $B-ftz"
      build "$B-ftz" -DMPPID_CUDA_FTZ=ON || { echo "FTZ BUILD FAILED"; grep -E 'error' "$WORK/build-$(basename "$B")-ftz.log" | head; }
      stamp "built ftz" ;;
    build-fast)
      stamp "build $B-fast"
      build "$B-fast" -DMPPID_CUDA_FAST_MATH=ON || { echo "FAST BUILD FAILED"; grep -E 'error' "$WORK/build-$(basename "$B")-fast.log" | head; }
      stamp "built fast" ;;
    build-fmad)
      stamp "build $B-fmad"
      build "$B-fmad" -DMPPID_CUDA_FMAD=ON || { echo "FMAD BUILD FAILED"; grep -E 'error' "$WORK/build-$(basename "$B")-fmad.log" | head; }
      stamp "built fmad" ;;
    cpucheck)
      # The CPU side of a change to core/ (fsincos): core's tests with the SIMD targets, -Werror.
      stamp "cpu build"
      # (-Werror off: an Ubuntu 24.04 host's newer g++ warns in code outside core; the log is searched
      # for warnings in core's headers instead.)
      cmake -S . -B "$B-cpu" -G Ninja -DCMAKE_BUILD_TYPE=Release -DMPPID_CUDA=OFF -DMPPID_WERROR=OFF -DMPPID_LCM=OFF \
        -DMPPID_SIMD=ON -DMPPID_BENCH=OFF -DMPPID_TESTS=ON -DRANDOM123_INCLUDE_DIR="$D/usr/include" \
        -DCMAKE_PREFIX_PATH="$D/usr" >"$WORK/configure-cpu.log" 2>&1 &&
        ninja -C "$B-cpu" -k 0 -j"$(nproc)" core_tests core_simd_tests core_alloc_tests closed_loop_tests >"$WORK/build-cpu.log" 2>&1 ||
        { echo "CPU BUILD FAILED"; grep -E "error|warning" "$WORK/build-cpu.log" | head -20; }
      echo "warnings in core/: $(grep -cE 'core/include/.*warning|core/src/.*warning' "$WORK/build-cpu.log")"
      export LD_LIBRARY_PATH="$D/usr/lib/x86_64-linux-gnu:$LD_LIBRARY_PATH"
      for t in core_tests core_simd_tests core_alloc_tests closed_loop_tests; do
        timeout 300 "$B-cpu"/bin/$t >"$WORK/cpu-$t.log" 2>&1
        echo "cpu $t: rc $? $(grep -E '^\[  (PASSED|FAILED)' "$WORK/cpu-$t.log" | tr '\n' ' ')"
      done
      stamp "cpu tests done" ;;
    parity) parity "$B" base ;;
    parity-ftz) parity "$B-ftz" ftz ;;
    parity-fast) parity "$B-fast" fast ;;
    parity-fmad) parity "$B-fmad" fmad ;;
    timing) timing "$B" base ;;
    timing2) timing "$B" again ;;
    timing-ftz) timing "$B-ftz" ftz ;;
    timing-fast) timing "$B-fast" fast ;;
    timing-fmad) timing "$B-fmad" fmad ;;
    variants)
      {
        for c in 16 20; do row "team chunk=$c" mppi.cuda.chunk_steps=$c -- --iters 1000 team3_forest:1200; done
        row "lanes (v4 path)" mppi.cuda.kernel=lanes -- --iters 1000 quadrotor_forest:16384 team3_forest:1200
        row "lanes redraw" mppi.cuda.controls=redraw -- --iters 100 --warmup 5 quadrotor_forest:1048576
      } | tee "$WORK/variants.txt" ;;
    ncu)
      command -v ncu >/dev/null || { echo "no ncu"; continue; }
      TM=("$B/bin/mppid-gpu-timing" --set mppi.cuda.graph=false)
      NCU_CASE=${NCU_CASE:-quadrotor_forest:16384}
      stamp "ncu full, chunked $NCU_CASE"
      timeout 200 ncu --clock-control none --kernel-name regex:rollout_chunked --launch-skip 6 --launch-count 1 --set full \
        --import-source no -f -o "$WORK/ncu-chunked" "${TM[@]}" --iters 3 --warmup 5 "$NCU_CASE" >"$WORK/ncu-chunked.log" 2>&1
      ncu --import "$WORK/ncu-chunked.ncu-rep" --page details >"$WORK/ncu-chunked.txt" 2>&1
      ncu --import "$WORK/ncu-chunked.ncu-rep" --page source --csv --print-source sass 2>/dev/null | gzip >"$WORK/ncu-chunked-sass.csv.gz"
      rm -f "$WORK/ncu-chunked.ncu-rep"
      grep -E "Duration|Executed Ipc A|Issue Slots Busy|No Eligible|Warp Cycles Per Issued|Executed Instructions  |Achieved Active Warps" "$WORK/ncu-chunked.txt"
      [ -n "${NCU_SKIP_4096:-}" ] || timeout 150 ncu --clock-control none --kernel-name regex:rollout_chunked --launch-skip 6 --launch-count 1 \
        --section SpeedOfLight --section WarpStateStats --section SourceCounters --section InstructionStats \
        --import-source no -f -o "$WORK/ncu-4096" "${TM[@]}" --iters 3 --warmup 5 quadrotor_forest:4096 >"$WORK/ncu-4096.log" 2>&1
      ncu --import "$WORK/ncu-4096.ncu-rep" --page details >"$WORK/ncu-4096.txt" 2>&1
      ncu --import "$WORK/ncu-4096.ncu-rep" --page source --csv --print-source sass 2>/dev/null | gzip >"$WORK/ncu-4096-sass.csv.gz"
      rm -f "$WORK/ncu-4096.ncu-rep"
      grep -E "Duration|Executed Instructions  " "$WORK/ncu-4096.txt" | sed 's/^/4096: /'
      stamp "ncu done" ;;
    ncu-others)
      TM=("$B/bin/mppid-gpu-timing" --set mppi.cuda.graph=false)
      stamp "ncu others"
      secs=(--section SpeedOfLight --section LaunchStats --section Occupancy --section WarpStateStats --section InstructionStats --section SchedulerStats)
      for c in quadrotor_rate_forest:16384 team3_forest:1200 team9_forest:6000 quadrotor_forest:4096; do
        echo "==== $c"
        timeout 120 ncu --clock-control none --launch-skip 12 --launch-count 5 "${secs[@]}" "${TM[@]}" --iters 3 --warmup 8 "$c"
      done >"$WORK/ncu-others.txt" 2>&1
      echo "==== quadrotor_forest:1048576" >>"$WORK/ncu-others.txt"
      timeout 150 ncu --clock-control none --launch-skip 4 --launch-count 4 "${secs[@]}" "${TM[@]}" --iters 1 --warmup 2 quadrotor_forest:1048576 \
        >>"$WORK/ncu-others.txt" 2>&1
      grep -E '^  [a-zA-Z_].*\(|^==== |Duration|Executed Ipc A|Issue Slots Busy|No Eligible|Warp Cycles Per Issued|Achieved Occupancy|Executed Instructions  |Registers Per|Block Limit (Sh|Reg)|Theoretical Occ' \
        "$WORK/ncu-chunked.txt" "$WORK/ncu-others.txt" | sed 's/^[^:]*://' >"$WORK/ncu-summary.txt"
      stamp "ncu done" ;;
    sass)
      obj=$(find "$B" -name 'instantiate_QuadrotorForest.cu.o' | head -1)
      [ -n "$obj" ] && cuobjdump -sass "$obj" | gzip >"$WORK/sass.txt.gz" ;;
    *) echo "unknown step $step" ;;
  esac
done
stamp "all done"
tar czf "$DEST/kernel.tgz" -C "$WORK" . && ls -la "$DEST"
