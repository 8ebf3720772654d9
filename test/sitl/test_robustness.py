"""tools/sitl robustness: each cell of the map changes the plant as it says and nothing else,
every variant is a scenario mppid-sim flies, and the map reads its campaign's runs."""
from __future__ import annotations

import json
import subprocess

import pytest
import yaml

from sitl_helpers import ROOT
from sitl_harness import robustness


@pytest.fixture(scope="module")
def variants(tmp_path_factory):
    out = tmp_path_factory.mktemp("map")
    files = robustness.write_variants(["forest_4m", "rate_track_circle_fast"], out)
    return {(b, c): yaml.safe_load(p.read_text()) for b, c, _, p in files}, files


def test_each_cell_changes_what_it_says(variants):
    docs, files = variants
    assert len(files) == 2 * len(robustness.CELLS)
    f, r = docs[("forest_4m", "nominal")], docs[("rate_track_circle_fast", "nominal")]
    base = yaml.safe_load((ROOT / "config/scenarios/forest_4m.yaml").read_text())
    assert f["plant"] == {**base["plant"], "params": {}} and f.get("wind") is None and f.get("noise") is None
    assert docs[("forest_4m", "mass_120")]["plant"]["params"] == {"mass": pytest.approx(0.30)}
    assert docs[("rate_track_circle_fast", "mass_080")]["plant"]["params"] == {"mass": pytest.approx(0.8)}
    # The motor constant: k_force on the 16-state plant, the thrust gain on the rate plant.
    assert docs[("forest_4m", "motor_090")]["plant"]["params"] == {"k_force": pytest.approx(0.9 * 6.11e-8)}
    assert docs[("rate_track_circle_fast", "motor_110")]["plant"]["thrust_gain"] == 1.1
    # Wind needs drag to act: drag / mass = 0.2 /s where the plant had none.
    w = docs[("forest_4m", "wind_3")]
    assert w["wind"]["mean"] == [0.0, 3.0, 0.0] and w["plant"]["params"]["drag"] == 0.05
    assert docs[("rate_track_circle_fast", "wind_1")]["plant"]["params"]["drag"] == 0.2
    assert docs[("forest_4m", "delay_20")]["timing"]["actuation_delay"] == 0.02
    assert "mppid" not in docs[("forest_4m", "delay_20")]  # the controller is not told
    assert docs[("rate_track_circle_fast", "noise_2")]["noise"]["velocity"] == pytest.approx(0.04)
    assert r["reference"] == docs[("rate_track_circle_fast", "noise_2")]["reference"]


def test_every_variant_is_a_scenario_the_simulator_flies(variants, sim_binary, tmp_path):
    _, files = variants
    for b, cell, _, path in files:
        out = tmp_path / f"{b}_{cell}"
        out.mkdir()
        # memq:// keeps LCM in-process; no controller: the plant holds its last (hover) command.
        subprocess.run([str(sim_binary), "--scenario", str(path), "--lcm-url", "memq://", "--duration", "0.02",
                        "--out", str(out), "--quiet"], check=True, timeout=30, capture_output=True)
        world = json.loads((out / "world.json").read_text())
        assert world["scenario"] == f"{b}__{cell}"


def test_the_map_counts_each_cell(variants):
    _, files = variants
    runs = {"forest_4m__mass_120": [{"success": True, "time_to_goal": 6.0}, {"success": False, "reason": "collision with ground (vehicle 0) at t=2.0 s"}],
            "rate_track_circle_fast__nominal": [{"success": True, "tracking_rmse": 0.05}]}
    text, totals = robustness.table(files, runs)
    assert "| mass +20 % | 1/2 (collision with ground (vehicle 0)) | goal in 6.00 s |" in text
    assert "RMSE 0.050 m (max 0.050)" in text
    assert totals == {"forest_4m": [1, 2], "rate_track_circle_fast": [1, 1]}
