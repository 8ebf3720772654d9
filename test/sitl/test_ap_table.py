"""tools/sitl autopilot-table: one row per mission and controller, whatever the seeds."""
from __future__ import annotations

import json

from sitl_harness import ap_table


def _campaign(folder, runs):
    folder.mkdir()
    (folder / "summary.json").write_text(json.dumps({"summary": {}, "runs": runs}))
    return folder


def _run(mission, seed, rmse, ok=True, reason="mission done"):
    return {"scenario": mission, "seed": seed, "success": ok, "reason": reason, "tracking_rmse": rmse,
            "max_tilt_deg": 10 + seed % 7, "legs": {"circle": {"max": 2 * rmse, "rmse_estimate": rmse / 2}}}


def test_one_row_per_mission_and_controller(tmp_path):
    a = _campaign(tmp_path / "mppid", [_run("circle_3ms", s, 0.08) for s in (51, 52, 53)] +
                  [_run("circle_5ms", s, 0.10) for s in (51, 52)] + [_run("circle_5ms", 53, 0.5, False, "hit the ground")])
    b = _campaign(tmp_path / "guided", [_run("circle_3ms", s, 0.30) for s in (51, 52, 53)])
    rows = [line for line in ap_table.table([a, b], ["mppid", "ArduCopter"]).splitlines()[2:]]
    assert [r.split(" | ")[:2] for r in rows] == [["| circle_3ms", "mppid"], ["| circle_3ms", "ArduCopter"],
                                                  ["| circle_5ms", "mppid"]]
    cells = [c.strip() for c in rows[2].strip("|").split("|")]
    assert cells[2:5] == ["3", "2/3", "0.100"]       # flights, success, RMS over the successful ones
    assert cells[-1] == "hit the ground"
    assert [c.strip() for c in rows[1].strip("|").split("|")][4] == "0.300"


def test_folders_under_one_label_are_one_campaign(tmp_path):
    """A campaign flown in batches (seeds 51-52, then 53) is one row, its flights together."""
    a = _campaign(tmp_path / "b1", [_run("circle_3ms", s, 0.08) for s in (51, 52)])
    b = _campaign(tmp_path / "b2", [_run("circle_3ms", 53, 0.5, False, "hit the ground")])
    rows = ap_table.table([a, b], ["mppid", "mppid"]).splitlines()[2:]
    assert len(rows) == 1
    assert [c.strip() for c in rows[0].strip("|").split("|")][2:4] == ["3", "2/3"]
