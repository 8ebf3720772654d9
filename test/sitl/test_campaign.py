"""Campaigns: scenario names and files alike, the local and Ray engines, retries, clean-up."""
from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time

import pytest

from sitl_helpers import ROOT, SITL, group_members, need_module, pid_alive, scenario_runs, sitl, write_scenario
from sitl_harness import campaign


def _raylets():
    out = set()
    for d in os.listdir("/proc"):
        if d.isdigit():
            try:
                with open(f"/proc/{d}/cmdline", "rb") as f:
                    if b"raylet" in f.read().split(b"\0")[0]:
                        out.add(int(d))
            except OSError:
                pass
    return out


def _assert_flight_gone(pids: dict, within: float = 15.0):
    deadline = time.monotonic() + within
    def alive():
        left = [n for n, p in pids.items() if n != "pgid" and pid_alive(p)]
        return left + [f"group member {p}" for p in group_members(pids["pgid"])]
    while alive() and time.monotonic() < deadline:
        time.sleep(0.2)
    assert alive() == [], alive()


# ---- issue 10 item 7: `campaign --scenarios FILE.yaml` ----------------------------------------
def test_resolve_scenarios_names_and_files(tmp_path):
    named = write_scenario(tmp_path / "some_file.yaml", name="hold_named")
    unnamed = write_scenario(tmp_path / "hold_unnamed.yaml", name=None)
    got = campaign.resolve_scenarios(["forest_4m", str(named), str(unnamed)])
    assert got == [("forest_4m", "forest_4m"), (str(named.resolve()), "hold_named"),
                   (str(unnamed.resolve()), "hold_unnamed")]
    # Two scenarios that would share a result folder are refused.
    twin = write_scenario(tmp_path / "twin.yaml", name="forest_4m")
    with pytest.raises(ValueError, match="both named 'forest_4m'"):
        campaign.resolve_scenarios(["forest_4m", str(twin)])
    with pytest.raises(FileNotFoundError):
        campaign.resolve_scenarios([str(tmp_path / "missing.yaml")])


def test_wilson_interval_holds_the_rate():
    # 0/11 and 6/6 came out a rounding error outside (the campaign plot refused them).
    for n in range(1, 200):
        for k in range(n + 1):
            lo, hi = campaign.wilson(k, n)
            assert 0.0 <= lo <= k / n <= hi <= 1.0, (k, n, lo, hi)
    assert campaign.wilson(0, 11)[0] == 0.0 and campaign.wilson(6, 6)[1] == 1.0
    lo, hi = campaign.wilson(5, 10)
    assert 0.2 < lo < 0.25 and 0.75 < hi < 0.8  # 0.237, 0.763


def test_campaign_plot_with_no_success(tmp_path):
    """A scenario that never succeeded (0 of 11) and one that always did (6 of 6) draw."""
    from sitl_harness.campaign_plot import plot_campaign
    runs = ([{"scenario": "never", "seed": s, "success": False, "min_clearance": -0.1} for s in range(11)] +
            [{"scenario": "always", "seed": s, "success": True, "time_to_goal": 5.0, "min_clearance": 1.0}
             for s in range(6)])
    summary = campaign.summarize(runs)
    (tmp_path / "summary.json").write_text(json.dumps({"summary": summary, "runs": runs}))
    out = plot_campaign(tmp_path)
    assert out.is_file() and out.stat().st_size > 1000


def test_parse_seeds():
    assert campaign.parse_seeds("3", 51) == [51, 52, 53]
    assert campaign.parse_seeds("51-53,60") == [51, 52, 53, 60]
    for bad in ("0", "5-2", "x", "1-"):
        with pytest.raises(ValueError):
            campaign.parse_seeds(bad)


