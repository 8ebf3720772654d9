#!/usr/bin/env bash
# Sets up a Debian 12 machine for mppid and builds it. Idempotent: a re-run on a set-up
# machine touches neither apt nor pip (no network) and only rebuilds what changed.
#
#   tools/setup.sh [--no-apt] [--no-venv] [--no-build] [--flight] [--progress] [--aarch64]
#                  [-- <extra cmake configure args>]
#
#   --no-apt     skip the Debian packages (e.g. no root and no sudo; you installed them)
#   --no-venv    skip the Python venv (.venv) and requirements.txt
#   --no-build   skip configuring and building (build/)
#   --flight     only what a SITL flight needs (tools/fly.sh): the venv's flight packages
#                (requirements-flight.txt), the project's flight packages (the LCM types,
#                the bridge, the mission tool, the harness) and the targets mppid, mppid-sim,
#                mppid-mapper and mppid-sensors (sensed flights) and the LCM types; a later run
#                without it adds the rest
#   --view       with --flight: also the live view (requirements-view.txt, tools/mppid_view)
#   --progress   one progress line instead of the compiler's output (kept in build/build.log;
#                its end is shown if the build fails)
#   --aarch64    also what the aarch64 cross build needs (tools/aarch64.sh, docs/aarch64.md):
#                the arm64 architecture in dpkg, the cross compiler, qemu-user and the arm64
#                libraries; the lcm wheel for aarch64 in .venv/aarch64
#
# Environment:
#   CI            when set (CI=true), warnings are errors (-DMPPID_WERROR=ON)
#   MPPID_CUDA    passed to CMake as -DMPPID_CUDA (ON, OFF, AUTO; default: the CMake default)
#   MPPID_FUZZ_REPLAY  passed to CMake as -DMPPID_FUZZ_REPLAY (ON, OFF; tools/test.sh sets it)
#   MPPID_BUILD_DIR  build folder (default: build)
#   MPPID_JOBS    parallel build jobs (default: 2, the size of the project's machines)
set -euo pipefail

ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
cd "$ROOT"

do_apt=1 do_venv=1 do_build=1 flight=0 view=0 progress=0 do_aarch64=0
cmake_extra=()
while (($#)); do
  case "$1" in
    --no-apt) do_apt=0 ;;
    --no-venv) do_venv=0 ;;
    --no-build) do_build=0 ;;
    --flight) flight=1 ;;
    --view) view=1 ;;
    --progress) progress=1 ;;
    --aarch64) do_aarch64=1 ;;
    --) shift; cmake_extra=("$@"); break ;;
    -h|--help) sed -n '2,27s/^# \{0,1\}//p' "${BASH_SOURCE[0]}"; exit 0 ;;
    *) echo "setup.sh: unknown argument '$1' (try --help)" >&2; exit 2 ;;
  esac
  shift
done

log() { printf '[setup %3d s] %s\n' "$SECONDS" "$*"; }  # seconds since setup began

