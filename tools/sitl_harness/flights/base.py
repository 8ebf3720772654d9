"""What every flight shares, whatever its plant: the spec a flight is flown from, its
sandbox (sandbox.py: the private network namespace, its processes, the clean-up), the
lcm-logger recording its bus, and the course of a run (start, watch, stop, record).

A plant's flight (flights/sim.py, flights/ardupilot.py) says which processes to start with
which command lines (plan), how to start them (start) and when the flight is over (watch),
and how its result folder is scored and plotted (score, plot)."""
from __future__ import annotations

import json
import os
import re
import time
from dataclasses import dataclass, field
from pathlib import Path

from .. import paths
from ..sandbox import Sandbox, SandboxError

LCM_URL = "udpm://239.255.76.67:7667?ttl=0"
# A lock-step flight bursts thousands of datagrams a second; the logger must not drop any
# while the CPU is busy (the kernel caps this at net.core.rmem_max).
LOGGER_RECV_BUF = 4 * 1024 * 1024
SIM_FIFO_PRIORITY = 90
# The recorder above everything of the flight (its work per datagram is a copy): at 79, below
# the daemon and the simulator, a lock-step flight beside another flight on the same two cores
# lost bursts of 11-14 states and their commands from its log in 3 of 4 runs, and a replay or a
# determinism check of that log then failed; at 95, none in 4.
LOGGER_FIFO_PRIORITY = 95


class FlightError(RuntimeError):
    pass


@dataclass
class FlightSpec:
    scenario: str
    seed: int = 1
    out: Path = Path("results/run")
    backend: str = "cpu"
    realtime: bool = False
    ideal: bool = False              # lock-step without charging the controller's latency
    latency: float | None = None     # lock-step: charge this fixed latency [s] (and tell mppid)
    controller: str = "mppid"        # mppid | ddp (the MPC-DDP baseline) | standin | guided | px4 (autopilots' own)
    wall_timeout: float = 0.0        # 0: from the scenario's duration
    sets: list[str] = field(default_factory=list)  # extra --set key=value for mppid
    kill_controller_after: float = 0.0  # tests: SIGKILL the controller after this many seconds
    lcm_url: str = LCM_URL           # the flight's bus (inside its own network namespace)
    plots: bool = True               # path.png, traces.png, timing.png (tuning skips them)
    params: list[str] = field(default_factory=list)  # "T:KEY=VALUE": parameter updates in flight (inject.py)
    autopilot: str = "sim"           # the plant: a name of flights.PLANTS (sim, ardupilot, px4)
    ardupilot_bin: str | None = None  # the SITL binary (else $MPPID_ARDUPILOT_BIN)
    px4_bin: str | None = None       # PX4 SITL's bin/px4 (px4_sitl_sih; else $MPPID_PX4_BIN)
    faults: list[str] = field(default_factory=list)  # PX4: ACTION@T after the first path leg (px4_faults.py)
    autopilot_params: list[str] = field(default_factory=list)  # PX4: NAME=VALUE over config/px4's files
    view: bool = False               # the live 3D view (tools/view) of the flight, rollouts on; flight.rrd
    view_hold: float = 0.0           # ... kept serving this long after the flight [s]
    view_wait: float = 0.0           # ... up this long before the flight starts (open the page) [s]
    view_port: int = 9090            # ... its web viewer's port; its gRPC server's is this + VIEW_GRPC_OFFSET
    rrd: bool = False                # flight.rrd: the LCM log converted for rerun's viewer


@dataclass
class Plan:
    """A flight's processes before they start: their command lines, by name, and what
    harness.json records besides them."""
    commands: dict[str, list[str]]
    wall_timeout: float
    record: dict = field(default_factory=dict)


def lcm_url_for_port(port: int) -> str:
    """The flight bus on another UDP port (each campaign flight gets its own)."""
    if not 1024 <= int(port) <= 65535:
        raise ValueError(f"LCM port {port} outside 1024-65535")
    return f"udpm://239.255.76.67:{int(port)}?ttl=0"


def sensor_bus(lcm_url: str) -> str:
    """The sensors' own bus: the flight's URL on the next UDP port (each flight has its own
    network namespace), so the controller's socket never receives the frames; a receive buffer
    that holds a few of them (the kernel caps it at net.core.rmem_max)."""
    m = re.match(r"^(udpm://[^:]+):(\d+)(\?.*)?$", lcm_url)
    if m is None:
        raise ValueError(f"cannot derive the sensor bus from the LCM URL {lcm_url}")
    port = int(m.group(2))
    port = port + 1 if port < 65535 else port - 1
    query = (m.group(3) or "?ttl=0") + f"&recv_buf_size={LOGGER_RECV_BUF}"
    return f"{m.group(1)}:{port}{query}"


def lcm_logger() -> Path:
    """The lcm-logger binary itself: the venv's entry point is a Python wrapper that would
    run it as a grandchild (and leave it behind on SIGTERM)."""
    try:
        import lcm
        p = Path(lcm.LCM_BIN_DIR) / "lcm-logger"
        if p.is_file():
            return p
    except (ImportError, AttributeError):
        pass
    return paths.VENV_BIN / "lcm-logger"


