"""tools/sitl tune (Optuna) and settings overlays."""
from __future__ import annotations

import json
import signal
import subprocess
import time

import pytest
import yaml

from sitl_helpers import ROOT, SITL, group_members, need_module, pid_alive, sitl, write_scenario
from sitl_harness import overlay, tune


# ---- overlays --------------------------------------------------------------------------------
def test_overlay_round_trip_and_errors(tmp_path):
    doc = {"mppi": {"lambda": 1e-5, "sigma": [2.0, 1.0], "rollouts": 512, "weighting": "trajectory"},
           "cost": {"w_obstacle": 1200.0}}
    sets = overlay.to_sets(doc)
    assert sets == ["mppi.lambda=1.0e-05", "mppi.sigma=[2.0,1.0]", "mppi.rollouts=512", "mppi.weighting=trajectory",
                    "cost.w_obstacle=1200.0"]
    assert overlay.from_sets(sets) == doc
    f = tmp_path / "o.yaml"
    f.write_text(yaml.safe_dump(doc, sort_keys=False))
    p = sitl("overlay", f, check=0, timeout=30)
    assert p.stdout.split() == [w for kv in sets for w in ("--set", kv)]
    for bad, field in (({"mppi": {"lambda": None}}, "mppi.lambda"), ({"mppi": {"x": {"a": "two words"}}}, "mppi.x.a"),
                       ([1, 2], "(file)")):
        f.write_text(yaml.safe_dump(bad))
        p = sitl("overlay", f, timeout=30)
        assert p.returncode == 2 and field in p.stderr, p.stderr


def test_resolve_params_table_and_ranges():
    settings = {"mppi": {"lambda": 100.0, "nu": 2.0, "sigma": [2.0, 1.0], "rollouts": 1024, "horizon": 75},
                "cost": {"w_pos": 10.0, "w_list": [1.0, 2.0]}}
    ps = {p.name: p for p in tune.resolve_params(
        ["lambda", "nu", "sigma", "rollouts", "horizon", "smoothing_window", "cost.w_pos", "cost.w_list"],
        tune.parse_ranges(["horizon=40:80:linear"]), settings, "cfg")}
    assert (ps["lambda"].lo, ps["lambda"].hi, ps["lambda"].log) == (10.0, 1000.0, True)
    assert (ps["nu"].lo, ps["nu"].hi) == (1.0, 8.0)  # the floor: validation wants nu >= 1
    assert ps["sigma"].kind == "factor" and ps["sigma"].setting(1.5) == "mppi.sigma=[3.0,1.5]"
    assert (ps["rollouts"].lo, ps["rollouts"].hi, ps["rollouts"].kind) == (512, 2048, "int")
    assert (ps["horizon"].lo, ps["horizon"].hi, ps["horizon"].log) == (40, 80, False)
    assert (ps["smoothing_window"].lo, ps["smoothing_window"].hi) == (1, 9)
    assert (ps["cost.w_pos"].lo, ps["cost.w_pos"].hi) == pytest.approx((1.0, 100.0))
    assert ps["cost.w_list"].kind == "factor"
    for names, ranges, field in ((["foo"], [], "foo"), (["cost.w_vel"], [], "cost.w_vel"),
                                 (["lambda"], ["lambda=-1:5"], "mppi.lambda"), (["lambda", "lambda"], [], "mppi.lambda"),
                                 (["bogus.key"], [], "bogus.key")):
        with pytest.raises(tune.TuneError, match=field.replace(".", r"\.")):
            tune.resolve_params(names, tune.parse_ranges(ranges), settings, "cfg")
    with pytest.raises(tune.TuneError, match="LO < HI"):
        tune.parse_ranges(["lambda=5:1"])


# ---- the study -------------------------------------------------------------------------------
def test_tune_stops_before_any_flight_on_bad_input(mppid_binary, tmp_path):
    scen = write_scenario(tmp_path / "hold.yaml")
    base = ["tune", "--scenarios", scen, "--params", "lambda", "--trials", 2]
    cases = [
        (["--seeds", "1-2", "--params", "lambda,not_a_param"], "not_a_param"),
        # mppi.nu must be >= 1: the daemon's own validation says so, naming the field.
        (["--seeds", "1-2", "--params", "nu", "--range", "nu=0.5:4"], "mppi.nu"),
        (["--seeds", "1-2", "--params", "cost.w_no_such_weight", "--range", "cost.w_no_such_weight=1:2"],
         "cost.w_no_such_weight"),
        (["--seeds", "49-52"], "seeds 1-50"),
    ]
    for k, (extra, field) in enumerate(cases):
        out = tmp_path / f"study{k}"
        args = list(base)
        if "--params" in extra:
            i = args.index("--params")
            del args[i:i + 2]
        p = sitl(*args, *extra, "--out", out, timeout=120)
        assert p.returncode == 2, p.stderr
        assert field in p.stderr, p.stderr
        assert not (out / "trials").exists()  # not one flight
    # --allow-test-seeds lifts the seed limit (and then fails only on what follows).
    p = sitl(*base, "--seeds", "49-52", "--params", "lambda,not_a_param", "--allow-test-seeds",
             "--out", tmp_path / "s9", timeout=120)
    assert p.returncode == 2 and "not_a_param" in p.stderr and "seeds" not in p.stderr


