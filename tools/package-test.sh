#!/usr/bin/env bash
# CI's package stage (tools/test.sh, after the aarch64 stage; docs/deploy.md):
#   1. tools/package.sh: the amd64 .deb from build/, the arm64 .deb from build-aarch64/; lintian
#      on each (Debian's checks of a binary package): any error or warning fails the stage (the
#      warnings the package keeps are overridden in cmake/debian/lintian-overrides, each argued
#      there and in docs/deploy.md, section "lintian").
#   2. amd64: a clean Debian 12 root (mmdebstrap, Debian's packages only: the .deb's Depends
#      and the Essential set; cached as a tarball under ~/.cache/mppid, keyed by the Depends,
#      so a re-run needs no network), the package installed into it with dpkg, and there,
#      from the installed files alone and in a private network namespace, the units' programs
#      (LCM route, recorder, mppid, bridge) started from their ExecStart= lines, the mapper
#      from its unit turning a published depth frame of a wall into a local map, and the
#      missions hover (a PX4 on UDP) and circle_3ms (an ArduPilot on UDP) flown against the
#      stand-in autopilot (sim/mavlink_vehicle, copied in as the test's fixture), the link
#      profile installed as the operator would: test/deploy/package_flight.py. Around them: the
#      postinst's byte code present after the install, and after `dpkg --purge` nothing of the
#      package left (its byte code, the enabled units' links).
#   3. arm64: the package unpacked beside the arm64 libraries of this machine (multiarch) and
#      its programs started under qemu-user (Cortex-A76): `mppid --self-test` with the
#      installed /etc/mppid, mppid-mapper with the installed /etc/mppid/mapper.yaml (its window
#      allocated, stopped by SIGTERM), lcm-logger; every ELF file in it an AArch64 one; the
#      same Depends as the amd64 package.
#
#   tools/package-test.sh [--no-build] [--amd64-only] [--ardupilot-bin BIN] [--keep DIR]
#                         [-- package_flight.py arguments]
#
#   --no-build     the packages in build/packages as they are
#   --amd64-only   no arm64 part (with flight arguments: a measurement, docs/first-flight.md's
#                  latency budget: `-- --cpu 1 --flights circle_3ms:px4 --set mppi.rollouts=1024`)
#   --ardupilot-bin BIN  ArduCopter SITL (BIN: <ardupilot checkout>/build/sitl/bin/arducopter, built
#                  outside this tree; never in CI) in place of the stand-in, copied into the root
#                  as a fixture with its checkout's copter.parm (test/deploy/package_sitl.py);
#                  implies --amd64-only; flights by default hover, circle_3ms and circle_3ms with
#                  mppid killed mid-circle (tools/ardupilot/package-flights.sh scores them)
#   --keep DIR     the flights' folder (/tmp/package-flight in the root) copied to DIR
#
# Environment: MPPID_PACKAGE_STAGE=0 skips the stage (tools/test.sh runs it by default);
# MPPID_DEBIAN_MIRROR (http://deb.debian.org/debian); MPPID_PACKAGE_DIR (build/packages).
set -euo pipefail

ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
cd "$ROOT"
log() { printf '[package-test] %s\n' "$*"; }
if [[ "${MPPID_PACKAGE_STAGE:-1}" == 0 ]]; then log "skipped (MPPID_PACKAGE_STAGE=0)"; exit 0; fi
build=1 arm64=1 ardupilot_bin="" keep=""
flight_args=()
while (($#)); do
  case "$1" in
    --no-build) build=0 ;;
    --amd64-only) arm64=0 ;;
    --ardupilot-bin) ardupilot_bin="$(realpath "$2")"; arm64=0; shift ;;
    --keep) keep="$2"; shift ;;
    --) shift; flight_args=("$@"); break ;;
    -h|--help) sed -n '2,38s/^# \{0,1\}//p' "${BASH_SOURCE[0]}"; exit 0 ;;
    *) echo "package-test.sh: unknown argument '$1' (try --help)" >&2; exit 2 ;;
  esac
  shift
done
((EUID == 0)) || { echo "package-test.sh: needs root (a chroot, a network namespace)" >&2; exit 1; }
OUT="${MPPID_PACKAGE_DIR:-build/packages}"
CACHE="${XDG_CACHE_HOME:-$HOME/.cache}/mppid"
WORK="$(mktemp -d /tmp/mppid-package-test.XXXXXX)"
trap 'umount -R "$WORK/root/proc" "$WORK/root/dev" 2>/dev/null || true; rm -rf "$WORK"' EXIT
t0=$(date +%s)

