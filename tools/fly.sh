#!/usr/bin/env bash
# The main job. Installs what is missing and builds what a flight needs (tools/setup.sh
# --flight: the daemon, the simulator, the LCM types; a progress line, the compiler's output
# in build/build.log), then flies the 16-state quadrotor through a seeded 4 m forest in
# SITL: the simulator (mppid-sim) and the daemon (mppid, SCHED_FIFO as in service) talk LCM
# over loopback multicast inside a private network namespace, in real time, on the CPU
# backend. Prints the score and where the log and plots are. The rest (tests, benchmarks,
# tools) is built by tools/setup.sh or tools/test.sh, or first with --build-all.
#
#   tools/fly.sh [--lockstep] [--view] [--build-all] [tools/sitl run arguments]
#       e.g. tools/fly.sh --seed 7      tools/fly.sh --backend cuda
#            tools/fly.sh --lockstep    (lock-step, the controller's measured latency charged)
#            tools/fly.sh --scenario rate_track_circle
#            tools/fly.sh --view        (the live 3D view with the rollout fan: open the URL it
#                                        prints; the flight starts 30 s later and the view keeps
#                                        serving 10 min after it, Ctrl-C ends it; docs/view.md)
#
# Environment: MPPID_SETUP_ARGS passes arguments to setup.sh (e.g. "--no-apt").
set -euo pipefail

ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
cd "$ROOT"

setup=(--flight)
for a in "$@"; do [[ "$a" == "--view" ]] && setup+=(--view); done
for a in "$@"; do [[ "$a" == "--build-all" ]] && setup=(); done
# shellcheck disable=SC2086  # a list of words on purpose
bash tools/setup.sh "${setup[@]}" --progress ${MPPID_SETUP_ARGS:-} >&2

out="results/forest_4m"
args=("$@")
for ((i = 0; i < ${#args[@]}; i++)); do
  [[ "${args[i]}" == "--out" ]] && out="${args[i + 1]}"
done
# Real time unless asked otherwise: a flight figure counts only with the controller's real
# latency in it. --lockstep flies lock-step with that latency charged (measured), --ideal or
# --latency S the other lock-step variants.
clock=(--realtime)
pass=()
hold=()
for a in "$@"; do
  case "$a" in
    --view) pass+=("$a")
            [[ " $* " == *" --view-hold "* ]] || hold+=(--view-hold 600)
            [[ " $* " == *" --view-wait "* ]] || hold+=(--view-wait 30) ;;
    --lockstep) clock=() ;;
    --build-all) ;;
    --ideal|--latency|--realtime) clock=(); pass+=("$a") ;;
    *) pass+=("$a") ;;
  esac
done
rc=0
tools/sitl run --scenario forest_4m --seed 1 --backend cpu --out "$out" "${clock[@]}" "${pass[@]}" "${hold[@]}" || rc=$?
if [[ -d "$out" ]]; then
  echo "plots:"
  find "$out" -maxdepth 1 -name '*.png' -printf '  %p\n' | sort
  echo "log:   $out/flight.lcmlog (tools/lcm-spy, or lcm-logplayer)"
  [[ -f "$out/flight.rrd" ]] && echo "3D:    $out/flight.rrd (tools/view open $out/flight.rrd)"
fi
if [[ "${setup[0]:-}" == "--flight" ]]; then
  echo "built: what the flight needs; tools/setup.sh builds the rest (tests, benchmarks, tools), tools/test.sh too"
fi
exit "$rc"
