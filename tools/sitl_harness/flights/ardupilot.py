"""A flight through a real autopilot: ArduCopter SITL, built from ArduPilot's source, in
place of mppid-sim. In real time (ArduPilot's SITL runs on the wall clock), in the flight's
private network namespace (sandbox.py), one process each:

    arducopter (SITL)  serial 0 tcp:5760 <- mppid-mavlink-bridge (config/bridge/ardupilot_sitl.yaml)
                       serial 1 tcp:5762 <- ap_truth.py, the referee (SIM_STATE: the simulated truth)
    mppid (the mission's task, --realtime) <-> LCM <-> the bridge
    mppid-mission fly <mission> --bridge <socket>: arm, the autopilot's take-off, `offboard`, the
                       legs (references and virtual trees to mppid), land
    lcm-logger

A sensed mission (`sensing:` with publish_obstacles: false, config/missions/rate_forest_sensed.yaml)
adds the simulator's sensors and the mapper (sensed.py): the referee also publishes the SITL's
truth on the sensors' bus, mppid-sensors ray-casts the mission's trees (which the mission tool
sends to it, not to mppid) from it, and mppid-mapper's map is all mppid knows of them.

`--controller guided` flies the same mission with ArduCopter's own GUIDED position controller
(the mission tool on serial 0 with --guided; no mppid, no bridge): the baseline.

The autopilot's parameters: ArduPilot's SITL defaults for a copter
(<ardupilot>/Tools/autotest/default_params/copter.parm), then config/ardupilot/copter_mppid.parm
and guided_baseline.parm (each argued there line by line). A fresh EEPROM every flight (--wipe), so flights do not inherit
each other's learnt hover thrust.
"""
from __future__ import annotations

import sys
import time
from pathlib import Path


from .. import paths
from ..overlay import load_sets
from ..sandbox import fifo_allowed
from . import sensed as sensed_mod
from .base import (SIM_FIFO_PRIORITY, Flight, FlightError, FlightSpec, Plan, autopilot_binary, autopilot_plan,
                   load_mission, logger_command, mppid_binary)

# ArduPilot's SITL home (Canberra Model Aircraft Club, the autotest default): lat, lon, alt AMSL, heading.
HOME = "-35.363261,149.165230,584,353"
PARAMS = paths.ROOT / "config" / "ardupilot" / "copter_mppid.parm"
# The GUIDED baseline's position-controller tuning (argued in the file): loaded for every flight,
# mppid's too, so both controllers take off and are scored on the same vehicle.
BASELINE = paths.ROOT / "config" / "ardupilot" / "guided_baseline.parm"
# The autopilot's own avoidance for `--controller auto` (a survey flown in AUTO with BendyRuler,
# the mapper's map through the bridge's OBSTACLE_DISTANCE): argued in the file.
BENDYRULER = paths.ROOT / "config" / "ardupilot" / "bendyruler.parm"
AUTO_START = paths.ROOT / "config" / "ardupilot" / "auto_start.parm"  # the ground station starts AUTO
LOITER_AVOID = paths.ROOT / "config" / "ardupilot" / "loiter_avoid.parm"  # --controller loiter
LOITER_PUSH_S = 12.0  # the pitch stick held forward in Loiter (--controller loiter)
GCS_URL = "tcp:127.0.0.1:5763"  # the SITL's third serial port: the ground station's
BRIDGE_CONFIG = paths.ROOT / "config" / "bridge" / "ardupilot_sitl.yaml"
IO_FIFO_PRIORITY = 85   # the bridge's latency path, as its unit runs it (above mppid's 80)
# mppid's settings through ArduCopter, over the task file (argued there), then the mission's
# own (its `mppid.set`), then --set.
OVERLAY = paths.ROOT / "config" / "ardupilot" / "mppid_overlay.yaml"
# The airframe both mppid and the bridge are given; `--set vehicle=FILE` (e.g. one tools/sysid
# identified) replaces it for both.
VEHICLE = paths.ROOT / "config" / "vehicles" / "arducopter_sitl.yaml"
BUILD_HINT = ("build ArduCopter SITL from an ArduPilot checkout, outside this repository, as ArduPilot's "
              "documentation says (docs/ardupilot.md names the build flown here), then pass "
              "--ardupilot-bin <checkout>/build/sitl/bin/arducopter or set MPPID_ARDUPILOT_BIN")


