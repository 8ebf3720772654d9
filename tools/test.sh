#!/usr/bin/env bash
# Sets up and builds (tools/setup.sh), then runs every test: the hygiene check
# (tools/check-hygiene.py), ctest over the build, pytest over test/ on two workers (a real-time
# forest flight among them; the sanitizer and aarch64 builds beside them at SCHED_IDLE,
# results/builds.log), a short soak with scheduled faults (tools/soak, every fault once,
# flown beside the sanitizer stage), the sanitizer and fuzzing stage (tools/sanitize.sh:
# ASan+UBSan build of every test, each libFuzzer target 30 s, TSan of the threaded tests),
# then the aarch64 cross build (tools/aarch64.sh) and the package stage (tools/package-test.sh:
# the .debs built, installed into a clean Debian 12 root and flown from there; the arm64 one's
# programs under qemu-user), the aarch64 build's tests under qemu-user beside it at nice 19.
# Exits non-zero when anything failed. This is what CI runs (.ci/run).
#
#   tools/test.sh [--quick] [setup.sh arguments]     e.g. tools/test.sh --no-apt
#
#   --quick   ctest and pytest only (no soak, no sanitizer builds, no fuzzing, no aarch64,
#             no package stage)
#
# Environment: CTEST_ARGS adds ctest arguments (e.g. "-L lcm"), PYTEST_ARGS pytest ones,
# MPPID_SOAK_MINUTES the soak's length (2.5: the schedule's seven faults once each).
# MPPID_PYTEST_JOBS the Python tests' workers (2; 0: none, one process).
set -euo pipefail

ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
cd "$ROOT"
BUILD_DIR="${MPPID_BUILD_DIR:-build}"
quick=0
if [[ "${1:-}" == "--quick" ]]; then quick=1; shift; fi

# The fuzz targets' corpus replays (test/fuzz) run in the ASan build when the sanitizer stage
# does; a quick run keeps them in this build.
if ((quick)); then
  export MPPID_FUZZ_REPLAY="${MPPID_FUZZ_REPLAY:-ON}"
  bash tools/setup.sh "$@"
else
  export MPPID_FUZZ_REPLAY="${MPPID_FUZZ_REPLAY:-OFF}"
  bash tools/setup.sh --aarch64 "$@"
fi

status=0
# Each stage's wall time, printed at the end (a stage over its share of CI's time shows here).
stage_names=() stage_secs=() stage_t0=0  # SECONDS: since the script began, so setup counts
stage_done() { stage_names+=("$1"); stage_secs+=($((SECONDS - stage_t0))); stage_t0=$SECONDS; }
stage_done setup

# The sanitizer and aarch64 builds (tools/sanitize.sh --build-only, tools/aarch64.sh
# --build-only) start now, beside ctest and pytest, at SCHED_IDLE: they take only the CPU time
# nothing else wants, and pytest leaves much of it (its flights wait on real time and take
# turns). From an empty compile cache they are ~20 minutes of compiling on 2 cores; the stages
# below wait for them, then find them built (and build whatever a failure here left).
builds_pid=""
if ((!quick)); then
  mkdir -p results
  idle=(chrt --idle 0)
  "${idle[@]}" true 2>/dev/null || idle=(nice -n 19)
  echo "[test] the sanitizer and aarch64 builds beside ctest and pytest (${idle[*]}; their log: results/builds.log)"
  "${idle[@]}" bash -c 'tools/sanitize.sh --build-only && tools/aarch64.sh --build-only' >results/builds.log 2>&1 &
  builds_pid=$!
fi

echo "[test] tools/check-hygiene.py (the tracked files: no development talk, no third-party recipe, sizes)"
python3 tools/check-hygiene.py || status=1
stage_done hygiene

echo "[test] ctest --test-dir $BUILD_DIR --output-on-failure -j2 ${CTEST_ARGS:-}"
# shellcheck disable=SC2086  # CTEST_ARGS is a list of words on purpose
ctest --test-dir "$BUILD_DIR" --output-on-failure --no-tests=error -j2 ${CTEST_ARGS:-} || status=1
stage_done ctest

