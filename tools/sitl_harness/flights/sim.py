"""A flight of mppid-sim, the project's simulator (sim/README.md): lcm-logger, the controller
(mppid, its MPC-DDP baseline, or the hover stand-in), then the simulator, in lock-step or in
real time, with the optional parameter injector (inject.py) and mission tool; scored from
the simulator's truth (score.py) and plotted (plots.py)."""
from __future__ import annotations

import json
import sys
import time
from pathlib import Path

import yaml

from .. import paths
from ..sandbox import fifo_allowed
from .base import (LOGGER_FIFO_PRIORITY, LOGGER_RECV_BUF, SIM_FIFO_PRIORITY, Flight, FlightError, FlightSpec, Plan,
                   logger_command, mppid_binary, sensor_bus)
from .view import FlightView, view_sets

INJECT_READY_TIMEOUT_S = 30.0  # the injector imports lcm and subscribes (seconds under load)
# What a sensed flight's log leaves out by default: the raw frames (a depth camera's are ~0.3 MB
# at 30 Hz) and the maps (1 MB at 10 Hz: 300 MB a 30-s flight). mapper.log_maps: true keeps the
# maps (tools/replay needs them); sensed.jsonl and mapper_stats.json say what was sensed.
SENSOR_CHANNELS = ("MPPI_DEPTH", "MPPI_LIDAR")
MAP_CHANNEL = "MPPI_LOCAL_MAP"
MAPPER_FIFO_PRIORITY = 70  # below the daemon (80) and the logger (79)


def sensed(scen: dict) -> bool:
    """The scenario has a sensor on (sensing.depth_camera or sensing.lidar, not enabled: false)."""
    sensing = scen.get("sensing") or {}
    return any(isinstance(sensing.get(k), dict) and sensing[k].get("enabled", True) for k in ("depth_camera", "lidar"))


def mapper_command(spec: FlightSpec, scen: dict, out: Path) -> list[str]:
    """mppid-mapper for a sensed flight: the scenario's mapper.config (default
    config/mapper/mapper.yaml) and mapper.set overrides; its timings and what it sensed into OUT."""
    exe = paths.find_binary("mppid-mapper")
    if exe is None:
        raise FlightError("mppid-mapper not built (searched %s)" % ", ".join(map(str, paths.build_dirs())))
    mp = scen.get("mapper") or {}
    cfg = paths.ROOT / mp.get("config", "config/mapper/mapper.yaml")
    if not cfg.is_file():
        raise FlightError(f"scenario {spec.scenario} names mapper config {cfg}, which does not exist")
    cmd = [str(exe), "--config", str(cfg), "--lcm-url", f"{spec.lcm_url}&recv_buf_size={LOGGER_RECV_BUF}",
           "--sensor-lcm-url", sensor_bus(spec.lcm_url), "--stats", str(out / "mapper_stats.json"),
           "--sensed", str(out / "sensed.jsonl")]
    for kv in mp.get("set", []):
        cmd += ["--set", str(kv)]
    return cmd


def log_exclusions(scen: dict) -> tuple[str, ...]:
    if not sensed(scen):
        return ()
    keep_maps = bool((scen.get("mapper") or {}).get("log_maps", False))
    return SENSOR_CHANNELS + (() if keep_maps else (MAP_CHANNEL,))


def controller_config(spec: FlightSpec, scen: dict) -> Path:
    """The scenario names its controller config (config/tasks/<task>.yaml), optionally
    another file (mppid.config) and overrides (mppid.set: ["mppi.lambda=10", ...])."""
    mp = scen.get("mppid") or {}
    cfg = paths.ROOT / mp["config"] if mp.get("config") else paths.TASKS / f"{scen['task']}.yaml"
    if not cfg.is_file():
        raise FlightError(f"scenario {spec.scenario} names controller config {cfg}, which does not exist")
    return cfg