def ardupilot_binary(explicit: str | None = None) -> Path:
    return autopilot_binary(explicit, "MPPID_ARDUPILOT_BIN", "ArduCopter SITL", BUILD_HINT)


def ardupilot_defaults(binary: Path) -> Path:
    """ArduPilot's own SITL defaults for a copter, in the checkout the binary was built in."""
    p = binary.parents[3] / "Tools" / "autotest" / "default_params" / "copter.parm"
    if not p.is_file():
        raise FlightError(f"{p} not found: the binary should be <ardupilot checkout>/build/sitl/bin/arducopter")
    return p


def sitl_command(binary: Path, ap_dir: Path, fifo: bool, extra_params: tuple = ()) -> list[str]:
    """The SITL in its own folder (EEPROM, dataflash logs); the world, above the controller."""
    defaults = ",".join(map(str, (ardupilot_defaults(binary), PARAMS, BASELINE) + tuple(extra_params)))
    sim = ["sh", "-c", f'cd "{ap_dir}" && exec "$0" "$@"', str(binary), "--model", "quad", "--speedup", "1",
           "--home", HOME, "--defaults", defaults, "-I0", "--wipe"]
    if fifo:
        sim = ["chrt", "-f", str(SIM_FIFO_PRIORITY)] + sim
    return sim


def mission_command(spec: FlightSpec, mission_path: Path, out: Path) -> list[str]:
    return [sys.executable, "-m", "mppi_mission", "fly", str(mission_path), "--seed", str(spec.seed), "--out",
            str(out), "--lcm-url", spec.lcm_url]


def mppid_and_bridge(spec: FlightSpec, mission: dict, out: Path, fifo: bool, bridge_config: Path = BRIDGE_CONFIG,
                     vehicle: Path = VEHICLE, overlay: Path = OVERLAY) -> tuple[list, list, Path]:
    """mppid and the bridge for the mission (the plant's bridge configuration, airframe and
    settings overlay; ArduCopter's by default); the bridge's control socket."""
    task = mission.get("task", "quadrotor_rate_track")
    cfg = paths.TASKS / f"{task}.yaml"
    sets = [str(kv) for kv in spec.sets if not str(kv).startswith("vehicle=")]
    vehicles = [Path(str(kv)[len("vehicle="):]) for kv in spec.sets if str(kv).startswith("vehicle=")]
    vehicle = (vehicles[-1].expanduser().resolve() if vehicles else vehicle)
    ctrl = [str(mppid_binary()), "--config", str(cfg), "--vehicle", str(vehicle),
            "--lcm-url", sensed_mod.controller_url(spec, mission),
            "--backend", spec.backend, "--set", f"mppi.seed={spec.seed}"] + (["--realtime"] if fifo else [])
    for kv in load_sets(overlay) + list((mission.get("mppid") or {}).get("set", [])) + sets:
        ctrl += ["--set", str(kv)]
    sock = out / "bridge.sock"
    # The bridge reads a sensed mission's maps (OBSTACLE_DISTANCE): mppid's receive buffer.
    bridge = [sys.executable, "-m", "mppi_mavlink", "run", "--config", str(bridge_config), "--lcm-url",
              sensed_mod.controller_url(spec, mission),
              "--set", f"control.socket={sock}", "--set", f"vehicle.file={vehicle}",
              "--set", f"trace.file={out / 'bridge_trace.jsonl'}"]  # each setpoint's path, stage by stage
    if fifo:   # its latency path's threads, once started (mppi_mavlink/realtime.py)
        bridge += ["--realtime", str(IO_FIFO_PRIORITY)]
    return ctrl, bridge, sock