def _study(out):
    import optuna

    return optuna.load_study(study_name="tune", storage=f"sqlite:///{out / 'study.db'}")


def test_tune_resumes_after_a_kill(mppid_binary, tmp_path):
    """A tiny study (stand-in controller, 1 s flights, one seed a trial) is SIGKILLed while a
    trial flies; the same command resumes it: the stored trials are kept, the killed one is
    closed and flown again, and the study ends with the trials asked for and an overlay."""
    optuna = need_module("optuna")
    from optuna.trial import TrialState

    scen = write_scenario(tmp_path / "hold.yaml")
    out = tmp_path / "study"
    cmd = [str(SITL), "tune", "--scenarios", str(scen), "--seeds", "1", "--params", "lambda,sigma",
           "--trials", "3", "--out", str(out), "--controller", "standin", "--jobs", "1", "--keep-flights"]
    p = subprocess.Popen(cmd, cwd=ROOT, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    deadline = time.monotonic() + 180
    killed_pids = None
    # One trial at a time (--jobs 1): a flight of trial 1 or later in the air means trial 0 is
    # stored. Watched on the file system alone (a study query takes long on a busy machine and
    # could miss a whole trial between two looks).
    while time.monotonic() < deadline and p.poll() is None:
        time.sleep(0.05)
        pid_files = [f for f in (out / "trials").glob("*/*/seed_*/pids.json") if int(f.parts[-4]) >= 1]
        if pid_files:
            try:
                killed_pids = json.loads(pid_files[0].read_text())
            except (OSError, ValueError):  # being written, or gone with its flight
                continue
            p.send_signal(signal.SIGKILL)
            break
    p.wait(timeout=30)
    assert killed_pids is not None, "the study ended before it could be killed"
    # The flight that was in the air stops by itself (its parent is gone) and cleans up.
    deadline = time.monotonic() + 20
    while time.monotonic() < deadline and (any(pid_alive(v) for k, v in killed_pids.items() if k != "pgid")
                                           or group_members(killed_pids["pgid"])):
        time.sleep(0.2)
    assert not any(pid_alive(v) for k, v in killed_pids.items() if k != "pgid")
    before = _study(out).get_trials()
    stored = {t.number: (t.params, t.value) for t in before if t.state == TrialState.COMPLETE}
    killed = [t for t in before if t.state == TrialState.RUNNING]
    assert stored and len(killed) == 1

    r = subprocess.run(cmd, cwd=ROOT, capture_output=True, text=True, timeout=300)
    assert r.returncode == 0, r.stderr
    assert f"trial {killed[0].number} was left running" in r.stderr
    after = _study(out).get_trials()
    for n, (params, value) in stored.items():  # the stored trials are kept as they were
        assert after[n].state == TrialState.COMPLETE and after[n].params == params and after[n].value == value
    assert after[killed[0].number].state == TrialState.FAIL
    reruns = [t for t in after if t.user_attrs.get("rerun_of") == killed[0].number]
    assert len(reruns) == 1 and reruns[0].params == killed[0].params and reruns[0].state == TrialState.COMPLETE
    counted = [t for t in after if t.state in (TrialState.COMPLETE, TrialState.PRUNED)]
    assert len(counted) == 3
    best = yaml.safe_load((out / "best.yaml").read_text())
    assert set(best["mppi"]) == {"lambda", "sigma"}
    assert all(s.startswith("mppi.") for s in overlay.load_sets(out / "best.yaml"))
    # The best settings load in the daemon as they are.
    cfg = subprocess.run([str(mppid_binary), "--config", str(out / "best_config.yaml"), "--lcm-url", "memq://",
                          "--duration", "0.05", "--log-level", "error"], capture_output=True, text=True, timeout=60)
    assert cfg.returncode == 0, cfg.stderr
    # Run again with more trials asked for: it goes on from the 3 it holds.
    r = subprocess.run(cmd[:cmd.index("--trials") + 1] + ["4"] + cmd[cmd.index("--trials") + 2:], cwd=ROOT,
                       capture_output=True, text=True, timeout=300)
    assert r.returncode == 0, r.stderr
    assert "3 trials stored, 1 to go" in r.stderr
    # Another definition of the study is refused, naming what changed.
    r = subprocess.run(cmd[:cmd.index("--seeds") + 1] + ["1-2"] + cmd[cmd.index("--seeds") + 2:], cwd=ROOT,
                       capture_output=True, text=True, timeout=120)
    assert r.returncode == 2 and "seeds" in r.stderr, r.stderr


class FakeEngine:
    """Flies nothing: each flight's outcome is `outcome(trial settings, seed)`."""
    capacity = 1

    def __init__(self, outcome):
        self.outcome, self.flown = outcome, []

    def submit(self, job, attempt):
        self.flown.append(job)
        return len(self.flown)

    def wait_any(self, handles, timeout=None):
        h = next(iter(handles))
        job = self.flown[h - 1]
        ok = self.outcome(job.sets, job.seed)
        return [(h, {"rc": 0 if ok else 1, "score": {"scenario": job.label, "seed": job.seed, "success": ok,
                                                     "reason": "ok" if ok else "crash", "time_to_goal": 10.0}})]

    def cancel(self, jobs_and_handles):
        pass


def _fake_study(tmp_path, prune):
    import types

    params = tune.resolve_params(["lambda"], tune.parse_ranges(["lambda=1:100"]), {"mppi": {"lambda": 10.0}}, "cfg")
    a = types.SimpleNamespace(backend="cpu", controller="mppid", realtime=False, keep_flights=False)
    return types.SimpleNamespace(a=a, scenarios=[("s", "s")], seeds=list(range(1, 11)), params=params, base_sets=[],
                                 secondary="time_to_goal", prune=prune, out=tmp_path,
                                 docs={"s": {"success": {"type": "goal"}, "timing": {"duration": 20}}})


def test_bound_pruning_stops_a_hopeless_trial(tmp_path):
    """The first trial succeeds on 8 of 10 seeds; the second fails its first 3: it can reach 7
    at most, so it is pruned after 3 flights, and the rest are never flown."""
    optuna = need_module("optuna")
    from optuna.trial import TrialState

    st = _fake_study(tmp_path, {"bound"})
    study = optuna.create_study(direction="maximize")
    study.enqueue_trial({"lambda": 10.0})
    study.enqueue_trial({"lambda": 50.0})
    good = FakeEngine(lambda sets, seed: seed <= 8)
    study.optimize(lambda t: tune._objective(st, study, t, good, optuna), n_trials=1)
    assert study.trials[0].value == pytest.approx((8 + 0.99 / 1.5) / 10)
    bad = FakeEngine(lambda sets, seed: False)
    study.optimize(lambda t: tune._objective(st, study, t, bad, optuna), n_trials=1)
    t = study.trials[1]
    assert t.state == TrialState.PRUNED and len(bad.flown) == 3, (t.state, len(bad.flown))
    assert "at most 7 < best 8" in t.user_attrs["pruned"]
    # Without pruning the hopeless trial flies every seed.
    st.prune = {"none"}
    bad = FakeEngine(lambda sets, seed: False)
    study.enqueue_trial({"lambda": 60.0})
    study.optimize(lambda t: tune._objective(st, study, t, bad, optuna), n_trials=1)
    assert study.trials[2].state == TrialState.COMPLETE and len(bad.flown) == 10
    assert study.trials[2].value == 0.0


def test_secondary_figure_orders_equal_success_counts():
    docs = {"a": {"success": {"type": "goal"}, "timing": {"duration": 20}}}
    fig, b = tune.secondary_bonus("time_to_goal", [{"scenario": "a", "success": True, "time_to_goal": 10.0},
                                                   {"scenario": "a", "success": False, "time_to_goal": None}], docs)
    assert fig == 10.0 and b == pytest.approx(1 / 1.5)
    fig, b = tune.secondary_bonus("min_clearance", [{"scenario": "a", "success": True, "min_clearance": 1.0}], docs)
    assert b == pytest.approx(0.5)
    assert tune.secondary_bonus("time_to_goal", [{"scenario": "a", "success": False}], docs) == (None, 0.0)
    # One more success always beats any secondary figure.
    assert (3 + 0.99 * 1.0) / 10 < (4 + 0.0) / 10