def logger_command(spec: FlightSpec, out: Path, exclude: tuple[str, ...] = ()) -> list[str]:
    """lcm-logger recording the flight's bus into OUT/flight.lcmlog, but the channels named in
    `exclude` (LCM's channel patterns are PCRE: a negative look-ahead leaves them out)."""
    cmd = [str(lcm_logger()), "-q", "-f", f"--lcm-url={spec.lcm_url}&recv_buf_size={LOGGER_RECV_BUF}"]
    if exclude:
        cmd.append("--channel=^(?!(" + "|".join(exclude) + ")$).*")
    return cmd + [str(out / "flight.lcmlog")]


def autopilot_binary(explicit: str | None, env: str, what: str, hint: str) -> Path:
    """An autopilot's SITL binary, built outside this repository: `explicit` (the command
    line's), else $env; a FlightError with `hint` (how to build it) when missing."""
    b = explicit or os.environ.get(env)
    if not b:
        raise FlightError(f"no {what} binary: {hint}")
    p = Path(b).expanduser().resolve()
    if not (p.is_file() and os.access(p, os.X_OK)):
        raise FlightError(f"{what} binary {p} does not exist or is not executable: {hint}")
    return p


def load_mission(spec: FlightSpec, autopilot: str) -> tuple[Path, dict]:
    """The mission file a flight through an autopilot flies (config/missions/*.yaml), and its
    contents; a scenario that is not a mission is a FlightError."""
    import yaml
    path = paths.scenario_path(spec.scenario)
    mission = yaml.safe_load(path.read_text())
    if "legs" not in mission:
        raise FlightError(f"{path} is not a mission (config/missions/*.yaml): --autopilot {autopilot} flies missions")
    return path, mission


def autopilot_plan(spec: FlightSpec, mission: dict, cmds: dict, record: dict) -> Plan:
    """An autopilot flight's plan: the mission's wall-clock limit and the record's common part."""
    record.update(commands=cmds, spec={"scenario": spec.scenario, "seed": spec.seed, "controller": spec.controller,
                                       "realtime": True, "lcm_url": spec.lcm_url})
    return Plan(commands=cmds, wall_timeout=spec.wall_timeout or float(mission.get("wall_timeout", 240.0)),
                record=record)


def mppid_binary() -> Path:
    mppid = paths.find_binary("mppid")
    if mppid is None:
        raise FlightError("mppid not built (searched %s)" % ", ".join(map(str, paths.build_dirs())))
    return mppid


class Flight:
    """One flight: plan() its command lines, then run() flies them in a sandbox."""

    def __init__(self, spec: FlightSpec):
        self.spec = spec
        self.out = Path(spec.out).resolve()
        self.sandbox = Sandbox(self.out)
        self.events: list[str] = []

    @classmethod
    def create(cls, spec: FlightSpec) -> "Flight":
        """The flight of `spec`; raises FlightError when it cannot be flown here (a binary missing)."""
        return cls(spec)

    # ---- what a plant's flight says ------------------------------------------------------
    def plan(self) -> Plan:
        raise NotImplementedError

    def start(self, plan: Plan) -> None:
        raise NotImplementedError

    def watch(self, plan: Plan, t0: float) -> str | None:
        """Until the flight is over: None when it ended as it should, else why not."""
        raise NotImplementedError

    def score(self, info: dict) -> dict:
        raise NotImplementedError

    def plot(self) -> list:
        raise NotImplementedError

    # ---- the course of a run -------------------------------------------------------------
    def run(self) -> dict:
        self.out.mkdir(parents=True, exist_ok=True)
        plan = self.plan()
        t0 = time.monotonic()
        outcome = None
        try:
            self.sandbox.start_namespace()
            self.start(plan)
            outcome = self.watch(plan, t0)
        except SandboxError as e:
            raise FlightError(str(e)) from None
        except KeyboardInterrupt:
            outcome = "interrupted"
            self.events.append("interrupted (Ctrl-C / SIGTERM)")
            raise
        finally:
            self.cleanup()
            info = self._record(t0, outcome, plan.record)
        return info

    def cleanup(self):
        """Stops everything, the logger last (it records the others' last messages)."""
        self.sandbox.stop(last="logger")

    def exited(self, name: str) -> bool:
        return self.sandbox.returncode(name) is not None

    def returncode(self, name: str) -> int | None:
        return self.sandbox.returncode(name)

    def _record(self, t0: float, outcome, extra: dict) -> dict:
        """harness.json: how the flight ended, its processes' exit codes and events, and `extra`."""
        info = {"harness_outcome": outcome, "wall_s": time.monotonic() - t0,
                "niceness": os.getpriority(os.PRIO_PROCESS, 0),
                "returncodes": {k: p.returncode for k, p in self.sandbox.procs.items()}, "events": self.events,
                **extra}
        (self.out / "harness.json").write_text(json.dumps(info, indent=2, default=str))
        return info
