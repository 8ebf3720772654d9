"""The harness's own parts, without a flight: the sandbox, the flight registry, the command
lines each plant's flight builds (ArduCopter SITL's without its binary), the campaign
results loader, the CLI's subcommands, and the package's shape (no module imports one that
imports it back; every function of the project's Python reads in one screen)."""
from __future__ import annotations

import ast
import json
import signal
import time
from pathlib import Path

import pytest

from sitl_helpers import ROOT, fake_ardupilot, group_members, pid_alive
from sitl_harness import cli, paths
from sitl_harness.flights import PLANTS, flight_class
from sitl_harness.flights.ardupilot import BASELINE, HOME, OVERLAY, PARAMS, VEHICLE, ArduPilotFlight
from sitl_harness.flights.base import FlightError, FlightSpec
from sitl_harness.flights.px4 import Px4Flight
from sitl_harness.flights.sim import SimFlight
from sitl_harness.overlay import load_sets
from sitl_harness.results import load_campaign, write_campaign
from sitl_harness.sandbox import Sandbox, SandboxError, fifo_allowed

HARNESS = ROOT / "tools" / "sitl_harness"


# ---- the sandbox -----------------------------------------------------------------------------
def test_sandbox_stops_everything_in_its_namespace(tmp_path):
    sb = Sandbox(tmp_path)
    sb.start_namespace()
    try:
        sb.spawn("a", ["sleep", "60"])
        sb.spawn("logger", ["sh", "-c", "echo hello; exec sleep 60"])
        # A process the sandbox does not know of, in the group: the killpg reaches it.
        sb.spawn("parent", ["sh", "-c", "sleep 60 & wait"])
        # In the private namespace: only lo.
        sb.spawn("links", ["ip", "-o", "link"])
        sb.procs["links"].wait(timeout=10)
        pids = sb.pids()
    finally:
        sb.stop(last="logger")
    assert pids["pgid"] == pids["holder"]
    for name in ("a", "logger", "parent", "holder"):
        assert not pid_alive(pids[name]), name
    assert group_members(pids["pgid"]) == []
    assert (tmp_path / "logger.log").read_text() == "hello\n"
    links = (tmp_path / "links.log").read_text().splitlines()
    assert len(links) == 1 and ": lo:" in links[0], links
    sb.stop(last="logger")  # twice is safe


def test_sandbox_without_a_namespace_continues_a_stopped_process_to_end_it(tmp_path):
    """The soak's use: children in the caller's namespace; one SIGSTOPped (the simulator
    under a sim_stop fault) still ends on terminate, at its SIGTERM, not after the grace."""
    sb = Sandbox(tmp_path, deathsig=signal.SIGKILL, any_thread=True)
    p = sb.spawn("sim", ["sleep", "60"])
    assert sb.pgid is None and sb.returncode("sim") is None
    p.send_signal(signal.SIGSTOP)
    t0 = time.monotonic()
    sb.terminate("sim", 5.0)
    assert p.returncode == -signal.SIGTERM
    assert time.monotonic() - t0 < 4.0
    sb.spawn("sim", ["sh", "-c", "echo again"]).wait(timeout=10)
    sb.stop()
    assert (tmp_path / "sim.log").read_text() == "again\n"  # a restart appends to the same log


def test_sandbox_wait_ready_names_the_log_of_a_helper_that_died(tmp_path):
    sb = Sandbox(tmp_path)
    sb.spawn("inject", ["sh", "-c", "echo starting; exit 3"])
    with pytest.raises(SandboxError, match=r"inject exited at start \(rc=3\); see inject.log"):
        sb.wait_ready("inject", 10.0)
    sb.spawn("recorder", ["sh", "-c", "echo '{\"event\": \"ready\"}'; exec sleep 60"])
    sb.wait_ready("recorder", 10.0)
    sb.stop()
    assert sb.procs["recorder"].returncode == -signal.SIGTERM


# ---- the flights ---------------------------------------------------------------------------
def test_every_plant_has_its_flight_class():
    assert set(PLANTS) == {"sim", "ardupilot", "px4"}
    assert flight_class("sim") is SimFlight and flight_class("ardupilot") is ArduPilotFlight
    assert flight_class("px4") is Px4Flight
    with pytest.raises(KeyError, match="gazebo.*known: sim, ardupilot, px4"):
        flight_class("gazebo")


