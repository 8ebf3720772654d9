#!/usr/bin/env bash
# Fills .devdeps/ (git-ignored) with what an offline GPU host lacks to build and fly the whole
# stack: copy it beside the tree on that host and run tools/gpu/run-all.sh there
# (tools/gpu/README.md). Runs on a networked Debian 12 machine (PyPI and Debian's archive).
#
#   tools/gpu/pack-deps.sh [--all] [--out DIR]
#
# Default: what a stock Ubuntu 24.04 CUDA image with the C++ libraries installed (checked on
# an H100 host on 2026-11-23) lacks:
#   wheels/lcm-1.5.*-cp312-*.whl   the lcm wheel (liblcm, lcm-gen, lcm-logger, lcmConfig.cmake)
#   usr/include/Random123/         librandom123-dev
#   lib/libglib-2.0.so.0           libglib2.0-0 (liblcm and the lcm binaries need it)
#   bin/busybox, bin/ip            busybox-static: `ip` brings up lo in the network
#                                  namespaces of the daemon bench and the SITL flights
#   usr/include/hwy, usr/lib/x86_64-linux-gnu/{libhwy*,cmake/hwy}
#                                  libhwy-dev + libhwy1 (Google Highway): the SIMD CPU
#                                  backend, for the CPU figures on the GPU host's cores
# --all adds the C++ libraries that image already has, for an image without them:
#   Eigen, yaml-cpp (+ its shared library), CLI11, spdlog + fmt, Google Benchmark, and
#   the GoogleTest sources (built in the tree through -DMPPID_GTEST_SOURCE).
set -euo pipefail
ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/../.." && pwd)"
DEST="$ROOT/.devdeps"
ALL=0
while (($#)); do
  case "$1" in
    --all) ALL=1 ;;
    --out) DEST="$2"; shift ;;
    -h|--help) sed -n '2,20s/^# \{0,1\}//p' "${BASH_SOURCE[0]}"; exit 0 ;;
    *) echo "pack-deps.sh: unknown argument '$1'" >&2; exit 2 ;;
  esac
  shift
done
log() { printf '[pack-deps] %s\n' "$*"; }
rm -rf "$DEST"
mkdir -p "$DEST/wheels" "$DEST/lib" "$DEST/bin"
TMP="$(mktemp -d)"
trap 'rm -rf "$TMP"' EXIT

# ---- the lcm wheel for the GPU machine's Python (3.12) -------------------------------
PY="$ROOT/.venv/bin/python"
[[ -x "$PY" ]] || PY="$(command -v python3)"
"$PY" -m pip download -q --no-deps --only-binary=:all: --python-version 3.12 --implementation cp \
  --platform manylinux_2_28_x86_64 --platform manylinux_2_27_x86_64 --platform manylinux_2_17_x86_64 \
  --platform manylinux2014_x86_64 -d "$DEST/wheels" 'lcm>=1.5,<1.6'
# setuptools builds the project's Python packages there (run-all.sh installs them editable).
"$PY" -m pip download -q --no-deps --only-binary=:all: -d "$DEST/wheels" 'setuptools>=70.1'
log "wheel: $(cd "$DEST/wheels" && ls)"

# ---- Debian 12 packages, unpacked -------------------------------------------------------
debs=(librandom123-dev libglib2.0-0 busybox-static libhwy-dev libhwy1)
if ((ALL)); then
  debs+=(libeigen3-dev libyaml-cpp-dev libyaml-cpp0.7 libcli11-dev libspdlog-dev libspdlog1.10 libfmt-dev libfmt9
         libbenchmark-dev libbenchmark1debian googletest)
fi
(cd "$TMP" && apt-get download "${debs[@]}" >/dev/null 2>&1) || {
  echo "pack-deps.sh: apt-get download ${debs[*]} failed (run 'apt-get update' first?)" >&2; exit 1; }
mkdir -p "$TMP/root"
for f in "$TMP"/*.deb; do dpkg -x "$f" "$TMP/root"; done
R="$TMP/root"
mkdir -p "$DEST/usr/include"
cp -a "$R/usr/include/Random123" "$DEST/usr/include/"
cp -a "$R"/usr/lib/x86_64-linux-gnu/libglib-2.0.so.0* "$DEST/lib/"
cp -a "$R/bin/busybox" "$DEST/bin/busybox"
ln -sf busybox "$DEST/bin/ip"
mkdir -p "$DEST/usr/lib/x86_64-linux-gnu/cmake"
cp -a "$R/usr/include/hwy" "$DEST/usr/include/"
cp -a "$R"/usr/lib/x86_64-linux-gnu/libhwy*.so* "$DEST/usr/lib/x86_64-linux-gnu/"  # libhwy, _contrib, _test: hwy-config.cmake names all three
cp -a "$R/usr/lib/x86_64-linux-gnu/cmake/hwy" "$DEST/usr/lib/x86_64-linux-gnu/cmake/"
if ((ALL)); then
  for d in eigen3 yaml-cpp CLI spdlog fmt benchmark; do cp -a "$R/usr/include/$d" "$DEST/usr/include/"; done
  mkdir -p "$DEST/usr/lib/x86_64-linux-gnu" "$DEST/usr/share"
  cp -a "$R"/usr/lib/x86_64-linux-gnu/{libyaml-cpp*,libspdlog*,libfmt*,libbenchmark*} "$DEST/usr/lib/x86_64-linux-gnu/"
  cp -a "$R"/usr/lib/x86_64-linux-gnu/cmake "$DEST/usr/lib/x86_64-linux-gnu/"
  cp -a "$R"/usr/share/eigen3 "$DEST/usr/share/"
  [[ -d "$R/usr/share/cmake" ]] && cp -a "$R/usr/share/cmake" "$DEST/usr/share/"
  cp -a "$R/usr/src/googletest" "$DEST/googletest"
fi
du -sh "$DEST" | sed 's/^/[pack-deps] size: /'
log "done: $DEST (copy it beside the tree as .devdeps; see tools/gpu/README.md)"
