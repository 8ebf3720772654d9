# Sourced by the GPU host's scripts (tools/gpu/*.sh, test/gpu/*.sh): ROOT (the tree), D (the
# dependencies tools/gpu/pack-deps.sh packed: $MPPID_DEVDEPS, default .devdeps beside the
# tree's sources) on PATH and LD_LIBRARY_PATH, and other_arg for their option loops.
ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/../.." && pwd)"
D="${MPPID_DEVDEPS:-$ROOT/.devdeps}"
export PATH="$D/bin:$PATH"
export LD_LIBRARY_PATH="$D/lib:$D/usr/lib/x86_64-linux-gnu${LD_LIBRARY_PATH:+:$LD_LIBRARY_PATH}"

# other_arg SCRIPT ARG: an argument no option took. -h/--help prints SCRIPT's header comment
# and exits 0; anything else is an error (exit 2).
other_arg() {
  case "$2" in
    -h|--help) sed -n '2,/^[^#]/s/^# \{0,1\}//p' "$1"; exit 0 ;;
    *) echo "$(basename "$1"): unknown argument '$2' (try --help)" >&2; exit 2 ;;
  esac
}