def test_ardupilot_flight_needs_its_binary(tmp_path, monkeypatch):
    monkeypatch.delenv("MPPID_ARDUPILOT_BIN", raising=False)
    with pytest.raises(FlightError, match="no ArduCopter SITL binary: build ArduCopter SITL"):
        ArduPilotFlight.create(FlightSpec(scenario="hover", autopilot="ardupilot"))
    with pytest.raises(FlightError, match="does not exist or is not executable"):
        ArduPilotFlight.create(FlightSpec(scenario="hover", autopilot="ardupilot",
                                          ardupilot_bin=str(tmp_path / "nothing")))


def test_ardupilot_guided_flight_commands(tmp_path):
    binary = fake_ardupilot(tmp_path)
    spec = FlightSpec(scenario="circle_1ms", seed=53, out=tmp_path / "out", controller="guided", realtime=True,
                      autopilot="ardupilot", ardupilot_bin=str(binary), lcm_url="udpm://239.255.76.67:7701?ttl=0")
    flight = flight_class("ardupilot").create(spec)
    flight.out.mkdir(parents=True)
    plan = flight.plan()
    cmds = plan.commands
    assert set(cmds) == {"logger", "sim", "recorder", "mission"}
    sim = cmds["sim"][cmds["sim"].index("sh"):]
    assert sim[3] == str(binary.resolve())
    assert sim[sim.index("--defaults") + 1] == f"{binary.parents[3].resolve()}/Tools/autotest/default_params/" \
                                               f"copter.parm,{PARAMS},{BASELINE}"
    assert sim[sim.index("--home") + 1] == HOME and sim[-2:] == ["-I0", "--wipe"]
    assert cmds["recorder"][1:] == ["-m", "sitl_harness.ap_truth", "--url", "tcp:127.0.0.1:5762", f"--home={HOME}",
                                    "--out", str(flight.out)]
    assert cmds["mission"][1:] == ["-m", "mppi_mission", "fly", str(paths.MISSIONS / "circle_1ms.yaml"), "--seed",
                                   "53", "--out", str(flight.out), "--lcm-url", spec.lcm_url, "--guided",
                                   "tcp:127.0.0.1:5760"]
    assert cmds["logger"][-1] == str(flight.out / "flight.lcmlog")
    assert plan.wall_timeout == 240.0
    assert plan.record["spec"] == {"scenario": "circle_1ms", "seed": 53, "controller": "guided", "realtime": True,
                                   "lcm_url": spec.lcm_url}
    with pytest.raises(FlightError, match="is not a mission"):
        ArduPilotFlight(FlightSpec(scenario="forest_4m", out=tmp_path / "o2"), binary).plan()


def option(argv: list[str], name: str) -> str:
    return argv[argv.index(name) + 1]


def test_ardupilot_mppid_flight_commands(mppid_binary, tmp_path):
    binary = fake_ardupilot(tmp_path)
    vehicle = tmp_path / "fitted.yaml"
    spec = FlightSpec(scenario="circle_1ms", seed=51, out=tmp_path / "out", realtime=True, autopilot="ardupilot",
                      ardupilot_bin=str(binary), sets=["mppi.lambda=7", f"vehicle={vehicle}"])
    flight = ArduPilotFlight.create(spec)
    flight.out.mkdir(parents=True)
    cmds = flight.plan().commands
    assert set(cmds) == {"logger", "sim", "recorder", "controller", "bridge", "mission"}
    ctrl = cmds["controller"]
    assert ctrl[0] == str(mppid_binary)
    assert ctrl[ctrl.index("--config") + 1] == str(paths.TASKS / "quadrotor_rate_track.yaml")
    assert ctrl[ctrl.index("--vehicle") + 1] == str(vehicle)   # --set vehicle= replaces the airframe
    sets = [ctrl[i + 1] for i, c in enumerate(ctrl) if c == "--set"]
    assert sets == ["mppi.seed=51"] + load_sets(OVERLAY) + ["mppi.lambda=7"]
    bridge = cmds["bridge"]
    sock = flight.out / "bridge.sock"
    assert bridge[bridge.index("-m") + 1:bridge.index("-m") + 3] == ["mppi_mavlink", "run"]
    assert option(bridge, "--config") == str(paths.ROOT / "config/bridge/ardupilot_sitl.yaml")
    assert option(bridge, "--lcm-url") == spec.lcm_url
    bridge_sets = dict(bridge[i + 1].split("=", 1) for i, c in enumerate(bridge) if c == "--set")
    assert bridge_sets == {"control.socket": str(sock), "vehicle.file": str(vehicle),   # mppid's airframe
                           "trace.file": str(sock.parent / "bridge_trace.jsonl")}      # the stage times (docs/latency.md)
    # As its unit runs it where SCHED_FIFO is allowed: its latency threads above mppid's loop, once started.
    assert "chrt" not in bridge
    assert (int(option(bridge, "--realtime")) > 80) if fifo_allowed() else "--realtime" not in bridge
    assert cmds["mission"][-2:] == ["--bridge", str(sock)]
    default = ArduPilotFlight.create(FlightSpec(scenario="hover", out=tmp_path / "o3", realtime=True,
                                                autopilot="ardupilot", ardupilot_bin=str(binary)))
    default.out.mkdir(parents=True)
    ctrl = default.plan().commands["controller"]
    assert ctrl[ctrl.index("--vehicle") + 1] == str(VEHICLE)


