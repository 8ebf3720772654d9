"""The referee (tools/sitl_harness/ap_truth.py) pairs each SIM_STATE with the
LOCAL_POSITION_NED of its burst: ArduPilot sends SIM_STATE first (ap_message order), and a
record written on the SIM_STATE held the previous burst's estimate, 20 ms older than the truth
beside it (at 5 m/s, 0.1 m of "lag" that was the referee's). Each record's truth and estimate
are now of the same time, and boot_us is that time."""
import json
import os
import sys
from pathlib import Path

os.environ.setdefault("MAVLINK20", "1")
from pymavlink import mavutil  # noqa: E402

sys.path.insert(0, str(Path(__file__).resolve().parents[2] / "tools"))
from sitl_harness import ap_truth  # noqa: E402

mavlink = mavutil.mavlink
ORIGIN = (-353632621, 1491652374, 584.0)


def recorder(tmp_path):
    r = ap_truth.Recorder.__new__(ap_truth.Recorder)  # no link: messages are handed in
    r.origin, r.f = ORIGIN, open(tmp_path / "truth.jsonl", "w")
    r.boot_us, r.est, r.truth, r.mode, r.armed = 0, None, None, "", False
    return r


def sim_state(k):
    """The truth of burst k: 1e-7 degree of latitude north a burst (~1.1 cm)."""
    return mavlink.MAVLink_sim_state_message(1, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, ORIGIN[2] + 2.0, 0, 0,
                                             0, 0, 0, lat_int=ORIGIN[0] + k, lon_int=ORIGIN[1])


def lpn(k):
    return mavlink.MAVLink_local_position_ned_message(1000 + 20 * k, k * ap_truth.M_PER_E7, 0, -2.0, 0, 0, 0)


def test_each_record_holds_the_truth_and_the_estimate_of_one_burst(tmp_path):
    r = recorder(tmp_path)
    for k in range(10):  # ArduPilot's order within a burst
        r.handle(sim_state(k))
        r.handle(lpn(k))
    r.handle(sim_state(10))   # a SIM_STATE whose position never comes: with the one before
    r.handle(sim_state(11))
    r.f.close()
    rows = [json.loads(line) for line in (tmp_path / "truth.jsonl").read_text().splitlines()]
    paired = [x for x in rows if x["paired"]]
    assert len(paired) == 10
    for k, row in enumerate(paired):
        assert row["boot_us"] == (1000 + 20 * k) * 1000
        assert abs(row["x"][1] - row["est"][1]) < 1e-3, row  # north: truth and estimate of the same burst
    assert [x["paired"] for x in rows[10:]] == [False]