def gcs_command(spec: FlightSpec, mission_path: Path, out: Path, url: str, dialect: str) -> list[str]:
    """The ground station (ap_gcs.py) on the autopilot's GCS link: the upload, the world's trees."""
    return [sys.executable, "-m", "sitl_harness.ap_gcs", "--url", url, "--dialect", dialect, "--mission",
            str(mission_path), "--seed", str(spec.seed), "--lcm-url", spec.lcm_url, "--out", str(out)]


def survey_commands(spec: FlightSpec, mission_path: Path, mission: dict, out: Path, cmds: dict, fifo: bool,
                    gcs: list[str], mppid_bridge: tuple, mount: Path | None = None) -> dict:
    """A mission uploaded to the autopilot by the ground station (`gcs`, ap_gcs.py), which also
    publishes the world's trees: flown by mppid (`mppid-mission from-autopilot` through the
    bridge), or with --controller auto by the autopilot's own mission mode, or (`guided_legs`:
    ArduPilot's guided segments) by AUTO with mppid flying the segments; the bridge and the
    mapper run either way (the map goes to the autopilot as OBSTACLE_DISTANCE)."""
    if spec.controller not in ("mppid", "auto"):
        raise FlightError(f"{mission_path.name}: an uploaded mission is flown by mppid or --controller auto")
    ctrl, bridge, sock = mppid_bridge
    cmds = {**cmds, "bridge": bridge}
    auto = gcs + ["--fly-auto", "--timeout", str(float(mission.get("wall_timeout", 200.0)) - 30)]
    tool = [sys.executable, "-m", "mppi_mission", "from-autopilot", "--bridge", str(sock), "--seed", str(spec.seed),
            "--out", str(out), "--lcm-url", spec.lcm_url]
    if spec.controller == "auto":
        cmds["mission"] = auto
    elif (mission.get("autopilot_mission") or {}).get("guided_legs"):  # AUTO flies, mppid its guided segments
        cmds.update(controller=ctrl, segments=tool, mission=auto)
    else:
        cmds.update(gcs=gcs, controller=ctrl, mission=tool)
    return sensed_mod.add_sensing(spec, mission_path, mission, out, cmds, fifo, mount)