def mppid_command(spec: FlightSpec, scen: dict, cfg: Path, fifo: bool) -> list[str]:
    """mppid (or its DDP baseline) for a flight of the scenario `scen`."""
    lockstep = not spec.realtime
    # A sensed flight's maps are 1 MB (local_map_t): a socket buffer that holds a few of them.
    url = f"{spec.lcm_url}&recv_buf_size={LOGGER_RECV_BUF}" if sensed(scen) else spec.lcm_url
    cmd = [str(mppid_binary()), "--config", str(cfg), "--lcm-url", url]
    # As the systemd unit runs it (SCHED_FIFO, locked memory; it runs on with a
    # warning where the OS refuses), in lock-step too: there its measured latency is
    # what the simulator charges, and it must be the service's, not a busy machine's.
    if fifo:
        cmd.append("--realtime")
    if lockstep:
        cmd.append("--lockstep")
        if spec.latency is not None:
            # The controller is told the fixed latency charged, and runs mppi.rollouts (its work
            # not sized from measured compute times): the run repeats exactly.
            ms = f"{1e3 * spec.latency:g}"
            cmd += ["--set", f"daemon.latency.floor_ms={ms}", "--set", f"daemon.latency.ceiling_ms={ms}",
                    "--set", "daemon.work.enabled=false"]
    cmd += ["--backend", spec.backend]
    if spec.controller == "ddp":
        cmd += ["--controller", "ddp"]
    # The flight's seed also seeds the controller's sampling (a campaign over seeds
    # varies both the world and the noise); --set can still override it.
    cmd += ["--set", f"mppi.seed={spec.seed}"]
    for kv in list((scen.get("mppid") or {}).get("set", [])) + view_sets(spec) + list(spec.sets):
        cmd += ["--set", str(kv)]
    return cmd


def sim_command(spec: FlightSpec, scen_path: Path, out: Path, sim_bin: Path, scen: dict | None = None) -> list[str]:
    lockstep = not spec.realtime
    cmd = [str(sim_bin), "--scenario", str(scen_path), "--seed", str(spec.seed), "--lcm-url", spec.lcm_url,
           "--out", str(out), "--lockstep" if lockstep else "--realtime"]
    if scen is not None and sensed(scen):
        cmd += ["--sensor-lcm-url", sensor_bus(spec.lcm_url)]
    if lockstep and spec.ideal:
        cmd.append("--ideal")
    elif lockstep and spec.latency is not None:
        cmd += ["--latency", f"{spec.latency:g}"]
    return cmd


def inject_command(spec: FlightSpec) -> list[str]:
    cmd = [sys.executable, "-m", "sitl_harness.inject", "--lcm-url", spec.lcm_url]
    for u in spec.params:
        cmd += ["--at", str(u)]
    return cmd


def mission_command(spec: FlightSpec, mission: Path, out: Path) -> list[str]:
    """The mission tool (drivers/mission, the package mppi_mission) flying `mission`."""
    return [sys.executable, "-m", "mppi_mission", "fly", str(mission), "--seed", str(spec.seed), "--out", str(out),
            "--lcm-url", spec.lcm_url]


def realtime_priorities(cmds: dict) -> dict:
    """The simulator stands in for the physical world: the controller's CPU load must not
    slow its physics down, nor other load its clock and the latency it measures (the daemon
    runs SCHED_FIFO 80, the simulator above). The logger above both: a lock-step flight runs
    many times faster than real time and a logger starved meanwhile loses datagrams
    (LOGGER_FIFO_PRIORITY says what it lost). The parameter injector as the logger: at the
    normal policy a lock-step flight
    (SCHED_FIFO, both cores) would starve it of every state until the flight ends. The mapper
    below the daemon (its maps feed the next cycles, but never before this one's command) and
    above the machine's other work: at the normal policy, on a loaded 2-core machine, its maps
    left 150-450 ms late (forest_4m_sensed seed 51, load 4-6)."""
    prio = {"sim": SIM_FIFO_PRIORITY, "logger": LOGGER_FIFO_PRIORITY, "inject": LOGGER_FIFO_PRIORITY,
            "mapper": MAPPER_FIFO_PRIORITY}
    return {k: (["chrt", "-f", str(prio[k])] + c if k in prio else c) for k, c in cmds.items()}


