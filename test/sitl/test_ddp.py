"""The MPC-DDP baseline through the harness (`--controller ddp`: mppid --controller ddp),
and the side-by-side table of `sitl versus`."""
from __future__ import annotations

import json

from sitl_helpers import sitl
from sitl_harness import versus


def test_ddp_flies_the_cartpole_through_the_harness(mppid_binary, tmp_path):
    out = tmp_path / "ddp"
    sitl("run", "--scenario", "cartpole_swingup", "--seed", 1, "--latency", 0.01, "--controller", "ddp",
         "--no-plots", "--out", out, timeout=120)
    score = json.loads((out / "score.json").read_text())
    harness = json.loads((out / "harness.json").read_text())
    cmd = harness["commands"]["controller"]
    assert "--controller" in cmd and cmd[cmd.index("--controller") + 1] == "ddp", cmd
    assert score["backend"] == "ddp", score  # controller_status_t names the optimizer
    assert score["success"] is True, score
    assert score["compute_ms_p50"] is not None and score["compute_ms_p50"] <= score["compute_ms_p99"]


def _folder(tmp_path, name, runs):
    d = tmp_path / name
    d.mkdir()
    (d / "summary.json").write_text(json.dumps({"summary": {}, "runs": runs}))
    return d


def test_versus_puts_controllers_side_by_side(tmp_path):
    def run(seed, ok, ttg, clr, p50, p99, reason="goal reached"):
        return {"scenario": "forest_4m", "seed": seed, "success": ok, "reason": reason, "time_to_goal": ttg,
                "min_clearance": clr, "compute_ms_p50": p50, "compute_ms_p99": p99}
    a = _folder(tmp_path, "a", [run(1, True, 5.0, 0.1, 2.0, 4.0), run(2, True, 7.0, 0.3, 3.0, 6.0)])
    b = _folder(tmp_path, "b", [run(1, True, 8.0, 0.5, 1.0, 9.0),
                                run(2, False, None, 0.6, 1.5, 3.0, reason="goal not reached in 30 s")])
    table, rows = versus.versus([a, b], ["MPPI", "DDP"])
    mppi, ddp = rows
    assert (mppi["controller"], mppi["success"], ddp["success"]) == ("MPPI", 2, 1)
    assert mppi["time_to_goal"] == 6.0 and mppi["time_to_goal_common"] == 5.0 and mppi["common"] == 1
    assert ddp["time_to_goal"] == 8.0
    assert mppi["compute_p50"] == 2.5 and mppi["compute_p99_worst"] == 6.0
    assert ddp["clearance_min"] == 0.5  # failed flights do not count
    assert ddp["failures"] == {"goal not reached in 30 s": 1}
    assert "| forest_4m | DDP | 1/2 |" in table
