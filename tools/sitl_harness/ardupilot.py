"""A flight through a real autopilot: ArduCopter SITL, built from ArduPilot's source, in
place of mppid-sim. In real time (ArduPilot's SITL runs on the wall clock), in the flight's
private network namespace (flight.py), one process each:

    arducopter (SITL)  serial 0 tcp:5760 <- mppid-mavlink-bridge (config/bridge/ardupilot_sitl.yaml)
                       serial 1 tcp:5762 <- ap_truth.py, the referee (SIM_STATE: the simulated truth)
    mppid (the mission's task, --realtime) <-> LCM <-> the bridge
    mppid-mission fly <mission> --bridge <socket>: arm, the autopilot's take-off, `offboard`, the
                       legs (references and virtual trees to mppid), land
    lcm-logger

`--controller guided` flies the same mission with ArduCopter's own GUIDED position controller
(the mission tool on serial 0 with --guided; no mppid, no bridge): the baseline.

The autopilot's parameters: ArduPilot's SITL defaults for a copter
(<ardupilot>/Tools/autotest/default_params/copter.parm), then config/ardupilot/copter_mppid.parm
(argued there line by line). A fresh EEPROM every flight (--wipe), so flights do not inherit
each other's learnt hover thrust.
"""
from __future__ import annotations

import json
import os
import sys
import time
from pathlib import Path

import yaml

from . import paths
from .flight import Flight, FlightError, _fifo_allowed, _lcm_logger, LOGGER_RECV_BUF, SIM_FIFO_PRIORITY

# ArduPilot's SITL home (Canberra Model Aircraft Club, the autotest default): lat, lon, alt AMSL, heading.
HOME = "-35.363261,149.165230,584,353"
PARAMS = paths.ROOT / "config" / "ardupilot" / "copter_mppid.parm"
BRIDGE_CONFIG = paths.ROOT / "config" / "bridge" / "ardupilot_sitl.yaml"
IO_FIFO_PRIORITY = 85   # the bridge, as its unit runs it (above mppid's 80)
# mppid's settings through ArduCopter, over the task file (argued there), then the mission's
# own (its `mppid.set`), then --set.
OVERLAY = paths.ROOT / "config" / "ardupilot" / "mppid_overlay.yaml"
# The airframe both mppid and the bridge are given; `--set vehicle=FILE` (e.g. one tools/sysid
# identified) replaces it for both.
VEHICLE = paths.ROOT / "config" / "vehicles" / "arducopter_sitl.yaml"
BUILD_HINT = ("build ArduCopter SITL from an ArduPilot checkout (tools/ardupilot/build-sitl.sh CHECKOUT: "
              "`./waf configure --board sitl` then `./waf copter`, as ArduPilot's documentation says), then pass "
              "--ardupilot-bin <checkout>/build/sitl/bin/arducopter or set MPPID_ARDUPILOT_BIN")


def ardupilot_binary(explicit: str | None = None) -> Path:
    b = explicit or os.environ.get("MPPID_ARDUPILOT_BIN")
    if not b:
        raise FlightError(f"no ArduCopter SITL binary: {BUILD_HINT}")
    p = Path(b).expanduser().resolve()
    if not (p.is_file() and os.access(p, os.X_OK)):
        raise FlightError(f"ArduCopter SITL binary {p} does not exist or is not executable: {BUILD_HINT}")
    return p


def ardupilot_defaults(binary: Path) -> Path:
    """ArduPilot's own SITL defaults for a copter, in the checkout the binary was built in."""
    p = binary.parents[3] / "Tools" / "autotest" / "default_params" / "copter.parm"
    if not p.is_file():
        raise FlightError(f"{p} not found: the binary should be <ardupilot checkout>/build/sitl/bin/arducopter")
    return p