if ((build)); then
  if ((arm64)); then tools/package.sh amd64 arm64; else tools/package.sh amd64; fi
fi
deb_amd64="$(ls -t "$OUT"/mppid_*_amd64.deb | head -1)"
deb_arm64=""
if ((arm64)); then deb_arm64="$(ls -t "$OUT"/mppid_*_arm64.deb | head -1)"; fi
t1=$(date +%s)

# ---- lintian on both packages --------------------------------------------------------------
debs=("$deb_amd64")
[[ -n "$deb_arm64" ]] && debs+=("$deb_arm64")
for deb in "${debs[@]}"; do
  log "lintian $(basename "$deb")"
  # (not --show-overrides: with it, lintian 2.116 fails on the overridden warnings too)
  lintian --fail-on error,warning --display-level '>=warning' "$deb" ||
    { log "FAILED: lintian on $(basename "$deb") (docs/deploy.md, section lintian)"; exit 1; }
done
t_lintian=$(($(date +%s) - t1))
t1=$(date +%s)

# ---- amd64: a clean Debian 12 root --------------------------------------------------------
# The Depends as package names (versions and alternatives are dpkg's to check at install),
# and systemd, the board's own: first-flight.md's `systemctl enable` and `systemd-analyze
# verify` run in the root (no systemd runs there; enabling is links, verifying reads files).
depends="$(dpkg-deb -f "$deb_amd64" Depends | tr ',' '\n' | sed 's/(.*)//; s/|.*//; s/ //g' | sort -u | paste -sd, -)"
include="$depends,systemd"
key="$(printf '%s\n' "$include" | sha256sum | cut -c1-16)"
tarball="$CACHE/debian12-root-$key.tar"
if [[ ! -f "$tarball" ]]; then
  mkdir -p "$CACHE"
  log "mmdebstrap bookworm with $include"
  mmdebstrap --quiet --format=tar --variant=apt --include="$include" bookworm "$tarball.part" \
    "${MPPID_DEBIAN_MIRROR:-http://deb.debian.org/debian}"
  mv "$tarball.part" "$tarball"
else
  log "Debian 12 root from $tarball"
fi
R="$WORK/root"
mkdir -p "$R"
tar -C "$R" -xf "$tarball"
cp "$deb_amd64" "$R/tmp/"
log "dpkg -i $(basename "$deb_amd64") in the clean root"
chroot "$R" dpkg -i "/tmp/$(basename "$deb_amd64")"
# The .deb carries no byte code; its postinst compiles (py3compile, as Debian's Python packages).
[[ -n "$(find "$R/usr/lib/mppid/python/pymavlink" -name '*.pyc' -print -quit)" ]] ||
  { log "FAILED: the postinst did not byte-compile /usr/lib/mppid/python"; exit 1; }
for bin in mppid mppid-mapper; do
  if chroot "$R" ldd "/usr/bin/$bin" | grep 'not found'; then
    log "FAILED: $bin's libraries are not all in the package's Depends"; exit 1
  fi
