#!/usr/bin/env bash
# The tests that touch time, run again and again on a busy machine: `stress-ng --cpu N`
# (N = 2 by default: as many busy workers as the project's machines have cores) keeps every
# core loaded while each named test runs RUNS times in a row. Prints one line per run and a
# last line `N passed, N failed`; exits non-zero when any run failed. Not part of CI (20 runs
# of the default list take about an hour on 2 cores): run it after touching a timed test.
#
#   tools/stress-tests.sh [--runs N] [--cpu N] [--list] [PYTEST_NODE_ID ...]
#
#   --runs N   runs of each test (20)
#   --cpu N    stress-ng CPU workers beside them (2; 0: none)
#   --list     print the default tests and exit
#   With no test named, the default list below: the tests whose assertions involve the wall
#   clock, the bridge's timeouts or real-time flights (docs/reliability.md).
set -euo pipefail
ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
cd "$ROOT"

DEFAULT_TESTS=(
  "test/mavlink/test_failsafes.py::test_px4_link_back_never_resumes_offboard"
  "test/mavlink/test_failsafes.py::test_px4_offboard_loss_does_what_com_obl_rc_act_says"
  "test/mavlink/test_faults.py::test_mppid_killed_stops_stream_and_failsafe_engages"
  "test/mavlink/test_faults.py::test_gate_seq_health_staleness"
  "test/sitl/test_ap_sensing.py::test_truth_to_sensors_to_mapper_makes_a_map_of_the_tree_ahead"
  "test/mavlink/test_clock_sync.py::test_flight_with_an_autopilot_clock_two_percent_slow"
  "test/sitl/test_live_and_replay.py::test_lockstep_flight_with_live_updates_replays_bit_for_bit"
  "test/sitl/test_live_and_replay.py::test_rollouts_and_horizon_change_in_a_realtime_flight_without_a_late_cycle"
  "test/sitl/test_mission.py::test_the_mission_tool_flies_a_figure_eight_on_mppid_sim"
  "test/mavlink/test_autopilot_mission.py::test_a_mission_changed_in_flight_to_one_refused_holds"
)

runs=20 cpu=2 list=0 tests=()
while (($#)); do
  case "$1" in
    --runs) runs="$2"; shift ;;
    --cpu) cpu="$2"; shift ;;
    --list) list=1 ;;
    -h|--help) sed -n '2,15s/^# \{0,1\}//p' "${BASH_SOURCE[0]}"; exit 0 ;;
    -*) echo "stress-tests.sh: unknown option '$1' (try --help)" >&2; exit 2 ;;
    *) tests+=("$1") ;;
  esac
  shift
done
((${#tests[@]})) || tests=("${DEFAULT_TESTS[@]}")
if ((list)); then printf '%s\n' "${tests[@]}"; exit 0; fi
[[ "$runs" =~ ^[1-9][0-9]*$ ]] || { echo "stress-tests.sh: --runs: a positive integer, not '$runs'" >&2; exit 2; }
[[ "$cpu" =~ ^[0-9]+$ ]] || { echo "stress-tests.sh: --cpu: a count, not '$cpu'" >&2; exit 2; }
[[ -x .venv/bin/python ]] || { echo "stress-tests.sh: no .venv: run tools/setup.sh first" >&2; exit 1; }

stress_pid=
if ((cpu > 0)); then
  command -v stress-ng >/dev/null || { echo "stress-tests.sh: stress-ng missing (tools/setup.sh installs it)" >&2; exit 1; }
  stress-ng --cpu "$cpu" --quiet &
  stress_pid=$!
  trap 'kill "$stress_pid" 2>/dev/null || true; wait "$stress_pid" 2>/dev/null || true' EXIT
fi

passed=0 failed=0
for t in "${tests[@]}"; do
  for ((i = 1; i <= runs; i++)); do
    t0=$(date +%s)
    if .venv/bin/python -m pytest -q -p no:cacheprovider "$t" >"/tmp/stress-tests.$$.log" 2>&1; then
      passed=$((passed + 1)); verdict=passed
    else
      failed=$((failed + 1)); verdict=FAILED
      mkdir -p results/stress-tests
      cp "/tmp/stress-tests.$$.log" "results/stress-tests/$(echo "$t" | tr '/:' '__')-run$i.log"
    fi
    printf '[stress] %s run %d/%d: %s (%d s)\n' "$t" "$i" "$runs" "$verdict" "$(($(date +%s) - t0))"
  done
done
rm -f "/tmp/stress-tests.$$.log"
((failed == 0)) || echo "[stress] failed runs' logs: results/stress-tests/"
echo "$passed passed, $failed failed"
((failed == 0))