# ---- Debian packages ------------------------------------------------------------------
# Everything the build, the tests and the tools need, nothing recommended on top.
APT_PACKAGES=(
  # toolchain and build
  build-essential cmake ninja-build pkg-config git ca-certificates
  ccache  # a second build of the same sources (a later CI run, the sanitizer builds) is a cache hit
  # C++ libraries (OpenMP comes with gcc as libgomp)
  libeigen3-dev librandom123-dev libyaml-cpp-dev libcli11-dev libspdlog-dev
  libhwy-dev  # Google Highway: the CPU backend's SIMD targets and vector math
  libsystemd-dev libglib2.0-dev
  # tests and benchmarks
  googletest libgtest-dev libgmock-dev libbenchmark-dev
  # mppid-mapper-bench's comparison (docs/sensing.md): OctoMap and DynamicEDT3D on the same
  # frames as mppid-mapper's grid (the mapper itself does not use them)
  liboctomap-dev libdynamicedt3d-dev
  # Python venv (lcm wheel, tools, pytest)
  python3 python3-venv python3-pip
  # Java: javac builds the LCM type jar; the non-headless JRE has the AWT/X11 part that
  # lcm-spy's Swing window needs, even under Xvfb
  openjdk-17-jdk-headless openjdk-17-jre-headless openjdk-17-jre
  # lcm-spy without a display (ps: tools/lcm-spy); network namespaces for multicast tests
  xvfb xauth iproute2 util-linux procps
  # daemon tests: capsh makes the OS refuse real-time, systemd-analyze verifies the unit
  libcap2-bin systemd
  # pyrealsense2's wheel (mppid-realsense and its test, docs/sensing.md) links libusb
  libusb-1.0-0
  # cyclictest: how late this machine wakes a SCHED_FIFO thread (drivers/daemon/README.md)
  rt-tests
  # tools/stress-tests.sh: the timed tests again and again beside busy CPU workers
  stress-ng
  # the package stage (tools/package-test.sh): a clean Debian 12 root to install the .deb into
  mmdebstrap
  # the package's manual pages (help2man from --help) and Debian's check of the .debs (lintian)
  help2man lintian
  # the live 3D view's test (tools/view, docs/view.md): a real headless browser loads rerun's
  # web viewer (WebGL through SwiftShader, no GPU) and takes a screenshot
  chromium
  # sanitizer and fuzz builds (tools/sanitize.sh, tools/fuzz): clang 14 with its sanitizer and
  # libFuzzer runtimes, its OpenMP (and Archer, which lets TSan see OpenMP), llvm-symbolizer
  clang-14 libclang-rt-14-dev libomp-14-dev llvm-14
)
# The aarch64 cross build (--aarch64): Debian's cross compiler, qemu-user to run its tests, and
# the arm64 libraries beside the amd64 ones (multiarch; each the same version as its amd64
# twin, so apt may upgrade that one). Header-only libraries (Eigen, Random123, CLI11) and
# yaml-cpp's headers are the amd64 packages'; yaml-cpp and glib are linked as their arm64
# runtime libraries (cmake/toolchains/aarch64-linux-gnu.cmake says why).
APT_PACKAGES_AARCH64=(
  g++-aarch64-linux-gnu qemu-user-static
  libgomp1:arm64 libhwy-dev:arm64 libspdlog-dev:arm64 libgtest-dev:arm64 libgmock-dev:arm64
  libyaml-cpp0.7:arm64 libglib2.0-0:arm64
  libsystemd-dev:arm64  # the arm64 mppid's sd_notify: its unit is Type=notify (tools/package.sh)
)

missing_packages() {
  local pkg status
  for pkg in "$@"; do
    status="$(dpkg-query -W -f='${db:Status-Abbrev}' "$pkg" 2>/dev/null || true)"
    [[ "$status" == ii* ]] || printf '%s\n' "$pkg"
  done
}

