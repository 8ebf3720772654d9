#!/bin/bash
# Build the CUDA backend's tests, timing tool and the public bench on the GPU machine, where
# the deps come from the carried, git-ignored .devdeps/ (Random123, Eigen, GoogleTest sources,
# yaml-cpp headers + shared library + CMake config, CLI11 headers + CMake config; copied
# from this Debian 12 machine). Logs go to $OUT. No Highway there: the CPU backend is built
# without its SIMD kernels (MPPID_SIMD=OFF); the parity tests compare with the scalar code.
#   test/gpu/device_run.sh [build-dir] [extra cmake args...]
set -u
B=${1:-build-dev}
shift || true
D=$PWD/.devdeps
OUT=${OUT:-/tmp/out}
mkdir -p "$OUT"
cmake -S . -B "$B" -G Ninja -DMPPID_LCM=OFF -DMPPID_BENCH=ON -DMPPID_CUDA=ON -DMPPID_WERROR=ON -DMPPID_SIMD=OFF \
  -DCMAKE_CUDA_ARCHITECTURES=90 -DCMAKE_PREFIX_PATH="$D" -DRANDOM123_INCLUDE_DIR="$D/include" \
  -DMPPID_GTEST_SOURCE="$D/googletest" "$@" > "$OUT/configure-$B.log" 2>&1 || { tail -40 "$OUT/configure-$B.log"; exit 1; }
ninja -C "$B" -j16 cuda_backend_tests mppid-gpu-timing mppid-bench > "$OUT/build-$B.log" 2>&1 || { grep -v '^\[' "$OUT/build-$B.log" | head -60; exit 1; }
echo "built $B"
