#!/usr/bin/env bash
# Guest instructions per sample-step of one full MPPI iteration, per SIMD target, counted the
# same way on both ISAs: mppid-bench runs under qemu-user (x86-64: build/, `-cpu max`, which has
# AVX2 but not AVX-512; aarch64: build-aarch64/, `-cpu cortex-a76`) with qemu's
# `-d in_asm,exec,nochain` log, each executed translation block charged its instruction count.
# Two runs per target, K1 and K2 rollouts (one thread, T = 100, 2 iterations, no warm-up):
# their difference over (K2 - K1) * T * 2 is what one more sample-step costs (noise, rollout,
# costs, weights and update), the start-up and per-iteration fixed costs cancelling.
# Emulation gives no time; docs/aarch64.md says how the counts size cpu_targets.neon.
#
#   bench/instruction_counts.sh [--task NAME] [--k1 N] [--k2 N] [TARGET ...]
#
#   TARGET   x86:off, x86:sse4, x86:avx2, arm:off, arm:neon (default: all five)
# Prints one JSON object per target. Needs build/bin/mppid-bench and
# build-aarch64/bin/mppid-bench (cmake --build build-aarch64 --target mppid-bench).
set -euo pipefail
ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
task=quadrotor_forest k1=256 k2=1280 horizon=100 iterations=2
targets=()
while (($#)); do
  case "$1" in
    --task) task="$2"; shift ;;
    --k1) k1="$2"; shift ;;
    --k2) k2="$2"; shift ;;
    -h|--help) sed -n '2,17s/^# \{0,1\}//p' "${BASH_SOURCE[0]}"; exit 0 ;;
    *) targets+=("$1") ;;
  esac
  shift
done
((${#targets[@]})) || targets=(x86:off x86:sse4 x86:avx2 arm:off arm:neon)

# Each translated block's instructions (its IN: listing), charged once per "Trace" line that
# names its host code (with nochain, one line per execution).
read -r -d '' COUNT <<'AWK' || true
/^IN:/ { pending = 0; listing = 1; next }
listing && /^0x[0-9a-f]+:/ { pending++; next }
/^Trace / {
  listing = 0
  if (pending > 0) { size[$3] = pending; pending = 0 }
  if (!($3 in size)) { unknown++ }
  total += size[$3]
}
END { if (unknown) { print "instruction_counts.sh: " unknown " blocks without a listing" > "/dev/stderr"; exit 1 } print total }
AWK

count() {  # isa simd rollouts
  local emulator bin
  if [[ "$1" == x86 ]]; then emulator=(qemu-x86_64-static -cpu max); bin="$ROOT/build/bin/mppid-bench"
  else emulator=(qemu-aarch64-static -cpu cortex-a76); bin="$ROOT/build-aarch64/bin/mppid-bench"; fi
  "${emulator[@]}" -d in_asm,exec,nochain -D /dev/fd/3 "$bin" --model "$task" --backend cpu --rollouts "$3" \
    --horizon "$horizon" --threads 1 --obstacles 32 --simd "$2" --iterations "$iterations" --warmup 0 \
    3>&1 1>/dev/null | awk "$COUNT"
}

for t in "${targets[@]}"; do
  isa="${t%%:*}" simd="${t#*:}"
  a=$(count "$isa" "$simd" "$k1")
  b=$(count "$isa" "$simd" "$k2")
  per=$(awk -v a="$a" -v b="$b" -v d="$(( (k2 - k1) * horizon * iterations ))" 'BEGIN { printf "%.1f", (b - a) / d }')
  printf '{"task":"%s","isa":"%s","simd":"%s","k1":%d,"k2":%d,"horizon":%d,"iterations":%d,"instructions_k1":%d,"instructions_k2":%d,"instructions_per_sample_step":%s}\n' \
    "$task" "$isa" "$simd" "$k1" "$k2" "$horizon" "$iterations" "$a" "$b" "$per"
done
