#!/usr/bin/env bash
# Sets up and builds (tools/setup.sh), then runs every test: the hygiene check
# (tools/check-hygiene.py), ctest over the build, pytest over test/ (a real-time forest flight
# among them), a short soak with scheduled faults
# (tools/soak, every fault once), the sanitizer and fuzzing stage (tools/sanitize.sh:
# ASan+UBSan build of every test, each libFuzzer target 60 s, TSan of the threaded tests),
# then the aarch64 stage (tools/aarch64.sh: a cross build's tests under qemu-user) and the
# package stage (tools/package-test.sh: the .debs built, installed into a clean Debian 12 root
# and flown from there; the arm64 one's programs under qemu-user).
# Exits non-zero when anything failed. This is what CI runs (.ci/run).
#
#   tools/test.sh [--quick] [setup.sh arguments]     e.g. tools/test.sh --no-apt
#
#   --quick   ctest and pytest only (no soak, no sanitizer builds, no fuzzing, no aarch64,
#             no package stage)
#
# Environment: CTEST_ARGS adds ctest arguments (e.g. "-L lcm"), PYTEST_ARGS pytest ones,
# MPPID_SOAK_MINUTES the soak's length (2.5: the schedule's seven faults once each).
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

echo "[test] tools/check-hygiene.py (the tracked files: no development talk, no third-party recipe, sizes)"
python3 tools/check-hygiene.py || status=1

echo "[test] ctest --test-dir $BUILD_DIR --output-on-failure -j2 ${CTEST_ARGS:-}"
# shellcheck disable=SC2086  # CTEST_ARGS is a list of words on purpose
ctest --test-dir "$BUILD_DIR" --output-on-failure --no-tests=error -j2 ${CTEST_ARGS:-} || status=1

if [[ -d test ]] && [[ -n "$(find test -name 'test_*.py' -print -quit)" ]]; then
  echo "[test] pytest test ${PYTEST_ARGS:-}"
  # shellcheck disable=SC2086
  .venv/bin/python -m pytest test -q ${PYTEST_ARGS:-} || {
    rc=$?
    # 5: no test was collected; not a failure while Python tests are being added.
    if ((rc != 5)); then status=1; fi
  }
else
  echo "[test] no Python tests under test/"
fi

if ((!quick)); then
  echo "[test] tools/soak --minutes ${MPPID_SOAK_MINUTES:-2.5}"
  tools/soak --minutes "${MPPID_SOAK_MINUTES:-2.5}" --out results/soak-test || status=1
  echo "[test] tools/sanitize.sh"
  tools/sanitize.sh || status=1
  echo "[test] tools/aarch64.sh"
  tools/aarch64.sh || status=1
  echo "[test] tools/package-test.sh (MPPID_PACKAGE_STAGE=0 skips it)"
  tools/package-test.sh || status=1
fi

if ((status == 0)); then echo "[test] all passed"; else echo "[test] FAILED" >&2; fi
exit "$status"