def test_campaign_accepts_scenario_files(sim_binary, tmp_path):
    """Regression: the file path was used as the result folder's name (NotADirectoryError)."""
    named = write_scenario(tmp_path / "scen_a.yaml", name="hold_named")
    unnamed = write_scenario(tmp_path / "hold_unnamed.yaml", name=None)
    out = tmp_path / "camp"
    sitl("campaign", "--scenarios", f"{named},{unnamed}", "--seeds", 2, "--out", out, "--controller", "standin",
         "--jobs", 2, timeout=240, check=0)
    runs = scenario_runs(out)
    assert sorted(runs) == [("hold_named", 1), ("hold_named", 2), ("hold_unnamed", 1), ("hold_unnamed", 2)]
    assert all(r["success"] and r["attempts"] == 1 for r in runs.values()), runs
    for label in ("hold_named", "hold_unnamed"):
        for seed in (1, 2):
            score = json.loads((out / label / f"seed_{seed:04d}" / "score.json").read_text())
            assert score["scenario"] == label
    summary = json.loads((out / "summary.json").read_text())["summary"]
    assert summary["scenarios"]["hold_named"]["successes"] == 2
    assert summary["scenario_files"]["hold_named"] == str(named.resolve())
    assert "| hold_unnamed | 2 | 2/2" in (out / "summary.md").read_text()


# ---- issue 13 item 1: engines ----------------------------------------------------------------
def test_local_and_ray_campaigns_agree(mppid_binary, tmp_path):
    """The same lock-step campaign (2 flights of the real daemon, side by side) on both engines: the same
    outcomes, figures, truth paths and summary; a local Ray cluster started and stopped."""
    need_module("ray")
    scen = write_scenario(tmp_path / "rate_circle_short.yaml", name="rate_circle_short", duration=2.0,
                          base="rate_circle")
    before = _raylets()
    outs = {}
    for engine in ("local", "ray"):
        outs[engine] = tmp_path / engine
        # One optimizer thread a flight: two flights at a time on CI's two cores, and no cycle
        # slow enough (> 0.5 s) to make the simulator republish a state (not reproducible).
        # The plan is bit-identical for any thread count.
        # A fixed latency charged (the daemon is told it): lock-step then repeats bit for bit;
        # with the measured latency it would follow each run's own timing.
        p = sitl("campaign", "--scenarios", scen, "--seeds", "3-4", "--out", outs[engine], "--engine", engine,
                 "--jobs", 2, "--latency", 0.005, "--set", "mppi.threads=1", timeout=600, check=0)
        assert "2/2" in p.stderr  # the progress bar
    assert campaign.compare_campaigns(outs["local"], outs["ray"]) == []
    a, b = (json.loads((outs[e] / "summary.json").read_text()) for e in ("local", "ray"))
    assert len(a["runs"]) == 2 and [r["seed"] for r in a["runs"]] == [3, 4]
    assert a["summary"]["engine"]["engine"] == "local" and b["summary"]["engine"]["engine"] == "ray"
    assert a["summary"]["scenarios"]["rate_circle_short"]["successes"] > 0  # a real flight, not two crashes
    for e in ("local", "ray"):
        assert (outs[e] / "summary.png").is_file() and (outs[e] / "summary.md").is_file()
        # Each flight on its own bus.
        urls = {json.loads((outs[e] / "rate_circle_short" / f"seed_{s:04d}" / "harness.json").read_text())
                ["spec"]["lcm_url"] for s in (3, 4)}
        assert len(urls) == 2
        # Flights run at the campaign's niceness (Ray starts its workers at 15).
        nice = {json.loads((outs[e] / "rate_circle_short" / f"seed_{s:04d}" / "harness.json").read_text())
                ["niceness"] for s in (3, 4)}
        assert nice == {os.getpriority(os.PRIO_PROCESS, 0)}, (e, nice)
    assert _raylets() <= before  # the local cluster is gone


