#!/usr/bin/env bash
# Sets up and builds (tools/setup.sh), then flies the quadrotor forest task offline
# (closed loop, simulated time) and writes the results under results/forest.
#
#   tools/fly.sh [mppid-offline arguments]     e.g. tools/fly.sh --seed 3
#
# Environment: MPPID_SETUP_ARGS passes arguments to setup.sh (e.g. "--no-apt").
set -euo pipefail

ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
cd "$ROOT"
BUILD_DIR="${MPPID_BUILD_DIR:-build}"

# shellcheck disable=SC2086  # a list of words on purpose
bash tools/setup.sh ${MPPID_SETUP_ARGS:-} >&2

OFFLINE="$BUILD_DIR/bin/mppid-offline"
if [[ ! -x "$OFFLINE" ]]; then
  echo "fly.sh: $OFFLINE was not built (is drivers/ or sim/ in the build yet?)" >&2
  exit 1
fi
mkdir -p results/forest
exec "$OFFLINE" --task quadrotor_forest --out results/forest "$@"
