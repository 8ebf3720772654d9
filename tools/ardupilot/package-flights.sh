#!/usr/bin/env bash
# ArduCopter SITL flown from the installed package (issue 29; docs/ardupilot.md): the amd64 .deb
# built, installed into a clean Debian 12 root (tools/package-test.sh), and there, from the
# installed files alone, hover, circle_3ms and circle_3ms with mppid killed mid-circle flown
# against a real ArduCopter SITL (test/deploy/package_sitl.py); then scored from the SITL's
# truth as the harness scores its own flights. Not CI: it needs an ArduCopter SITL build
# (ArduPilot's own instructions, outside this tree; docs/ardupilot.md names the build flown).
#
#   tools/ardupilot/package-flights.sh ARDUCOPTER_BIN OUT_DIR [package_flight.py arguments]
#
# Needs root (a chroot and a network namespace), as tools/package-test.sh.
set -euo pipefail
ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/../.." && pwd)"
[[ $# -ge 2 ]] || { sed -n '2,11s/^# \{0,1\}//p' "${BASH_SOURCE[0]}" >&2; exit 2; }
bin="$1" out="$(realpath -m "$2")"
shift 2
cd "$ROOT"
extra=()
(($#)) && extra=(-- "$@")
status=0
tools/package-test.sh --ardupilot-bin "$bin" --keep "$out" "${extra[@]}" || status=$?
.venv/bin/python tools/ardupilot/score_package_flights.py "$out" | tee "$out/table.md"
exit "$status"
