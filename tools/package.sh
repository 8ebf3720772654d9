#!/usr/bin/env bash
# Builds the Debian packages of what a companion computer runs (cmake/Install.cmake,
# cmake/Packaging.cmake; docs/deploy.md): mppid_<version>_amd64.deb from build/ and
# mppid_<version>_arm64.deb from the aarch64 cross build, build-aarch64/ (preset `aarch64`,
# configured here when missing; tools/setup.sh --aarch64 installs what it needs). Only the
# installed targets are built, and the programs' manual pages (help2man, the target mppid-man);
# the PyPI wheels the package carries are downloaded once into ~/.cache/mppid/wheels
# (MPPID_WHEEL_CACHE). tools/package-test.sh runs lintian on what this makes.
#
#   tools/package.sh [amd64] [arm64]      (both when none is named)
#
# Environment: MPPID_PACKAGE_DIR output folder (build/packages), MPPID_BUILD_DIR (build),
# MPPID_JOBS (2), CI=true makes warnings errors in a new cross build.
set -euo pipefail

ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
cd "$ROOT"
OUT="${MPPID_PACKAGE_DIR:-build/packages}"
jobs="${MPPID_JOBS:-2}"
TARGETS=(mppid mppid-mapper mppi_lcm_python mppid-man)
umask 022  # the package's directories and files 0755/0644 whatever the caller's umask
log() { printf "[package] %s\n" "$*" >&2; }

arches=("$@")
((${#arches[@]})) || arches=(amd64 arm64)
for a in "${arches[@]}"; do
  case "$a" in
    amd64|arm64) ;;
    -h|--help) sed -n '2,15s/^# \{0,1\}//p' "${BASH_SOURCE[0]}"; exit 0 ;;
    *) echo "package.sh: unknown architecture '$a' (amd64, arm64)" >&2; exit 2 ;;
  esac
done
command -v help2man >/dev/null || { echo "package.sh: help2man is missing (tools/setup.sh installs it)" >&2; exit 1; }
if command -v ccache >/dev/null; then
  export CCACHE_BASEDIR="$ROOT" CCACHE_NOHASHDIR=true  # another clone of the same tree hits
fi

# The package of one build folder into $OUT; prints its path.
package() {
  local dir="$1" deb
  log "cmake --build $dir --target ${TARGETS[*]}"
  cmake --build "$dir" -j"$jobs" --target "${TARGETS[@]}" >&2
  mkdir -p "$OUT"
  (cd "$dir" && cpack -G DEB -B "$ROOT/$OUT/.cpack-$(basename "$dir")" >&2)
  deb="$(find "$OUT/.cpack-$(basename "$dir")" -maxdepth 1 -name 'mppid_*.deb' -newer "$dir/CPackConfig.cmake" | head -1)"
  [[ -n "$deb" ]] || { echo "package.sh: cpack made no .deb in $dir" >&2; exit 1; }
  mv -f "$deb" "$OUT/"
  echo "$OUT/$(basename "$deb")"
}

for a in "${arches[@]}"; do
  t0=$(date +%s)
  if [[ "$a" == amd64 ]]; then
    dir="${MPPID_BUILD_DIR:-build}"
    [[ -f "$dir/CMakeCache.txt" ]] || { echo "package.sh: $dir is not configured (tools/setup.sh)" >&2; exit 1; }
    cmake "$dir" >/dev/null  # picks up install rules added since the folder was configured
  else
    dir=build-aarch64
    args=(--preset aarch64)
    command -v ccache >/dev/null && args+=(-DCMAKE_CXX_COMPILER_LAUNCHER=ccache)
    [[ -n "${CI:-}" ]] && args+=(-DMPPID_WERROR=ON)
    log "configure $dir (preset aarch64)"
    cmake "${args[@]}" >/dev/null
  fi
  deb="$(package "$dir")"
  log "$deb: $(du -k "$deb" | cut -f1) KiB, installed $(dpkg-deb -f "$deb" Installed-Size) KiB ($(($(date +%s) - t0)) s)"
done
