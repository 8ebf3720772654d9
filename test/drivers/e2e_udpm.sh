#!/bin/sh
# End-to-end test of mppid over real UDP multicast LCM between processes, inside a private
# network namespace (loopback up, multicast routed to it, ttl=0), so it neither needs nor
# disturbs the host network. Usage: e2e_udpm.sh PYTHON MPPID CONFIG PYTHON_TYPES_DIR
# If the namespace cannot be created this FAILS (exit 1); it never passes silently.
set -eu
PY=$1 MPPID=$2 CONFIG=$3 TYPES=$4
HERE=$(cd "$(dirname "$0")" && pwd)
if ! unshare -n true 2>/dev/null; then
  echo "FAIL: 'unshare -n' is not permitted here (needs root or user namespaces);" \
       "the end-to-end multicast test cannot run" >&2
  exit 1
fi
exec unshare -n sh -c '
  set -e
  ip link set lo up
  ip route add 224.0.0.0/4 dev lo
  exec "$@"' sh "$PY" "$HERE/e2e_udpm.py" --mppid "$MPPID" --config "$CONFIG" --types "$TYPES"
