#!/usr/bin/env bash
# CI's aarch64 stage (tools/test.sh, after `tools/setup.sh --aarch64` and the x86-64 build):
# cross-builds for aarch64 (preset `aarch64`: cmake/toolchains/aarch64-linux-gnu.cmake,
# build-aarch64, through ccache) only the tests it runs, and runs them under qemu-user
# (Cortex-A76), two at a time:
#   core_tests            models, noise, optimizer, determinism, thread-count independence
#   core_simd_tests       the NEON lanes against the scalar code, anytime, obstacle grid
#   plan_reference        this machine's build/ writes its plans; the emulated build's scalar
#                         code must match them bit for bit, its NEON lanes AVX2's bit for bit
#                         and the scalar plans within the SIMD tolerances (docs/aarch64.md)
#   rt_tests, rt_alloc_tests   the real-time blocks and the control loop on a fake clock
#   driver_tests, lcm_types_roundtrip   LCM in process (memq://, the lcm wheel for aarch64)
#   daemon_binary_tests   the mppid binary (under qemu too), but not the one test that needs
#                         a network namespace (the udpm ones stay with the x86-64 stage)
#   simd_kernels_share_no_symbols   the NEON kernel objects
#   mapper_tests          mppid-mapper's grid, distance transform and node (the package ships
#                         it; the tests link the simulator's sensors, built here too: ~10 more
#                         files, cached by ccache after the first run; 1 s under qemu)
# Not here: the benchmarks (bench: x86-64 timing tools), the closed-loop flights, the MPC-DDP baseline (ddp_tests: 3 min of cold compile),
# the allocation counts of core_alloc_tests (the NEON path's are the same code as SSE4's;
# ~3 min under emulation), the simulator's own tests, the fuzz corpora, systemd and the
# end-to-end tests: their code is the x86-64 stage's, not the ISA's.
#
#   tools/aarch64.sh [--no-build | --build-only]
#
# Environment: MPPID_JOBS (2) build and test jobs; CI=true makes warnings errors.
set -euo pipefail

ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
cd "$ROOT"
build=1 run=1
case "${1:-}" in
  --no-build) build=0 ;;
  --build-only) run=0 ;;
  "") ;;
  -h|--help) sed -n '2,26s/^# \{0,1\}//p' "${BASH_SOURCE[0]}"; exit 0 ;;
  *) echo "aarch64.sh: unknown argument '$1' (try --help)" >&2; exit 2 ;;
esac
jobs="${MPPID_JOBS:-2}"
log() { printf '[aarch64] %s\n' "$*"; }
stamp() { date +%s; }

TARGETS=(core_tests core_simd_tests plan_reference rt_tests rt_alloc_tests driver_tests lcm_types_roundtrip
         daemon_binary_tests mppid mppid-mapper mapper_tests)
# Defined in build-aarch64 but not built here (the list above says why).
EXCLUDE_LABELS='closed_loop|fuzz|sim|e2e|systemd|bench'
EXCLUDE='^(NoAlloc\.|(closed_loop_tests|ddp_closed_loop_tests|ddp_tests|core_alloc_tests)_NOT_BUILT$|lcm_types_(python|java)$|DaemonBinary\.WarnsWhenItsLcmUrlWouldLeaveTheHost$)'

[[ -x build/bin/plan_reference ]] || { echo "aarch64.sh: build/bin/plan_reference missing (tools/setup.sh builds it)" >&2; exit 1; }

t0=$(stamp)
if ((build)); then
  args=(--preset aarch64)
  if command -v ccache >/dev/null; then
    args+=(-DCMAKE_CXX_COMPILER_LAUNCHER=ccache)
    export CCACHE_BASEDIR="$ROOT" CCACHE_NOHASHDIR=true  # another clone of the same tree hits
  fi
  if [[ -n "${CI:-}" ]]; then args+=(-DMPPID_WERROR=ON); fi
  log "configure and build build-aarch64: ${TARGETS[*]}"
  cmake "${args[@]}" >/dev/null
  cmake --build build-aarch64 -j"$jobs" --target "${TARGETS[@]}"
fi
t1=$(stamp)
if ((!run)); then log "build $((t1 - t0)) s (tests not run: --build-only)"; exit 0; fi
log "ctest under qemu-user (excluded: labels $EXCLUDE_LABELS; $EXCLUDE)"
status=0
ctest --test-dir build-aarch64 --output-on-failure --no-tests=error -j"$jobs" \
  -LE "$EXCLUDE_LABELS" -E "$EXCLUDE" || status=1
log "build $((t1 - t0)) s, tests $(($(stamp) - t1)) s"
if ((status == 0)); then log "all passed"; else log "FAILED" >&2; fi
exit "$status"