if ((do_apt)); then
  wanted=("${APT_PACKAGES[@]}")
  ((do_aarch64)) && wanted+=("${APT_PACKAGES_AARCH64[@]}")
  mapfile -t missing < <(missing_packages "${wanted[@]}")
  if ((${#missing[@]} == 0)); then
    log "Debian packages: all ${#wanted[@]} installed"
  else
    log "Debian packages missing: ${missing[*]}"
    SUDO=()
    if ((EUID != 0)); then
      command -v sudo >/dev/null || { echo "setup.sh: not root and no sudo; install: ${missing[*]}" >&2; exit 1; }
      SUDO=(sudo)
    fi
    export DEBIAN_FRONTEND=noninteractive
    # arm64 packages need the architecture in dpkg before the index update below lists them.
    if ((do_aarch64)) && ! dpkg --print-foreign-architectures | grep -qx arm64; then
      log "dpkg --add-architecture arm64"
      "${SUDO[@]}" dpkg --add-architecture arm64
    fi
    # One index update per run, and only because something has to be installed.
    "${SUDO[@]}" apt-get update -q
    "${SUDO[@]}" apt-get install -y -q --no-install-recommends "${missing[@]}"
  fi
fi

# ---- Python venv ----------------------------------------------------------------------
# uv (PyPI `uv`, pinned) makes the venv and installs into it: its cache (~/.cache/uv) keeps
# every wheel unpacked, and a venv is hard links into it. uv itself is pip-installed once into
# ~/.cache/mppid/uv-VERSION, a venv of its own; a cold cache downloads from PyPI as pip did.
# The full set (requirements.txt) is installed once per requirements into a byte-compiled
# venv, ~/.cache/mppid/venv-KEY (KEY: the requirements files, the interpreter
# and uv's version), and a clone's .venv is a hard-linked copy of it (cp -al: seconds where
# pip took minutes; a CI run starts from a fresh clone); the project's packages are then
# installed into .venv alone, editable, pointing at the clone's sources.
PY_BASE=/usr/bin/python3
[[ -x "$PY_BASE" ]] || PY_BASE="$(command -v python3)"
VENV="$ROOT/.venv"
UV_VERSION=0.13.9
MPPID_CACHE="${XDG_CACHE_HOME:-$HOME/.cache}/mppid"
UV_HOME="$MPPID_CACHE/uv-$UV_VERSION"
UV="$UV_HOME/bin/uv"
# uv checks certificates against the system's store, as pip does here (Debian's ca-certificates).
export UV_NATIVE_TLS=1
STAMP="$VENV/.mppid-requirements.sha256"
FLIGHT_STAMP="$VENV/.mppid-flight-requirements.sha256"
VIEW_STAMP="$VENV/.mppid-view-requirements.sha256"
# requirements.txt includes both of these; its stamp covers all three.
ALL_REQUIREMENTS=(requirements-flight.txt requirements-view.txt requirements.txt requirements-nodeps.txt)

# The stamp of a requirements file: it and the interpreter, so a Python upgrade reinstalls.
requirements_hash() {
  { cat "$@"; "$PY_BASE" -c 'import sys; print(sys.version)'; } | sha256sum | cut -d' ' -f1
}
# uv pip install -r FILE into VENV_DIR unless STAMP says it is installed (FILE and what it
# includes). Byte-compiled as pip does (uv's cache holds no .pyc; without them each Python
# process compiles what it imports again where PYTHONDONTWRITEBYTECODE is set).
pip_install() {
  local venv="$1" file="$2" stamp="$3" want
  if [[ "$file" == requirements.txt ]]; then want="$(requirements_hash "${ALL_REQUIREMENTS[@]}")"
  else want="$(requirements_hash "$file")"; fi
  if [[ "$want" == "$(cat "$stamp" 2>/dev/null || true)" ]]; then
    log "venv: $file unchanged"
    return
  fi
  local uv_pip=("$UV" pip install -q --python "$venv/bin/python" --compile-bytecode)
  log "uv pip install -r $file"
  "${uv_pip[@]}" -r "$file"
  if [[ "$file" == requirements.txt ]]; then
    log "uv pip install --no-deps -r requirements-nodeps.txt"
    "${uv_pip[@]}" --no-deps -r requirements-nodeps.txt
  fi
  printf '%s\n' "$want" >"$stamp"
}
# A new venv at $1 (uv venv --seed: pip in it too, which the package stage and
# test/mavlink/test_install.py use).
new_venv() {
  "$UV" venv -q --seed --python "$PY_BASE" "$1"
}
# In the copy at $2 of the venv made at $1: each file of bin/ that names $1 (the scripts'
# #! lines, the activate scripts) written anew naming $2, so they run the copy's python (and
# a script needs nothing from PATH, as pip's do). A new file, not the hard link's: the cached
# venv keeps its own.
retarget_venv() {
  "$PY_BASE" - "$1" "$2" <<'PY'
import os, sys
old, new = (p.encode() for p in sys.argv[1:3])
bindir = os.path.join(sys.argv[2], "bin")
for name in os.listdir(bindir):
    path = os.path.join(bindir, name)
    if os.path.islink(path) or not os.path.isfile(path):
        continue
    with open(path, "rb") as f:
        data = f.read()
    if old in data:
        tmp = path + ".retarget"
        with open(tmp, "wb") as f:
            f.write(data.replace(old, new))
        os.chmod(tmp, os.stat(path).st_mode & 0o7777)
        os.replace(tmp, path)
PY
}
# .venv as a hard-linked copy of the full set's venv in the cache, made first if missing
# (in a temporary folder renamed into place: two set-ups at once each get a whole one). The
# newest three such venvs stay; a venv copied from an older one keeps its files (hard links).
cached_venv() {
  echo "$MPPID_CACHE/venv-$({ requirements_hash "${ALL_REQUIREMENTS[@]}"; echo "uv $UV_VERSION, retargeted"; } | sha256sum | cut -c1-16)"
}
venv_from_cache() {
  local tmpl tmp key
  tmpl="$(cached_venv)"
  key="${tmpl##*/venv-}"
  if [[ ! -f "$tmpl/.mppid-requirements.sha256" ]]; then
    log "making the cached venv $tmpl"
    mkdir -p "$MPPID_CACHE"
    find "$MPPID_CACHE" -maxdepth 1 -name 'venv-*.tmp.*' -mmin +60 -exec rm -rf {} +  # a failed one
    tmp="$(mktemp -d "$MPPID_CACHE/venv-$key.tmp.XXXXXX")"
    new_venv "$tmp"
    printf '%s\n' "$tmp" >"$tmp/.mppid-made-at"  # the path its scripts name (retarget_venv)
    pip_install "$tmp" requirements.txt "$tmp/.mppid-requirements.sha256"
    mv -T "$tmp" "$tmpl" 2>/dev/null || rm -rf "$tmp"  # another set-up made it meanwhile
    find "$MPPID_CACHE" -maxdepth 1 -name 'venv-*' ! -name '*.tmp.*' -printf '%T@ %p\n' |
      sort -rn | tail -n +4 | cut -d' ' -f2- | xargs -r -d '\n' rm -rf
  fi
  log "$VENV: hard-linked copy of $tmpl"
  rm -rf "$VENV"
  # Hard links where the cache and the clone share a file system, a copy elsewhere.
  cp -al "$tmpl" "$VENV" 2>/dev/null || { rm -rf "$VENV"; cp -a "$tmpl" "$VENV"; }
  retarget_venv "$(cat "$tmpl/.mppid-made-at")" "$VENV"
  # The stamp as a file of its own: nothing written into .venv reaches the cached venv.
  cp --remove-destination "$tmpl/.mppid-requirements.sha256" "$STAMP"
}

# uv, pinned, in a venv of its own under ~/.cache/mppid (once per machine and version).
ensure_uv() {
  [[ "$("$UV" --version 2>/dev/null || true)" == "uv $UV_VERSION"* ]] && return
  log "pip install uv==$UV_VERSION into $UV_HOME"
  rm -rf "$UV_HOME"
  "$PY_BASE" -m venv "$UV_HOME"
  "$UV_HOME/bin/python" -m pip install --disable-pip-version-check -q "uv==$UV_VERSION"
}

if ((do_venv)); then
  ensure_uv
  venv_ok=1
  if [[ ! -x "$VENV/bin/python" ]] || ! "$VENV/bin/python" -c 'import sys' 2>/dev/null; then venv_ok=0; fi
  # A flight needs a few packages (requirements-flight.txt, ~30 s), a viewed one rerun too
  # (requirements-view.txt), installed into a venv of its own unless the cached full set is
  # there; the tests the rest (requirements.txt includes both): .venv from the cached full
  # set. The full set installed covers the flight's.
  if [[ "$(requirements_hash "${ALL_REQUIREMENTS[@]}")" == "$(cat "$STAMP" 2>/dev/null || true)" ]] && ((venv_ok)); then
    log "venv: requirements unchanged"
  elif ((flight)) && [[ ! -f "$(cached_venv)/.mppid-requirements.sha256" ]]; then
    if ((!venv_ok)); then
      log "creating $VENV with $PY_BASE"
      rm -rf "$VENV"
      new_venv "$VENV"
    fi
    pip_install "$VENV" requirements-flight.txt "$FLIGHT_STAMP"
    ((view)) && pip_install "$VENV" requirements-view.txt "$VIEW_STAMP"
  else
    venv_from_cache
  fi
  # The aarch64 cross build links the lcm wheel for aarch64 (PyPI has it), of the same version
  # as the venv's, unpacked into .venv/aarch64 (its lcm-gen is not run: the venv's generates).
  if ((do_aarch64)); then
    lcm_version="$("$VENV/bin/python" -c 'import importlib.metadata as m; print(m.version("lcm"))')"
    have_aarch64="$(cat "$VENV/aarch64/.lcm-version" 2>/dev/null || true)"
    if [[ "$have_aarch64" != "$lcm_version" ]]; then
      log "lcm $lcm_version for aarch64 into $VENV/aarch64"
      rm -rf "$VENV/aarch64"
      py_version="$("$VENV/bin/python" -c 'import sys; print(f"{sys.version_info[0]}.{sys.version_info[1]}")')"
      "$UV" pip install -q --python "$VENV/bin/python" --no-deps --only-binary :all: \
        --python-platform aarch64-manylinux_2_28 --python-version "$py_version" \
        --target "$VENV/aarch64" "lcm==$lcm_version"
      printf '%s\n' "$lcm_version" >"$VENV/aarch64/.lcm-version"
    else
      log "lcm for aarch64: $lcm_version present"
    fi
  fi
fi

# ---- the project's Python packages ----------------------------------------------------
# Every folder with a pyproject.toml (docs/setup.md), installed editable into .venv: the
# commands (mppid-mavlink-bridge, mppid-mission, mppid-sitl, ...) land in .venv/bin and the
# sources stay where they are. No build isolation and no dependencies: setuptools, lcm (its
# lcm-gen makes the LCM types) and every package's dependencies come from the requirements
# above, so nothing is downloaded. Re-installed when a pyproject.toml or the LCM types'
# sources change (lcmtypes/setup.py, lcmtypes/*/*.lcm).
PY_PACKAGES_FLIGHT=(lcmtypes drivers/mavlink drivers/mission tools/sitl_harness)
PY_PACKAGES_VIEW=(tools/mppid_view)
PY_PACKAGES=("${PY_PACKAGES_FLIGHT[@]}" "${PY_PACKAGES_VIEW[@]}" sim/mavlink_vehicle tools/sysid_fit drivers/realsense)
PACKAGES_STAMP="$VENV/.mppid-packages.sha256"
FLIGHT_PACKAGES_STAMP="$VENV/.mppid-flight-packages.sha256"

packages_hash() {
  local d
  { printf '%s\n' "$@"
    for d in "$@"; do cat "$d/pyproject.toml"; done
    cat lcmtypes/setup.py lcmtypes/*/*.lcm
    "$VENV/bin/python" -c 'import sys; print(sys.version)'
  } | sha256sum | cut -d' ' -f1
}
# uv pip install -e each folder unless STAMP says these are installed as they are.
install_packages() {
  local stamp="$1" want d args=()
  shift
  want="$(packages_hash "$@")"
  if [[ "$want" == "$(cat "$stamp" 2>/dev/null || true)" ]]; then
    log "venv: packages unchanged ($*)"
    return
  fi
  for d in "$@"; do args+=(-e "./$d"); done
  log "uv pip install -e $*"
  "$UV" pip install -q --python "$VENV/bin/python" --no-deps --no-build-isolation "${args[@]}"
  printf '%s\n' "$want" >"$stamp"
}

if ((do_venv)); then
  if ((flight)) && [[ "$(packages_hash "${PY_PACKAGES[@]}")" != "$(cat "$PACKAGES_STAMP" 2>/dev/null || true)" ]]; then
    flight_packages=("${PY_PACKAGES_FLIGHT[@]}")
    ((view)) && flight_packages+=("${PY_PACKAGES_VIEW[@]}")
    install_packages "$FLIGHT_PACKAGES_STAMP" "${flight_packages[@]}"
  elif ((!flight)); then
    install_packages "$PACKAGES_STAMP" "${PY_PACKAGES[@]}"
  else
    log "venv: packages unchanged"
  fi
fi

# An NVIDIA GPU this machine could fly the CUDA backend on.
gpu_present() {
  [[ -e /dev/nvidia0 ]] || nvidia-smi -L >/dev/null 2>&1
}

# cmake --build "$@", its output in $BUILD_DIR/build.log and one line of progress on stderr
# (ninja's [done/total]); on failure the log's end.
build_with_progress() {
  local logf="$BUILD_DIR/build.log" line last=-1 pct rc
  local tty=0
  [[ -t 2 ]] && tty=1
  set +o pipefail
  cmake --build "$@" 2>&1 | tee "$logf" | while IFS= read -r line; do
    if [[ "$line" =~ ^\[([0-9]+)/([0-9]+)\]\ (Building|Linking|Generating) ]]; then
      pct=$((100 * BASH_REMATCH[1] / BASH_REMATCH[2]))
      if ((tty)); then
        printf '\r[setup] building: %s/%s (%d %%)' "${BASH_REMATCH[1]}" "${BASH_REMATCH[2]}" "$pct" >&2
      elif ((pct / 25 != last)); then  # a log, not a terminal: a line at each quarter
        last=$((pct / 25))
        printf '[setup] building: %s/%s (%d %%)\n' "${BASH_REMATCH[1]}" "${BASH_REMATCH[2]}" "$pct" >&2
      fi
    fi
  done
  rc=${PIPESTATUS[0]}
  set -o pipefail
  ((tty)) && printf '\n' >&2
  if ((rc != 0)); then
    echo "[setup] build failed; the end of $logf:" >&2
    tail -n 40 "$logf" >&2
  fi
  return "$rc"
}

# ---- configure and build --------------------------------------------------------------
if ((do_build)); then
  BUILD_DIR="${MPPID_BUILD_DIR:-build}"
  args=(-S . -B "$BUILD_DIR" -DCMAKE_BUILD_TYPE=Release)
  # A build folder keeps its generator; choose Ninja only for a new one.
  [[ -f "$BUILD_DIR/CMakeCache.txt" ]] || args+=(-G Ninja)
  if [[ -n "${CI:-}" ]]; then args+=(-DMPPID_WERROR=ON); else args+=(-DMPPID_WERROR=OFF); fi
  # The venv now holds the lcm wheel: turn LCM on even in a folder first configured without
  # it (override with: -- -DMPPID_LCM=OFF).
  if [[ -x "$VENV/bin/python" ]]; then args+=(-DMPPID_LCM=ON); fi
  [[ -n "${MPPID_CUDA:-}" ]] && args+=("-DMPPID_CUDA=$MPPID_CUDA")
  # The first flight flies the CPU backend. On a machine with no GPU, a new build folder made
  # for it (--flight) leaves the CUDA backend to the rest (its kernels are half the flight's
  # compile time where nvcc is installed); the next set-up without --flight turns it back to
  # the default and builds it.
  no_cuda_mark="$BUILD_DIR/.mppid-flight-without-cuda"
  if [[ -z "${MPPID_CUDA:-}" ]]; then
    if ((flight)) && [[ ! -f "$BUILD_DIR/CMakeCache.txt" ]] && ! gpu_present; then
      args+=(-DMPPID_CUDA=OFF)
      mkdir -p "$BUILD_DIR" && touch "$no_cuda_mark"
    elif ((!flight)) && [[ -f "$no_cuda_mark" ]]; then
      args+=(-DMPPID_CUDA=AUTO)
      rm -f "$no_cuda_mark"
    fi
  fi
  [[ -n "${MPPID_FUZZ_REPLAY:-}" ]] && args+=("-DMPPID_FUZZ_REPLAY=$MPPID_FUZZ_REPLAY")
  if command -v ccache >/dev/null; then
    args+=(-DCMAKE_CXX_COMPILER_LAUNCHER=ccache -DCMAKE_CUDA_COMPILER_LAUNCHER=ccache)
    # Paths under the checkout hash as relative ones: another clone of the same tree hits.
    export CCACHE_BASEDIR="$ROOT" CCACHE_NOHASHDIR=true
  fi
  log "cmake ${args[*]} ${cmake_extra[*]}"
  if ((progress)); then
    mkdir -p "$BUILD_DIR"
    cmake "${args[@]}" "${cmake_extra[@]}" >"$BUILD_DIR/configure.log" 2>&1 ||
      { echo "[setup] configure failed; the end of $BUILD_DIR/configure.log:" >&2; tail -n 40 "$BUILD_DIR/configure.log" >&2; exit 1; }
  else
    cmake "${args[@]}" "${cmake_extra[@]}"
  fi
  build_args=("$BUILD_DIR" -j"${MPPID_JOBS:-2}")
  # The flight's targets: the daemon, the simulator and the LCM types the harness reads.
  ((flight)) && build_args+=(--target mppid mppid-sim mppid-mapper mppid-sensors mppi_lcm_python)
  log "cmake --build ${build_args[*]}"
  if ((progress)); then
    build_with_progress "${build_args[@]}"
  else
    cmake --build "${build_args[@]}"
  fi
  # Whether this was a warm build (the cache's totals, all builds since it was last zeroed).
  if command -v ccache >/dev/null; then log "ccache: $(ccache -s | grep -E '^ *(Hits|Misses):' | tr -s ' ' | paste -sd ',')"; fi
fi
log "done"