def test_sim_flight_commands(mppid_binary, tmp_path):
    spec = FlightSpec(scenario="forest_4m", seed=7, out=tmp_path, latency=0.012, sets=["mppi.lambda=9"],
                      params=["2:mppi.rollouts=512"], view=True)
    plan = SimFlight(spec).plan()
    cmds = plan.commands
    ctrl = cmds["controller"][cmds["controller"].index(str(mppid_binary)):]
    assert ctrl[1:5] == ["--config", str(paths.TASKS / "quadrotor_forest.yaml"), "--lcm-url", spec.lcm_url]
    assert "--lockstep" in ctrl and ctrl[ctrl.index("--backend") + 1] == "cpu"
    sets = [ctrl[i + 1] for i, c in enumerate(ctrl) if c == "--set"]
    assert sets == ["daemon.latency.floor_ms=12", "daemon.latency.ceiling_ms=12", "daemon.work.enabled=false",
                    "mppi.seed=7", "daemon.rollouts.hz=5", "daemon.rollouts.top=16", "daemon.rollouts.random=16",
                    "mppi.lambda=9"]
    sim = cmds["sim"][cmds["sim"].index("--scenario") - 1:]
    assert sim[1:] == ["--scenario", str(paths.SCENARIOS / "forest_4m.yaml"), "--seed", "7", "--lcm-url",
                       spec.lcm_url, "--out", str(tmp_path), "--lockstep", "--latency", "0.012"]
    assert cmds["inject"][-4:] == ["--lcm-url", spec.lcm_url, "--at", "2:mppi.rollouts=512"]
    assert plan.record["controller_config"] == str(paths.TASKS / "quadrotor_forest.yaml")
    assert list(plan.record["commands"]) == ["sim", "controller", "logger", "inject"]
    rt = SimFlight(FlightSpec(scenario="forest_4m", out=tmp_path, realtime=True, controller="standin")).plan()
    assert rt.commands["sim"][-1] == "--realtime" and "sitl_harness.standin" in rt.commands["controller"]
    assert rt.record["controller_config"] is None and rt.wall_timeout > 0


# ---- campaign results ------------------------------------------------------------------------
def test_campaign_results_one_loader(tmp_path):
    with pytest.raises(FileNotFoundError, match="no summary.json"):
        load_campaign(tmp_path)
    runs = [{"scenario": "b", "seed": 2}, {"scenario": "a", "seed": 9}, {"scenario": "b", "seed": 1}]
    write_campaign(tmp_path, {"seeds": [1, 2, 9]}, runs)
    res = load_campaign(tmp_path)
    assert [(r["scenario"], r["seed"]) for r in res.runs] == [("a", 9), ("b", 1), ("b", 2)]
    assert res.summary == {"seeds": [1, 2, 9]}
    assert list(res.by_scenario()) == ["a", "b"] and len(res.by_scenario()["b"]) == 2
    assert res.by_key()[("b", 1)] is res.runs[1]
    assert res.flight_folder("b", 1) == tmp_path / "b" / "seed_0001"
    assert json.loads((tmp_path / "summary.json").read_text())["runs"][0]["scenario"] == "a"