done
# The test's fixtures: the stand-in autopilot and the driver; nothing else of this tree.
mkdir -p "$R/opt/standin"
cp -r sim/mavlink_vehicle/mavlink_vehicle "$R/opt/standin/"
cp test/deploy/package_flight.py test/deploy/package_sitl.py "$R/opt/"
if [[ -n "$ardupilot_bin" ]]; then
  F="$R/opt/ardupilot"
  mkdir -p "$F"
  cp "$ardupilot_bin" "$F/arducopter"
  cp "$(dirname "$ardupilot_bin")/../../../Tools/autotest/default_params/copter.parm" "$F/"
  cp config/ardupilot/guided_baseline.parm tools/sitl_harness/ap_truth.py "$F/"
  cp config/vehicles/arducopter_sitl.yaml "$F/vehicle.yaml"
  ((${#flight_args[@]})) || flight_args=(--no-doc --flights
    hover:arducopter,circle_3ms:arducopter,circle_3ms:arducopter:kill)
fi
t2=$(date +%s)
log "flights from the installed files (private network namespace)"
status=0
unshare --net --mount --pid --fork --kill-child sh -c "
  mount -t proc proc '$R/proc' && mount --rbind /dev '$R/dev' &&
  exec chroot '$R' /usr/bin/python3 /opt/package_flight.py \"\$@\"" sh "${flight_args[@]}" || status=1
cat "$R/tmp/package-flight/results.json" 2>/dev/null || true
if [[ -n "$keep" ]]; then mkdir -p "$keep" && cp -r "$R/tmp/package-flight/." "$keep/"; fi
if ((status)); then
  for f in "$R"/tmp/package-flight/*.log; do [[ -f "$f" ]] && { echo "--- $f"; tail -n 30 "$f"; }; done
fi
# Purge after the flights: the prerm removes the byte code (else /usr/lib/mppid would stay) and
# the postrm the links of the units the flights enabled (`systemctl enable mppid.target`).
log "dpkg --purge mppid in the root"
chroot "$R" dpkg --purge mppid || { log "FAILED: dpkg --purge mppid"; status=1; }
left="$(cd "$R" && { find etc/systemd/system -name 'mppid*'; [[ ! -e usr/lib/mppid ]] || find usr/lib/mppid | head -3; } | paste -sd' ' -)"
[[ -z "$left" ]] || { log "FAILED: left after dpkg --purge: $left"; status=1; }
t3=$(date +%s)

# ---- arm64: the programs under qemu-user beside this machine's arm64 libraries -------------
if ((!arm64)); then
  log "times: package $((t1 - t0 - t_lintian)) s, lintian $t_lintian s, root and install $((t2 - t1)) s, flights $((t3 - t2)) s (no arm64)"
  exit "$status"
fi
A="$WORK/arm64"
dpkg-deb -x "$deb_arm64" "$A"
[[ "$(dpkg-deb -f "$deb_arm64" Depends)" == "$(dpkg-deb -f "$deb_amd64" Depends)" ]] ||
  { log "FAILED: the arm64 and amd64 packages' Depends differ"; status=1; }
wrong=0
while IFS= read -r -d '' f; do
  if [[ "$(head -c4 "$f")" == $'\x7fELF' ]] && ! readelf -h "$f" | grep -q 'Machine:.*AArch64'; then
    log "FAILED: not an AArch64 file: ${f#"$A"}"; wrong=1
  fi
done < <(find "$A" -type f -print0)
((wrong)) && status=1
qemu=(qemu-aarch64-static -cpu cortex-a76)
log "arm64: mppid --self-test under qemu-user"
"${qemu[@]}" "$A/usr/bin/mppid" --self-test --config "$A/etc/mppid/mppid.yaml" --vehicle "$A/etc/mppid/vehicle.yaml" ||
  { log "FAILED: the arm64 mppid's self-test"; status=1; }
log "arm64: mppid-mapper with the installed settings under qemu-user (2 s, then SIGTERM)"
out="$(timeout --preserve-status -s TERM 2 "${qemu[@]}" "$A/usr/bin/mppid-mapper" --config "$A/etc/mppid/mapper.yaml" \
  --lcm-url memq:// 2>&1)" && rc=0 || rc=$?
[[ $rc == 0 && "$out" == *"cells of 0.25 m -> MPPI_LOCAL_MAP"* && "$out" == *'"frames":0'* ]] ||
  { log "FAILED: the arm64 mppid-mapper (rc $rc): $out"; status=1; }
# (--help exits 1 after its usage: the usage is the proof that it loaded and ran)
usage="$("${qemu[@]}" "$A/usr/lib/mppid/python/bin/lcm-logger" --help 2>&1 || true)"
[[ "$usage" == "usage: lcm-logger"* ]] || { log "FAILED: the arm64 lcm-logger does not start: $usage"; status=1; }
t4=$(date +%s)

log "packages: $(for d in "$deb_amd64" "$deb_arm64"; do printf '%s %s KiB (installed %s KiB); ' \
  "$(basename "$d")" "$(du -k "$d" | cut -f1)" "$(dpkg-deb -f "$d" Installed-Size)"; done)"
log "times: package $((t1 - t0 - t_lintian)) s, lintian $t_lintian s, root and install $((t2 - t1)) s, flights $((t3 - t2)) s, arm64 $((t4 - t3)) s; total $((t4 - t0)) s"
if ((status == 0)); then log "all passed"; else log "FAILED" >&2; fi
exit "$status"
