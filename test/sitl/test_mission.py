"""The mission tool against mppid-sim (issue 20: it works the same against mppid-sim and a
real autopilot): config/scenarios/mission_figure_eight.yaml, whose simulator publishes no
reference, flown in real time with drivers/mission giving mppid the figure-eight of
config/missions/figure_eight_3ms.yaml, ramped up from the hover."""
import json

from sitl_helpers import sitl
from sitl_harness import logs


def test_the_mission_tool_flies_a_figure_eight_on_mppid_sim(mppid_binary, tmp_path):
    out = tmp_path / "mission"
    sitl("run", "--scenario", "mission_figure_eight", "--seed", 1, "--realtime", "--out", out, timeout=120)
    score = json.loads((out / "score.json").read_text())
    summary = json.loads((out / "mission_summary.json").read_text())
    assert summary["outcome"] == "done", summary
    assert [leg["kind"] for leg in summary["legs"]] == ["hold", "figure_eight", "hold"]
    assert score["success"] is True, (score["reason"], score["deadline_misses"], score["state_to_command_ms_p99"], score["state_age_ms_p99"])
    assert score["collisions"] == []
    # mppid tracked what the tool sent: a figure-eight with a ramp, epoch on the state clock.
    refs = [m for _, m in logs.read_lcm_log(out / "flight.lcmlog", {"MPPI_REFERENCE"})["MPPI_REFERENCE"]]
    eights = [m for m in refs if m.kind == m.KIND_FIGURE_EIGHT]
    assert eights and eights[0].ramp_s == 3.0 and eights[0].speed == 3.0
    steps = [r for r in map(json.loads, (out / "mission.jsonl").read_text().splitlines()) if r.get("event") == "step"]
    assert any(s["kind"] == "figure_eight" and s["t0_us"] == eights[0].t0_utime for s in steps)