# ---- the CLI -------------------------------------------------------------------------------
def test_every_subcommand_has_its_function():
    sub = next(a for a in cli.build_parser()._actions if a.dest == "cmd")
    names = {"list", "run", "campaign", "compare", "table", "versus", "autopilot-table", "robustness", "overlay",
             "tune", "plot", "speed-curve", "refusals"}
    assert set(sub.choices) == names
    for name, p in sub.choices.items():
        assert p.get_default("func") is getattr(cli, "cmd_" + name.replace("-", "_")), name


def test_cli_usage_errors_exit_2(capsys, tmp_path):
    assert cli.main(["run", "--scenario", "forest_4m", "--realtime", "--latency", "0.01"]) == 2
    assert "sitl: --ideal and --latency are lock-step options" in capsys.readouterr().err
    assert cli.main(["run", "--scenario", "no_such_scenario"]) == 2
    assert "sitl: no scenario or mission 'no_such_scenario'" in capsys.readouterr().err
    assert cli.main(["campaign", "--scenarios", "forest_4m", "--out", str(tmp_path), "--controller", "guided"]) == 2
    assert "it needs --autopilot ardupilot" in capsys.readouterr().err
    assert cli.main(["table", str(tmp_path)]) == 2
    assert "no summary.json (not a finished campaign)" in capsys.readouterr().err
    overlay = tmp_path / "o.yaml"
    overlay.write_text("mppi: {lambda: 40.0}\n")
    assert cli.main(["overlay", str(overlay)]) == 0
    assert capsys.readouterr().out.strip() == "--set mppi.lambda=40.0"


# ---- the package's shape ---------------------------------------------------------------------
def _modules():
    for f in sorted(HARNESS.rglob("*.py")):
        parts = f.relative_to(HARNESS.parent).with_suffix("").parts
        yield ".".join(parts[:-1] if parts[-1] == "__init__" else parts), f


def _imports(name: str, f: Path, known: set) -> set:
    """The harness modules `name` imports, at module level or inside its functions."""
    pkg = name.split(".") if f.name == "__init__.py" else name.split(".")[:-1]
    out = set()
    for n in ast.walk(ast.parse(f.read_text())):
        if isinstance(n, ast.ImportFrom):
            base = ".".join(pkg[:len(pkg) - n.level + 1] + ([n.module] if n.module else [])) if n.level else n.module
            for a in n.names:
                out.add(f"{base}.{a.name}" if f"{base}.{a.name}" in known else base)
        elif isinstance(n, ast.Import):
            out |= {a.name for a in n.names}
    return (out & known) - {name}


def test_no_two_harness_modules_import_each_other():
    mods = dict(_modules())
    graph = {m: _imports(m, f, set(mods)) for m, f in mods.items()}
    mutual = sorted({tuple(sorted((a, b))) for a in graph for b in graph[a] if a in graph[b]})
    assert mutual == []
    # No longer cycles either: a module never reaches itself.
    for start in graph:
        seen, todo = set(), list(graph[start])
        while todo:
            m = todo.pop()
            assert m != start, f"{start} imports itself through others"
            if m not in seen:
                seen.add(m)
                todo += graph[m]


def _python_sources():
    """The project's own Python in drivers/, sim/ and tools/ (the harness among them)."""
    for top in ("drivers", "sim", "tools"):
        for f in sorted((ROOT / top).rglob("*.py")):
            if not {"__pycache__", "build"} & set(f.relative_to(ROOT).parts):
                yield f


def test_every_function_reads_in_one_screen():
    """No function in drivers/, sim/ or tools/ over 60 lines (def to its last line)."""
    sources = list(_python_sources())
    assert HARNESS / "cli.py" in sources and ROOT / "tools" / "soak.py" in sources
    long = []
    for f in sources:
        for n in ast.walk(ast.parse(f.read_text())):
            if isinstance(n, (ast.FunctionDef, ast.AsyncFunctionDef)) and n.end_lineno - n.lineno + 1 > 60:
                long.append(f"{f.relative_to(ROOT)}:{n.lineno} {n.name} ({n.end_lineno - n.lineno + 1} lines)")
    assert long == []


def test_no_sys_path_edits():
    hits = [f"{f.relative_to(ROOT)}" for f in sorted(HARNESS.rglob("*.py")) + [ROOT / "tools" / "soak.py"]
            if "sys.path" in f.read_text() or "PYTHONPATH" in f.read_text()]
    assert hits == []