class SimFlight(Flight):
    def __init__(self, spec: FlightSpec):
        super().__init__(spec)
        self.view = FlightView(spec, self.sandbox) if spec.view else None

    def plan(self) -> Plan:
        spec = self.spec
        scen_path = paths.scenario_path(spec.scenario)
        scen = yaml.safe_load(scen_path.read_text())
        sim_bin = paths.find_binary("mppid-sim")
        if sim_bin is None:
            raise FlightError("mppid-sim not built (searched %s)" % ", ".join(map(str, paths.build_dirs())))
        duration = float(scen.get("timing", {}).get("duration", 30.0))
        wall_timeout = spec.wall_timeout or (duration * 4 + 60 if not spec.realtime else duration + 30)
        fifo = fifo_allowed()
        cfg = None
        if spec.controller in ("mppid", "ddp"):
            cfg = controller_config(spec, scen)
            ctrl = mppid_command(spec, scen, cfg, fifo)
        else:
            ctrl = [sys.executable, "-m", "sitl_harness.standin", "--scenario", str(scen_path), "--lcm-url",
                    spec.lcm_url]
        cmds = {"sim": sim_command(spec, scen_path, self.out, sim_bin, scen), "controller": ctrl,
                "logger": logger_command(spec, self.out, log_exclusions(scen))}
        if sensed(scen):
            # The trees exist only in the simulator's world: mppid knows what the mapper makes
            # of the sensors (docs/sensing.md).
            cmds["mapper"] = mapper_command(spec, scen, self.out)
        if spec.params:
            cmds["inject"] = inject_command(spec)
        if fifo:
            cmds = realtime_priorities(cmds)
        record = {"commands": cmds, "controller_config": str(cfg) if cfg is not None else None,
                  "spec": {"scenario": spec.scenario, "seed": spec.seed, "backend": spec.backend,
                           "realtime": spec.realtime, "ideal": spec.ideal, "latency": spec.latency,
                           "controller": spec.controller, "lcm_url": spec.lcm_url, "params": spec.params}}
        if scen.get("mission"):
            # The operator's side: the mission tool gives mppid its references (the
            # scenario's own reference is `none`), as on a real vehicle. Not recorded.
            cmds = {**cmds, "mission": mission_command(spec, paths.ROOT / scen["mission"], self.out)}
        return Plan(commands=cmds, wall_timeout=wall_timeout, record=record)

    def start(self, plan: Plan) -> None:
        sb, cmds = self.sandbox, plan.commands
        if self.view is not None:
            self.view.start()
        sb.spawn("logger", cmds["logger"])
        sb.spawn("controller", cmds["controller"])
        if "mapper" in cmds:
            sb.spawn("mapper", cmds["mapper"])
        time.sleep(0.5)  # let them subscribe before the first state
        for name in ("logger", "controller", "mapper"):
            if name not in cmds:
                continue
            if self.exited(name):
                raise FlightError(f"{name} exited at start (rc={self.returncode(name)}); see {name}.log")
        if "inject" in cmds:
            # Parameter updates at set state times, their answers logged (inject.log).
            sb.spawn("inject", cmds["inject"])
            sb.wait_ready("inject", INJECT_READY_TIMEOUT_S)
        sb.spawn("sim", cmds["sim"])
        if "mission" in cmds:
            sb.spawn("mission", cmds["mission"])
        (self.out / "pids.json").write_text(json.dumps(sb.pids()))

    def watch(self, plan: Plan, t0: float) -> str | None:
        """Until the simulator ends; the controller or the logger exiting first, or the
        wall-clock limit, ends the flight as a failure at once."""
        spec, killed = self.spec, False
        while True:
            time.sleep(0.05)
            now = time.monotonic() - t0
            if self.exited("sim"):
                return None
            if spec.kill_controller_after and not killed and now > spec.kill_controller_after:
                self.sandbox.procs["controller"].kill()
                killed = True
                self.events.append(f"controller killed by the harness at {now:.2f} s (test)")
            if self.exited("controller"):
                self.events.append(f"controller exited rc={self.returncode('controller')} at {now:.2f} s")
                return "controller_died"
            if self.exited("logger"):
                return "logger_died"
            if "mapper" in plan.commands and self.exited("mapper"):
                self.events.append(f"mapper exited rc={self.returncode('mapper')} at {now:.2f} s")
                return "mapper_died"
            if now > plan.wall_timeout:
                return "wall_timeout"

    def cleanup(self):
        super().cleanup()
        if self.view is not None:
            self.view.stop()  # after: its hold ends on Ctrl-C / SIGTERM

    def score(self, info: dict) -> dict:
        from .. import score
        return score.score_flight(self.out, self.spec, info)

    def plot(self) -> list:
        from .. import plots
        return plots.plot_flight(self.out)
