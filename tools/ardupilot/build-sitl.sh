#!/usr/bin/env bash
# Builds ArduCopter SITL from an ArduPilot checkout (outside this repository, at nice 19), as
# ArduPilot's documentation says (https://ardupilot.org/dev/docs/building-setup-linux.html):
# `./waf configure --board sitl`, then `./waf copter`. Prints the binary for
# `tools/sitl --autopilot ardupilot` (MPPID_ARDUPILOT_BIN). Never run in CI: ~1,100 compile steps.
#
#   tools/ardupilot/build-sitl.sh CHECKOUT [--no-can] [--jobs N]
#
#   CHECKOUT   an ArduPilot git checkout with its submodules (modules/waf, modules/mavlink, ...)
#   --no-can   configure SITL without CAN: for a checkout without the DroneCAN submodules
#              (modules/DroneCAN/*). waf has no option for it, so this turns SITL's `with_can`
#              off in the checkout's Tools/ardupilotwaf/boards.py (a local edit, shown by
#              `git -C CHECKOUT diff`)
#   --jobs N   parallel compile jobs (default: the number of cores)
#
# SITL is configured with --disable-networking (AP_Networking's lwIP is not needed for SITL's
# serial ports) and --no-submodule-update (the submodules are the checkout's own).
# waf's Python packages (empy 3.3.4, future, pexpect: ArduPilot's own list for Debian) go into a
# venv beside the checkout, CHECKOUT/.venv-sitl; apt packages it needs: g++, git, python3-venv.
set -euo pipefail

usage() { sed -n '2,19s/^# \{0,1\}//p' "${BASH_SOURCE[0]}"; }
checkout="" no_can=0 jobs="$(nproc)"
while (($#)); do
  case "$1" in
    --no-can) no_can=1 ;;
    --jobs) jobs="$2"; shift ;;
    -h|--help) usage; exit 0 ;;
    -*) echo "build-sitl.sh: unknown option '$1' (try --help)" >&2; exit 2 ;;
    *) checkout="$1" ;;
  esac
  shift
done
[[ -n "$checkout" ]] || { usage >&2; exit 2; }
checkout="$(cd "$checkout" && pwd)"
[[ -x "$checkout/waf" && -f "$checkout/Tools/ardupilotwaf/boards.py" ]] ||
  { echo "build-sitl.sh: $checkout is not an ArduPilot checkout (no waf, no Tools/ardupilotwaf)" >&2; exit 2; }
git -C "$checkout" rev-parse --git-dir >/dev/null 2>&1 ||
  { echo "build-sitl.sh: $checkout is not a git repository (ArduPilot's waf reads its version from git)" >&2; exit 2; }
for m in modules/waf modules/mavlink; do
  [[ -n "$(ls -A "$checkout/$m" 2>/dev/null)" ]] ||
    { echo "build-sitl.sh: $checkout/$m is empty: git -C $checkout submodule update --init --recursive" >&2; exit 2; }
done

venv="$checkout/.venv-sitl"
if [[ ! -x "$venv/bin/python" ]]; then
  python3 -m venv "$venv"
  "$venv/bin/pip" install -q --disable-pip-version-check "empy==3.3.4" future pexpect
fi
# shellcheck disable=SC1091
source "$venv/bin/activate"

cd "$checkout"
if ((no_can)); then
  sed -i 's/^\(        self.with_can = \)True$/\1False/' Tools/ardupilotwaf/boards.py
  grep -q "self.with_can = False" Tools/ardupilotwaf/boards.py ||
    { echo "build-sitl.sh: --no-can found no 'self.with_can = True' to turn off in boards.py" >&2; exit 1; }
fi
nice -n 19 ./waf configure --board sitl --disable-networking --no-submodule-update
nice -n 19 ./waf copter -j"$jobs"
bin="$checkout/build/sitl/bin/arducopter"
[[ -x "$bin" ]] || { echo "build-sitl.sh: the build ended without $bin" >&2; exit 1; }
echo "export MPPID_ARDUPILOT_BIN=$bin"