class ArduPilotFlight(Flight):
    def __init__(self, spec, binary: Path):
        super().__init__(spec)
        self.binary = binary

    def run(self) -> dict:
        spec = self.spec
        self.out.mkdir(parents=True, exist_ok=True)
        mission_path = paths.scenario_path(spec.scenario)
        mission = yaml.safe_load(mission_path.read_text())
        if "legs" not in mission:
            raise FlightError(f"{mission_path} is not a mission (config/missions/*.yaml): --autopilot ardupilot "
                              f"flies missions")
        cmds = self._commands(mission_path, mission)
        t0 = time.monotonic()
        outcome = None
        wall_timeout = spec.wall_timeout or float(mission.get("wall_timeout", 240.0))
        try:
            self._start_namespace()
            self._spawn("logger", cmds["logger"])
            self._spawn("sim", cmds["sim"])
            self._spawn("recorder", cmds["recorder"])
            if spec.controller != "guided":
                self._spawn("controller", cmds["controller"])
                self._spawn("bridge", cmds["bridge"])
            self._spawn("mission", cmds["mission"])
            # The SITL boots once serial 0 (the bridge, or the mission tool's GUIDED link) connects.
            self._wait_ready("recorder", 60.0)
            outcome = self._wait(t0, wall_timeout)
        except KeyboardInterrupt:
            outcome = "interrupted"
            self.events.append("interrupted (Ctrl-C / SIGTERM)")
            raise
        finally:
            self.cleanup()
            info = self._record(t0, outcome, {
                "autopilot": "ardupilot", "ardupilot_bin": str(self.binary), "commands": cmds,
                "mission": str(mission_path), "spec": {"scenario": spec.scenario, "seed": spec.seed,
                                                       "controller": spec.controller, "realtime": True,
                                                       "lcm_url": spec.lcm_url}})
        return info

    def _wait(self, t0, wall_timeout):
        """Until the mission tool exits (the flight is over: landed, or given up), or
        something it needs dies, or the wall-clock limit."""
        watched = [n for n in ("sim", "controller", "bridge", "recorder", "logger") if n in self.procs]
        while True:
            time.sleep(0.1)
            if self.procs["mission"].poll() is not None:
                return None
            for name in watched:
                if self.procs[name].poll() is not None:
                    self.events.append(f"{name} exited rc={self.procs[name].returncode} at {time.monotonic() - t0:.1f} s")
                    return f"{name}_died" if name != "controller" else "controller_died"
            if time.monotonic() - t0 > wall_timeout:
                return "wall_timeout"

    def _commands(self, mission_path: Path, mission: dict) -> dict:
        spec = self.spec
        py = sys.executable
        fifo = _fifo_allowed()
        ap_dir = self.out / "ardupilot"
        ap_dir.mkdir(exist_ok=True)
        defaults = f"{ardupilot_defaults(self.binary)},{PARAMS}"
        # The SITL in its own folder (EEPROM, dataflash logs); the world, above the controller.
        sim = ["sh", "-c", f'cd "{ap_dir}" && exec "$0" "$@"', str(self.binary), "--model", "quad", "--speedup", "1",
               "--home", HOME, "--defaults", defaults, "-I0", "--wipe"]
        if fifo:
            sim = ["chrt", "-f", str(SIM_FIFO_PRIORITY)] + sim
        cmds = {
            "logger": [str(_lcm_logger()), "-q", "-f", f"--lcm-url={spec.lcm_url}&recv_buf_size={LOGGER_RECV_BUF}",
                       str(self.out / "flight.lcmlog")],
            "sim": sim,
            "recorder": [py, "-m", "sitl_harness.ap_truth", "--url", "tcp:127.0.0.1:5762", f"--home={HOME}", "--out",
                         str(self.out)],
        }
        mission_cmd = [str(paths.ROOT / "drivers" / "mission" / "mppid-mission"), "fly", str(mission_path), "--seed",
                       str(spec.seed), "--out", str(self.out), "--lcm-url", spec.lcm_url]
        if spec.controller == "guided":
            cmds["mission"] = mission_cmd + ["--guided", "tcp:127.0.0.1:5760"]
            return cmds
        mppid = paths.find_binary("mppid")
        if mppid is None:
            raise FlightError("mppid not built (searched %s)" % ", ".join(map(str, paths.build_dirs())))
        task = mission.get("task", "quadrotor_rate_track")
        cfg = paths.TASKS / f"{task}.yaml"
        sets = [str(kv) for kv in spec.sets if not str(kv).startswith("vehicle=")]
        vehicles = [Path(str(kv)[len("vehicle="):]) for kv in spec.sets if str(kv).startswith("vehicle=")]
        vehicle = (vehicles[-1].expanduser().resolve() if vehicles else VEHICLE)
        ctrl = [str(mppid), "--config", str(cfg), "--vehicle", str(vehicle), "--lcm-url", spec.lcm_url,
                "--backend", spec.backend, "--set", f"mppi.seed={spec.seed}"] + (["--realtime"] if fifo else [])
        from .overlay import load_sets
        for kv in load_sets(OVERLAY) + list((mission.get("mppid") or {}).get("set", [])) + sets:
            ctrl += ["--set", str(kv)]
        sock = self.out / "bridge.sock"
        bridge = [str(paths.ROOT / "drivers" / "mavlink" / "mppid-mavlink-bridge"), "run", "--config",
                  str(BRIDGE_CONFIG), "--lcm-url", spec.lcm_url, "--set", f"control.socket={sock}",
                  "--set", f"vehicle.file={vehicle}"]
        if fifo:
            bridge = ["chrt", "-f", str(IO_FIFO_PRIORITY)] + bridge
        cmds.update(controller=ctrl, bridge=bridge, mission=mission_cmd + ["--bridge", str(sock)])
        return cmds