def _kill_mid_flight(tmp_path, engine):
    """A 6 s real-time stand-in flight; its task is killed 1 s in (the Ray worker, or the local
    `sitl run` process). Returns (campaign folder, the first attempt's pids, the process)."""
    scen = write_scenario(tmp_path / "hold6.yaml", name="hold6", duration=6.0)
    out = tmp_path / "camp"
    p = subprocess.Popen([str(SITL), "campaign", "--scenarios", str(scen), "--seeds", "1", "--out", str(out),
                          "--controller", "standin", "--realtime", "--engine", engine], cwd=ROOT,
                         stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    folder = out / "hold6" / "seed_0001"
    deadline = time.monotonic() + 90
    while not (folder / "pids.json").is_file() and time.monotonic() < deadline:
        time.sleep(0.1)
    assert (folder / "pids.json").is_file(), p.stderr.read() if p.poll() is not None else "no flight started"
    time.sleep(1.0)
    pids = json.loads((folder / "pids.json").read_text())
    if engine == "ray":
        victim = json.loads((folder / "worker.json").read_text())["pid"]
    else:
        victim = int(subprocess.run(["ps", "-o", "ppid=", "-p", str(pids["holder"])], capture_output=True,
                                    text=True).stdout)
    os.kill(victim, signal.SIGKILL)
    return out, pids, p


@pytest.mark.parametrize("engine", ["local", "ray"])
def test_task_killed_mid_flight_leaves_nothing_and_is_flown_again(sim_binary, tmp_path, engine):
    if engine == "ray":
        need_module("ray")
    before = _raylets()
    out, pids, p = _kill_mid_flight(tmp_path, engine)
    # No orphan simulator, controller, logger or namespace holder.
    _assert_flight_gone(pids)
    _, err = p.communicate(timeout=180)
    assert p.returncode == 0, err
    run = scenario_runs(out)[("hold6", 1)]
    assert run["attempts"] == 2, run
    assert run["success"] is True  # the second attempt flew
    assert len(run["retried"]) == 1 and run["retried"][0].startswith("attempt 1:")
    assert "flying it again" in err
    assert "hold6 seed 1: attempt 1:" in (out / "summary.md").read_text()
    if engine == "ray":
        assert "lost" in run["retried"][0], run["retried"]
        assert _raylets() <= before


def test_local_engine_needs_no_ray(sim_binary, tmp_path):
    """`--engine local` never imports ray; `--engine ray` without it is a clear error."""
    scen = write_scenario(tmp_path / "hold.yaml")
    block = ("import sys; sys.modules['ray'] = None; sys.argv[0] = 'sitl'; "
             "from sitl_harness.cli import main; sys.exit(main(sys.argv[1:]))")
    env = dict(os.environ)
    base = [sys.executable, "-c", block, "campaign", "--scenarios", str(scen), "--seeds", "1", "--controller", "standin"]
    p = subprocess.run(base + ["--out", str(tmp_path / "a")], cwd=ROOT, env=env, capture_output=True, text=True,
                       timeout=120)
    assert p.returncode == 0, p.stderr
    p = subprocess.run(base + ["--out", str(tmp_path / "b"), "--engine", "ray"], cwd=ROOT, env=env,
                       capture_output=True, text=True, timeout=120)
    assert p.returncode == 2 and "needs the `ray` package" in p.stderr, p.stderr


def test_local_engine_stops_flights_and_runs_again(sim_binary, tmp_path):
    """A caller that stops after the first result (tune's pruning) gets one score, the other
    flights are never flown; the engine then flies the same jobs again in full."""
    from sitl_harness.engine import LocalEngine, run_flights

    scen = write_scenario(tmp_path / "hold.yaml")
    jobs = campaign.make_jobs(campaign.resolve_scenarios([str(scen)]), [1, 2, 3], tmp_path / "out",
                              controller="standin", plots=False)
    eng = LocalEngine(1)
    try:
        first = run_flights(eng, jobs, on_result=lambda job, score: True)
        assert [r["seed"] for r in first] == [1]
        assert not any((tmp_path / "out" / "hold_short" / f"seed_{s:04d}").exists() for s in (2, 3))
        again = run_flights(eng, jobs)
        assert [r["seed"] for r in again] == [1, 2, 3] and all(r["success"] for r in again)
    finally:
        eng.close()


def test_compare_names_differences_and_disturbed_lockstep(tmp_path):
    def folder(name, runs):
        d = tmp_path / name
        d.mkdir()
        (d / "summary.json").write_text(json.dumps({"summary": campaign.summarize(runs), "runs": runs}))
        return d

    base = {"scenario": "s", "seed": 1, "success": True, "reason": "goal reached", "time_to_goal": 6.0,
            "compute_ms_p99": 9.0, "wall_s": 3.0}
    a = folder("a", [dict(base), dict(base, seed=2)])
    b = folder("b", [dict(base, compute_ms_p99=30.0, wall_s=9.0), dict(base, seed=2)])
    assert campaign.compare_campaigns(a, b, truth=False) == []  # timings are not outcomes
    c = folder("c", [dict(base), dict(base, seed=2, time_to_goal=7.5, lockstep_republished=2)])
    diffs = campaign.compare_campaigns(a, c, truth=False)
    assert any("seed 2: time_to_goal 6.0 != 7.5 [lock-step disturbed in B (2 states republished)]" in d
               for d in diffs), diffs
    assert any(d.startswith("summary s: time_to_goal") for d in diffs)
    md = campaign.markdown(campaign.summarize([dict(base), dict(base, seed=2, lockstep_republished=2)]))
    assert "1 lock-step flight(s) waited > 0.5 s" in md


def test_ray_campaign_joins_an_existing_cluster(sim_binary, tmp_path):
    """--address: the campaign runs its flights on a running cluster (here one this test
    starts) and leaves that cluster running."""
    ray = need_module("ray")
    os.environ.setdefault("RAY_USAGE_STATS_ENABLED", "0")
    ctx = ray.init(num_cpus=2, include_dashboard=False, log_to_driver=False, logging_level="WARNING")
    try:
        address = ctx.address_info["gcs_address"]
        scen = write_scenario(tmp_path / "hold.yaml")
        out = tmp_path / "camp"
        sitl("campaign", "--scenarios", scen, "--seeds", 2, "--out", out, "--controller", "standin", "--engine", "ray",
             "--address", address, timeout=300, check=0)
        runs = scenario_runs(out)
        assert [r["success"] for r in runs.values()] == [True, True]
        engine = json.loads((out / "summary.json").read_text())["summary"]["engine"]
        assert engine["engine"] == "ray" and engine["address"] == address and engine["jobs"] == 2
        worker = json.loads((out / "hold_short" / "seed_0001" / "worker.json").read_text())
        assert worker["node_id"] == ray.get_runtime_context().get_node_id()
        assert ray.get(ray.remote(lambda: 42).remote()) == 42  # still up
    finally:
        ray.shutdown()


# ---- tools/sitl table: real time and lock-step side by side -----------------------------------
def _fake_campaign(folder, clock, runs):
    folder.mkdir()
    (folder / "summary.json").write_text(json.dumps({"summary": {"clock": clock, "seeds": [51, 52]}, "runs": runs}))


def test_table_puts_campaigns_side_by_side(tmp_path):
    from sitl_harness.sidebyside import rows, table
    run = lambda seed, ok, p99, misses, t, clear, reason: {  # noqa: E731
        "scenario": "forest_4m", "seed": seed, "backend": "cpu-avx2", "success": ok, "reason": reason,
        "compute_ms_p99": p99, "deadline_misses": misses, "time_to_goal": t, "min_clearance": clear}
    _fake_campaign(tmp_path / "rt", "realtime", [run(51, True, 5.0, 0, 6.0, 0.2, "goal"),
                                                 run(52, False, 9.0, 2, None, 0.0, "collision")])
    _fake_campaign(tmp_path / "ls", "lockstep, measured latency charged", [run(51, True, 4.0, 0, 5.0, 0.3, "goal"),
                                                                           run(52, True, 4.5, 0, 7.0, 0.1, "goal")])
    r = rows(tmp_path / "rt")["rows"]["forest_4m"]
    assert (r["success"], r["runs"], r["misses"], r["min_clearance"]) == (1, 2, 2, 0.0)
    assert r["compute_p99_median"] == 7.0 and r["compute_p99_worst"] == 9.0
    assert r["merit"] == "goal in 6.00 s"  # successful flights only
    text = table([tmp_path / "rt", tmp_path / "ls"], ["real time", "lock-step"])
    line = [ln for ln in text.splitlines() if ln.startswith("| forest_4m")][0]
    assert "1/2 (collision)" in line and "2/2" in line and "goal in 6.00 s" in line and "goal in 6.00 s" in line.split("2/2")[1]
    assert "seeds 51-52" in text
    out = sitl("table", tmp_path / "rt", tmp_path / "nothing")
    assert out.returncode == 2 and "no summary.json" in out.stderr


def test_table_merges_folders_of_one_name(tmp_path):
    from sitl_harness.sidebyside import table
    run = lambda scen: {"scenario": scen, "seed": 51, "backend": "cpu", "success": True, "reason": "goal",  # noqa: E731
                        "compute_ms_p99": 3.0, "deadline_misses": 0, "time_to_goal": 5.0}
    _fake_campaign(tmp_path / "a", "realtime", [run("forest_4m")])
    _fake_campaign(tmp_path / "b", "realtime", [run("cartpole_swingup")])
    text = table([tmp_path / "a", tmp_path / "b"], ["real time", "real time"])
    assert text.splitlines()[0].count("real time: success") == 1
    assert "| forest_4m | 1/1" in text and "| cartpole_swingup | 1/1" in text


def test_speed_curve_groups_campaigns_by_their_speed_limit(tmp_path):
    from sitl_harness.speed_curve import markdown, rows, speed_limit
    assert speed_limit(["cost.vehicle_radius=0.3", "cost.max_speed=5", "cost.max_speed=7.5"]) == 7.5
    assert speed_limit(["cost.w_speed=2"]) is None and speed_limit(["cost.max_speed=0"]) is None
    assert speed_limit(["mppi.rollouts=512", "cost.max_speed=5"], "mppi.rollouts") == 512
    run = lambda seed, ok, fs, s2c: {"scenario": "forest_4m_sensed", "seed": seed, "backend": "cpu-avx3",  # noqa: E731
                                     "success": ok, "forest_speed": fs, "peak_speed": fs + 1, "min_clearance": fs / 100,
                                     "state_to_command_ms_p99": s2c, "deadline_misses": 1}
    for name, limit, flights in (("v10", 10, [run(51, True, 8.0, 9.0), run(52, False, 9.0, 30.0)]),
                                 ("v5", 5, [run(51, True, 4.0, 8.0), run(52, True, 5.0, 10.0)]),
                                 ("free", None, [run(51, True, 9.5, 7.0)])):
        (tmp_path / name).mkdir()
        sets = [f"cost.max_speed={limit}"] if limit else []
        (tmp_path / name / "summary.json").write_text(json.dumps({"summary": {"sets": sets}, "runs": flights}))
    table = rows([tmp_path / "free", tmp_path / "v10", tmp_path / "v5"])
    assert [r["limit"] for r in table] == [5.0, 10.0, None]
    v10 = table[1]
    assert (v10["successes"], v10["runs"], v10["forest_speed"], v10["deadline_misses"]) == (1, 2, 8.0, 2)
    assert v10["state_to_command_p99_worst"] == 30.0 and v10["min_clearance"] == 0.08
    assert v10["wilson95"][0] < 0.5 < v10["wilson95"][1]
    text = markdown(table)
    assert "| 5 | forest_4m_sensed | cpu-avx3 | 2/2 |" in text and "| no limit |" in text
    out = sitl("speed-curve", tmp_path / "v5", tmp_path / "nothing")
    assert out.returncode == 2 and "no summary.json" in out.stderr