class ArduPilotFlight(Flight):
    def __init__(self, spec: FlightSpec, binary: Path):
        super().__init__(spec)
        self.binary = binary

    @classmethod
    def create(cls, spec: FlightSpec) -> "ArduPilotFlight":
        return cls(spec, ardupilot_binary(spec.ardupilot_bin))

    def plan(self) -> Plan:
        spec = self.spec
        mission_path, mission = load_mission(spec, "ardupilot")
        cmds = self._commands(mission_path, mission)
        return autopilot_plan(spec, mission, cmds, {"autopilot": "ardupilot", "ardupilot_bin": str(self.binary),
                                                    "mission": str(mission_path)})

    def _commands(self, mission_path: Path, mission: dict) -> dict:
        spec = self.spec
        fifo = fifo_allowed()
        ap_dir = self.out / "ardupilot"
        ap_dir.mkdir(exist_ok=True)
        uploaded = "autopilot_mission" in mission or spec.controller == "loiter"
        auto_start = spec.controller == "auto" or bool((mission.get("autopilot_mission") or {}).get("guided_legs"))
        extra = {"auto": (BENDYRULER,), "loiter": (LOITER_AVOID,)}.get(spec.controller, ()) + \
            ((AUTO_START,) if auto_start else ())
        cmds = {
            "logger": logger_command(spec, self.out, sensed_mod.log_exclusions(mission)),
            "sim": sitl_command(self.binary, ap_dir, fifo, extra),
            "recorder": [sys.executable, "-m", "sitl_harness.ap_truth", "--url", "tcp:127.0.0.1:5762",
                         f"--home={HOME}", "--out", str(self.out)],
        }
        if uploaded:
            return self._survey_commands(mission_path, mission, cmds, fifo)
        mission_cmd = mission_command(spec, mission_path, self.out)
        if spec.controller == "guided":
            cmds["mission"] = mission_cmd + ["--guided", "tcp:127.0.0.1:5760"]
            return cmds
        ctrl, bridge, sock = mppid_and_bridge(spec, mission, self.out, fifo)
        cmds.update(controller=ctrl, bridge=bridge, mission=mission_cmd + ["--bridge", str(sock)])
        if sensed_mod.sensed(mission):
            cmds = sensed_mod.add_sensing(spec, mission_path, mission, self.out, cmds, fifo)
        return cmds

    def _survey_commands(self, mission_path: Path, mission: dict, cmds: dict, fifo: bool) -> dict:
        """The survey uploaded on the SITL's third serial port (survey_commands), flown by mppid,
        with --controller auto by ArduCopter's AUTO with BendyRuler; or, --controller loiter,
        ArduCopter's Loiter pushed towards a trunk, mppid not flying."""
        spec = self.spec
        gcs = gcs_command(spec, mission_path, self.out, GCS_URL, "ardupilot") + [f"--home={HOME}"]
        mppid_bridge = mppid_and_bridge(spec, mission, self.out, fifo)
        if spec.controller == "loiter":  # the map to ArduCopter's simple avoidance, mppid not flying
            cmds = {**cmds, "bridge": mppid_bridge[1], "mission": gcs + ["--loiter-push", f"{LOITER_PUSH_S:g}"]}
            return sensed_mod.add_sensing(spec, mission_path, mission, self.out, cmds, fifo)
        return survey_commands(spec, mission_path, mission, self.out, cmds, fifo, gcs, mppid_bridge)

    def start(self, plan: Plan) -> None:
        sb, cmds = self.sandbox, plan.commands
        sb.spawn("logger", cmds["logger"])
        sb.spawn("sim", cmds["sim"])
        sb.spawn("recorder", cmds["recorder"])
        for name in ("sensors", "mapper"):  # a sensed mission's: up before the world's trees come
            if name in cmds:
                sb.spawn(name, cmds[name])
        for name in ("controller", "bridge"):
            if name in cmds:
                sb.spawn(name, cmds[name])
        if "gcs" in cmds:  # the operator's upload first: the mission tool reads it at once
            sb.spawn("gcs", cmds["gcs"])
            sb.wait_ready("gcs", 120.0)
        sb.spawn("mission", cmds["mission"])
        if "segments" in cmds:  # the ground station's upload first, then the tool reads it
            sb.wait_ready("mission", 120.0)
            sb.spawn("segments", cmds["segments"])
        # The SITL boots once serial 0 (the bridge, or the mission tool's GUIDED link) connects.
        sb.wait_ready("recorder", 60.0)

    def watch(self, plan: Plan, t0: float) -> str | None:
        """Until the mission tool exits (the flight is over: landed, or given up), or
        something it needs dies, or the wall-clock limit."""
        watched = [n for n in ("sim", "controller", "bridge", "recorder", "logger", "sensors", "mapper", "gcs")
                   if n in self.sandbox.procs]
        while True:
            time.sleep(0.1)
            if self.exited("mission"):
                return None
            for name in watched:
                if self.exited(name):
                    self.events.append(f"{name} exited rc={self.returncode(name)} at {time.monotonic() - t0:.1f} s")
                    return f"{name}_died" if name != "controller" else "controller_died"
            if time.monotonic() - t0 > plan.wall_timeout:
                return "wall_timeout"

    def score(self, info: dict) -> dict:
        from .. import ap_score
        return ap_score.score_flight(self.out, self.spec, info)

    def plot(self) -> list:
        from .. import ap_plots
        return ap_plots.plot_flight(self.out)
