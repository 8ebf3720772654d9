"""The simulator and the harness on their own (hover stand-in controller): fast checks."""
from __future__ import annotations

import json
import subprocess

import pytest

from sitl_helpers import ROOT, sitl
from sitl_harness import paths


def run_sim(sim_binary, scenario, seed, out, duration=0.1):
    # memq:// keeps LCM in-process: nothing goes on any network.
    subprocess.run([str(sim_binary), "--scenario", str(paths.scenario_path(scenario)), "--seed", str(seed),
                    "--lcm-url", "memq://", "--out", str(out), "--duration", str(duration), "--quiet"],
                   check=True, timeout=30)
    return json.loads((out / "world.json").read_text())


def test_list_names_every_scenario():
    p = sitl("list", check=0, timeout=30)
    names = p.stdout.split()
    for n in ("forest_3m", "forest_4m", "forest_5m", "cartpole_swingup", "racecar_ellipse", "team3_moving",
              "track_circle", "track_figure_eight"):
        assert n in names
    assert names == paths.scenario_names() + paths.mission_names()
    assert "circle_5ms" in paths.mission_names()


def test_every_scenario_loads_and_steps(sim_binary, tmp_path):
    for n in paths.scenario_names():
        d = tmp_path / n
        d.mkdir()
        w = run_sim(sim_binary, n, 1, d, duration=0.05)
        assert w["scenario"] == n
        assert (d / "truth.jsonl").read_text().count("\n") >= 2


def test_command_timeout_hovers_the_plant(sim_binary, tmp_path):
    """timing.command_timeout (soak_circle: 0.25 s): with no command the plant gets its hover
    command once the timeout passes (truth mode -2) and holds its altitude; without it the
    applied command is whatever came last (here: the initial hover, mode -1)."""
    run_sim(sim_binary, "soak_circle", 1, tmp_path, duration=0.6)
    summary = json.loads((tmp_path / "sim_summary.json").read_text())
    assert summary["command_timeouts"] == 1 and not summary["collisions"]
    rows = [json.loads(line) for line in (tmp_path / "truth.jsonl").read_text().splitlines() if '"x"' in line]
    modes = {round(r["t"], 2): r["mode"] for r in rows}
    assert modes[0.2] == -1 and modes[0.3] == -2
    assert abs(rows[-1]["x"][2] - 2.0) < 0.05
    off = tmp_path / "off"
    off.mkdir()
    run_sim(sim_binary, "rate_track_circle", 1, off, duration=0.6)
    assert json.loads((off / "sim_summary.json").read_text())["command_timeouts"] == 0


def test_a_seed_names_a_forest(sim_binary, tmp_path):
    (tmp_path / "a").mkdir(), (tmp_path / "b").mkdir(), (tmp_path / "c").mkdir()
    a = run_sim(sim_binary, "forest_3m", 7, tmp_path / "a")["obstacles"]
    b = run_sim(sim_binary, "forest_3m", 7, tmp_path / "b")["obstacles"]
    c = run_sim(sim_binary, "forest_3m", 8, tmp_path / "c")["obstacles"]
    assert a == b and a != c
    # Denser forests for smaller spacing, start and goal kept clear.
    n = {}
    for sp in (3, 4, 5):
        d = tmp_path / f"f{sp}"
        d.mkdir()
        w = run_sim(sim_binary, f"forest_{sp}m", 1, d)
        n[sp] = len(w["obstacles"])
        for ob in w["obstacles"]:
            for p in w["starts"] + w["goals"]:
                assert ((ob[0] - p[0]) ** 2 + (ob[1] - p[1]) ** 2) ** 0.5 > 2.5
    assert n[3] > n[4] > n[5] > 10


def test_hover_standin_flight_holds_position(sim_binary, tmp_path):
    """Lock-step plumbing end to end: namespace, logger, sim, a controller answering every
    state; the plant (RK4) hovers in place on the hover command."""
    out = tmp_path / "hover"
    sitl("run", "--scenario", "track_circle", "--controller", "standin", "--out", out, "--timeout", 60)
    score = json.loads((out / "score.json").read_text())
    assert score["sim_outcome"] == "duration"
    # Lock-step: the simulator stepped only on an answer, so its truth log has one line per
    # answered state (the logger, one more UDP listener, may miss some on a loaded machine).
    answered = (out / "truth.jsonl").read_text().splitlines()
    assert len(answered) >= 1000  # 20 s at 50 Hz
    assert score["commands"] > 0
    last = json.loads((out / "truth.jsonl").read_text().splitlines()[-1])
    assert abs(last["x"][2] - 2.0) < 0.05 and abs(last["x"][0] - 3.0) < 0.05
    for f in ("flight.lcmlog", "path.png", "traces.png", "timing.png", "world.json", "sim_summary.json"):
        assert (out / f).is_file(), f


def test_quad_speeds_peak_and_in_the_trees():
    import numpy as np
    from sitl_harness.score import _quad_speeds
    # x from 0 to 30 m; 2 m/s before x = 4, 8 m/s among the trees (x 4-26 with radii), 3 after.
    px = np.linspace(0.0, 30.0, 301)
    v = np.where(px < 4.0, 2.0, np.where(px <= 26.0, 8.0, 3.0))
    v[150] = np.nan  # a missing sample is ignored
    X = np.zeros((301, 16))
    X[:, 0], X[:, 3], X[:, 4] = px, 0.6 * v, 0.8 * v
    world = {"nx": 16, "vehicles": 1, "obstacles": [[4.3, 1.0, 0.3, 0, 0], [25.7, -2.0, 0.3, 0, 0]]}
    out = _quad_speeds(world, X)
    assert out["peak_speed"] == pytest.approx(8.0)
    assert out["forest_speed"] == pytest.approx(8.0)
    assert _quad_speeds({"nx": 16, "vehicles": 1}, X)["forest_speed"] is None
