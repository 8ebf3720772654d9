#!/usr/bin/env bash
# Sets up and builds (tools/setup.sh), then runs every test: ctest over the build, then
# pytest over test/ when it holds Python tests. Exits non-zero when anything failed.
#
#   tools/test.sh [setup.sh arguments]     e.g. tools/test.sh --no-apt
#
# Environment: CTEST_ARGS adds ctest arguments (e.g. "-L lcm"), PYTEST_ARGS pytest ones.
set -euo pipefail

ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
cd "$ROOT"
BUILD_DIR="${MPPID_BUILD_DIR:-build}"

bash tools/setup.sh "$@"

status=0

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

if ((status == 0)); then echo "[test] all passed"; else echo "[test] FAILED" >&2; fi
exit "$status"