if [[ -d test ]] && [[ -n "$(find test -name 'test_*.py' -print -quit)" ]]; then
  # Two workers, a test file each at a time (pytest-xdist; MPPID_PYTEST_JOBS=0: one process).
  jobs_args=(-n "${MPPID_PYTEST_JOBS:-2}" --dist loadfile)
  [[ "${MPPID_PYTEST_JOBS:-2}" == 0 ]] && jobs_args=()
  echo "[test] pytest test ${jobs_args[*]} ${PYTEST_ARGS:-}"
  # shellcheck disable=SC2086
  .venv/bin/python -m pytest test -q --durations=12 "${jobs_args[@]}" ${PYTEST_ARGS:-} || {
    rc=$?
    # 5: no test was collected; not a failure while Python tests are being added.
    if ((rc != 5)); then status=1; fi
  }
else
  echo "[test] no Python tests under test/"
fi
stage_done pytest

if ((!quick)); then
  echo "[test] waiting for the sanitizer and aarch64 builds (results/builds.log)"
  wait "$builds_pid" || echo "[test] those builds failed (rc $?; results/builds.log): the stages below build again and report"
  grep -E '^\[(sanitize|aarch64)\]' results/builds.log || true
  stage_done builds
  # The soak flies in real time (SCHED_FIFO) beside the sanitizer stage's tests and fuzzers:
  # a busy machine, as a companion computer is, and 2.5 minutes of CI's time given back.
  echo "[test] tools/soak --minutes ${MPPID_SOAK_MINUTES:-2.5} (beside the sanitizer stage; its log: results/soak-test.log)"
  mkdir -p results
  tools/soak --minutes "${MPPID_SOAK_MINUTES:-2.5}" --out results/soak-test >results/soak-test.log 2>&1 &
  soak_pid=$!
  echo "[test] tools/sanitize.sh"
  tools/sanitize.sh || status=1
  stage_done sanitize
  soak_rc=0
  wait "$soak_pid" || soak_rc=$?
  grep '^\[soak\]' results/soak-test.log || tail -n 20 results/soak-test.log
  if ((soak_rc != 0)); then echo "[test] the soak FAILED (rc $soak_rc): results/soak-test.log" >&2; status=1; fi
  stage_done soak
  echo "[test] tools/aarch64.sh --build-only"
  tools/aarch64.sh --build-only || status=1
  stage_done aarch64
  # The emulated aarch64 tests (CPU-bound, minutes) run beside the package stage at nice 19:
  # its flights' processes run at SCHED_FIFO and wait on real time for most of the stage, and
  # its other steps at the normal priority come first; the tests take the CPU that is left.
  echo "[test] tools/aarch64.sh --no-build at nice 19, beside the package stage (its log: results/aarch64.log)"
  nice -n 19 tools/aarch64.sh --no-build >results/aarch64.log 2>&1 &
  aarch64_pid=$!
  echo "[test] tools/package-test.sh (MPPID_PACKAGE_STAGE=0 skips it)"
  tools/package-test.sh || status=1
  stage_done package
  aarch64_rc=0
  wait "$aarch64_pid" || aarch64_rc=$?
  grep '^\[aarch64\]' results/aarch64.log || true
  if ((aarch64_rc != 0)); then
    tail -n 80 results/aarch64.log
    echo "[test] the aarch64 tests FAILED (rc $aarch64_rc): results/aarch64.log" >&2; status=1
  fi
  stage_done qemu  # what the emulated tests took beyond the package stage
fi

total=0
for i in "${!stage_names[@]}"; do
  printf '[test] stage %-9s %5d s\n' "${stage_names[$i]}" "${stage_secs[$i]}"
  total=$((total + stage_secs[i]))
done
printf '[test] stage %-9s %5d s\n' total "$total"

if ((status == 0)); then echo "[test] all passed"; else echo "[test] FAILED" >&2; fi
exit "$status"
