"""A flight through a real PX4: PX4 SITL with SIH (Simulation-In-Hardware, PX4's own
quadrotor model inside the firmware, no Gazebo), built from PX4's source (docs/px4.md names
the build flown), in place of mppid-sim. In real time (SIH runs lock-step on PX4's clock,
which it paces to the wall clock), in the flight's private network namespace, one process
each:

    px4 (SIH, airframe sihsim_quadx)  offboard link udp 14540 <- mppid-mavlink-bridge
                                      (config/bridge/px4_sitl.yaml)
                                      SIH display link 19410 <-> px4_truth.py, the referee (SIH's
                                      truth, PX4's estimate and mode)
    mppid (the mission's task, --realtime) <-> LCM <-> the bridge
    mppid-mission fly <mission> --bridge <socket>: arm, PX4's take-off, `offboard`, the legs, land
    lcm-logger

A sensed mission (`sensing:` with publish_obstacles: false, config/missions/rate_forest_sensed.yaml)
adds the sensors and the mapper as through ArduCopter (sensed.py): the referee asks PX4 for SIH's
truth at TRUTH_HZ and publishes it on the sensors' bus (px4_truth.py --lcm-url).

A survey uploaded to the autopilot (`autopilot_mission:`, config/missions/survey_forest_sensed.yaml):
ap_gcs.py on PX4's GCS link (udp 14550, where QGroundControl listens) uploads it in PX4's
numbering and publishes the world's trees; `mppid-mission from-autopilot` reads it through the
bridge and mppid flies it in OFFBOARD (PX4 lands at its NAV_LAND: the bridge's `land`, AUTO.LAND).
`--controller auto`: PX4 flies it itself in AUTO.MISSION (no avoidance in PX4's missions at the
commit flown: collision prevention acts in Position mode only).

`--controller position` (config/missions/position_toward_trunk.yaml): PX4's own collision
prevention with mppid not flying: the bridge sends mppid-mapper's map as OBSTACLE_DISTANCE, and
ap_gcs.py on PX4's GCS link takes off, switches to Position mode and pushes the pitch stick
(MANUAL_CONTROL) towards a trunk only the camera sees, with config/px4/collision_prevention.params.

`--controller px4` flies the same mission with PX4's own offboard position control
(px4_offboard.py on the offboard link: SET_POSITION_TARGET_LOCAL_NED with the reference's
position, velocity and acceleration at 50 Hz; no mppid, no bridge): the baseline.

PX4 runs in a folder of the flight's own (OUT/px4: fresh parameters every flight, its ULog in
OUT/px4/log/), with config/px4/px4_mppid.params (the parameters docs/failsafes.md argues)
and config/px4/offboard_baseline.params given as PX4_PARAM_ variables, which PX4's SITL start-up script applies after the airframe's.
PX4 runs at SCHED_FIFO 85 (above mppid's 80: at normal priority SIH's loop stalls for 0.2 s now
and then on a loaded machine, docs/px4.md), the bridge with `--realtime 85` as its unit runs it.
"""
from __future__ import annotations

import os
import re
import signal
import sys
import time
from pathlib import Path


from .. import paths, px4_faults
from ..sandbox import fifo_allowed
from . import sensed as sensed_mod
from .ardupilot import IO_FIFO_PRIORITY, gcs_command, mission_command, mppid_and_bridge, survey_commands
from .base import Flight, FlightError, FlightSpec, Plan, autopilot_binary, autopilot_plan, load_mission, logger_command

PARAMS = paths.ROOT / "config" / "px4" / "px4_mppid.params"
# The offboard baseline's position-controller tuning (argued in the file): loaded for every
# flight, mppid's too, so both controllers take off and land on the same vehicle.
BASELINE = paths.ROOT / "config" / "px4" / "offboard_baseline.params"
BRIDGE_CONFIG = paths.ROOT / "config" / "bridge" / "px4_sitl.yaml"
# mppid's settings through PX4, over the task file (argued there), then the mission's, then --set.
OVERLAY = paths.ROOT / "config" / "px4" / "mppid_overlay.yaml"
# The airframe mppid and the bridge are given (tools/sysid's fit of SIH's quadrotor from a PX4
# ULog); `--set vehicle=FILE` replaces it for both.
VEHICLE = paths.ROOT / "config" / "vehicles" / "px4_sih_identified.yaml"
# Where SIH's quadrotor carries a sensed mission's camera (over the mission's `sensing:`; argued
# in the file): tilted up, as it cruises tilted 40 degrees.
SENSOR_MOUNT = paths.ROOT / "config" / "px4" / "sensor_mount.yaml"
# PX4's collision prevention and the ground station's sticks (argued in the file): loaded for
# `--controller position` only.
COLLISION_PREVENTION = paths.ROOT / "config" / "px4" / "collision_prevention.params"
POSITION_PUSH_S = 12.0  # the pitch stick held forward in Position mode (ArduCopter's Loiter push's)
OFFBOARD_URL = "udpin:127.0.0.1:14540"
GCS_URL = "udpin:127.0.0.1:14550"   # PX4's GCS link sends here (px4-rc.mavlink), a ground station listens
# SIH's truth for a sensed flight's camera pose: PX4 starts the display link's HIL_STATE_QUATERNION
# at 25 Hz, which would make the 30 Hz camera capture at 25; at 50 Hz (ArduCopter's SIM_STATE's
# rate) each 30 Hz frame is cast on the 20 ms grid of the truths.
TRUTH_HZ = 50.0
# A failsafe flight ends this long after its last fault (what PX4 did is seen by then).
FAULT_WATCH_S = 20.0
SIH_ENV = {"PX4_SIM_MODEL": "sihsim_quadx", "PX4_SIMULATOR": "sihsim"}
BUILD_HINT = ("build PX4 SITL with SIH (`make px4_sitl_sih`) from a PX4 checkout, outside this repository "
              "(docs/px4.md names the build flown here), then pass --px4-bin <checkout>/build/px4_sitl_sih/bin/px4 "
              "or set MPPID_PX4_BIN")


def px4_binary(explicit: str | None = None) -> Path:
    p = autopilot_binary(explicit, "MPPID_PX4_BIN", "PX4 SITL", BUILD_HINT)
    if not (p.parents[1] / "etc" / "init.d-posix" / "rcS").is_file():
        raise FlightError(f"{p.parents[1]}/etc/init.d-posix/rcS not found: the binary should be "
                          f"<PX4 checkout>/build/px4_sitl_sih/bin/px4")
    return p


def px4_params(path: Path = PARAMS) -> dict[str, str]:
    """The `param set NAME VALUE` lines of a PX4 parameter file."""
    found = re.findall(r"^\s*param\s+set\s+(\w+)\s+(\S+)", path.read_text(), flags=re.M)
    return dict(found)


# PX4's server socket is /tmp/px4-sock-<instance> whatever its working folder: two PX4s of
# instance 0 at once (a campaign's parallel flights) would take each other's. As root, each PX4
# sees a /tmp of its own: its working folder's tmp/ mounted there (a private mount namespace),
# with the folders it needs that lie under the machine's /tmp (its work, its build) bound in.
PRIVATE_TMP = r"""set -e
own="$1/tmp"; shift
mkdir -p "$own"
while [ "$1" != -- ]; do
  case "$1" in /tmp/*) mkdir -p "$1" "$own${1#/tmp}"; mount --bind "$1" "$own${1#/tmp}" ;; esac
  shift
done
shift
mount --rbind "$own" /tmp
exec "$@"
"""


def private_tmp(work: Path, keep: list[Path]) -> list[str]:
    """The prefix that runs a command with `work`/tmp as its /tmp, `keep` still at their paths."""
    return (["unshare", "--mount", "--propagation", "private", "--", "sh", "-c", PRIVATE_TMP, "px4-tmp",
             str(work)] + [str(k) for k in keep] + ["--"])


def px4_command(binary: Path, work: Path, fifo: bool, params: dict[str, str]) -> list[str]:
    """PX4 in its own working folder (parameters, dataman, ULogs) and, as root, its own /tmp,
    with SIH's airframe and `params` on top; above mppid."""
    env = {**SIH_ENV, **{f"PX4_PARAM_{k}": v for k, v in params.items()}}
    cmd = ["env"] + [f"{k}={v}" for k, v in env.items()] + [str(binary), "-d", "-w", str(work),
                                                            str(binary.parents[1] / "etc")]
    if os.geteuid() == 0:
        cmd = private_tmp(work.resolve(), [work.resolve(), binary.parents[1].resolve()]) + cmd
    return (["chrt", "-f", str(IO_FIFO_PRIORITY)] + cmd) if fifo else cmd


class Px4Flight(Flight):
    def __init__(self, spec: FlightSpec, binary: Path):
        super().__init__(spec)
        self.binary = binary
        self.faults_done: list[dict] = []
        self.last_fault = None

    @classmethod
    def create(cls, spec: FlightSpec) -> "Px4Flight":
        return cls(spec, px4_binary(spec.px4_bin))

    def plan(self) -> Plan:
        spec = self.spec
        mission_path, mission = load_mission(spec, "px4")
        cmds = self._commands(mission_path, mission)
        return autopilot_plan(spec, mission, cmds, {
            "autopilot": "px4", "px4_bin": str(self.binary), "mission": str(mission_path),
            "faults": self.faults_done, "autopilot_params": spec.autopilot_params,
            "load_avg_start": [round(x, 2) for x in os.getloadavg()]})  # the machine is shared: SIH lags under load

    def _commands(self, mission_path: Path, mission: dict) -> dict:
        spec = self.spec
        fifo = fifo_allowed()
        work = self.out / "px4"
        work.mkdir(exist_ok=True)
        own = px4_params(COLLISION_PREVENTION) if spec.controller == "position" else {}
        params = {**px4_params(PARAMS), **px4_params(BASELINE), **own,
                  "MIS_TAKEOFF_ALT": str(mission.get("takeoff", 2.0)), **dict(kv.split("=", 1) for kv in spec.autopilot_params)}
        sensed = sensed_mod.sensed(mission)
        cmds = {
            "logger": logger_command(spec, self.out, sensed_mod.log_exclusions(mission)),
            "recorder": [sys.executable, "-m", "sitl_harness.px4_truth", "--out", str(self.out)]
            + (["--truth-hz", f"{TRUTH_HZ:g}"] if sensed else []),
            "sim": px4_command(self.binary, work, fifo, params),
        }
        if spec.controller == "position":
            return self._position_commands(mission_path, mission, cmds, fifo)
        if "autopilot_mission" in mission:
            cmds["recorder"] += ["--gcs-port", "0"]   # the ground station's port: PX4's messages from the display link
            gcs = gcs_command(spec, mission_path, self.out, GCS_URL, "px4")
            return survey_commands(spec, mission_path, mission, self.out, cmds, fifo, gcs, self._mppid(mission, fifo),
                                   SENSOR_MOUNT)
        if spec.controller == "auto":
            raise FlightError(f"{mission_path.name}: --controller auto flies a mission uploaded to PX4 "
                              f"(autopilot_mission:, config/missions/survey_*.yaml)")
        if spec.controller == "px4":
            cmds["mission"] = [sys.executable, "-m", "sitl_harness.px4_offboard", str(mission_path), "--url",
                               OFFBOARD_URL, "--seed", str(spec.seed), "--out", str(self.out)]
            return cmds
        ctrl, bridge, sock = self._mppid(mission, fifo)
        cmds.update(controller=ctrl, bridge=bridge,
                    mission=mission_command(spec, mission_path, self.out) + ["--bridge", str(sock)])
        cut = [px4_faults.parse_fault(f) for f in spec.faults if f.startswith("link_cut")]
        if cut:  # the bridge behind the relay, which can cut the link
            cmds["bridge"] += ["--set", f"mavlink.url=udpin:127.0.0.1:{px4_faults.BRIDGE_PORT}"]
            cmds["relay"] = [sys.executable, "-m", "sitl_harness.px4_faults", "relay", "--out", str(self.out),
                             "--cut-s", str(cut[0][2])]
        if sensed:
            cmds = sensed_mod.add_sensing(spec, mission_path, mission, self.out, cmds, fifo, SENSOR_MOUNT)
        return cmds

    def _position_commands(self, mission_path: Path, mission: dict, cmds: dict, fifo: bool) -> dict:
        """PX4's Position mode pushed towards what the sensors see, mppid not flying: the bridge
        (the map as OBSTACLE_DISTANCE), the sensors and the mapper, the ground station on PX4's
        GCS link with the sticks (the recorder takes PX4's messages from the display link)."""
        if not sensed_mod.sensed(mission) or "autopilot_mission" in mission:
            raise FlightError(f"{mission_path.name}: --controller position flies a sensed mission with no "
                              f"autopilot_mission (config/missions/position_toward_trunk.yaml)")
        gcs = gcs_command(self.spec, mission_path, self.out, GCS_URL, "px4")
        cmds = {**cmds, "recorder": cmds["recorder"] + ["--gcs-port", "0"], "bridge": self._mppid(mission, fifo)[1],
                "mission": gcs + ["--position-push", f"{POSITION_PUSH_S:g}"]}
        return sensed_mod.add_sensing(self.spec, mission_path, mission, self.out, cmds, fifo, SENSOR_MOUNT)

    def _mppid(self, mission: dict, fifo: bool) -> tuple:
        """mppid and the bridge with PX4's configuration, airframe and overlay; the bridge's socket."""
        return mppid_and_bridge(self.spec, mission, self.out, fifo, bridge_config=BRIDGE_CONFIG, vehicle=VEHICLE,
                                overlay=OVERLAY)

    def start(self, plan: Plan) -> None:
        sb, cmds = self.sandbox, plan.commands
        sb.spawn("logger", cmds["logger"])
        sb.spawn("recorder", cmds["recorder"])   # bound to its ports before PX4 sends
        time.sleep(0.3)
        sb.spawn("sim", cmds["sim"])
        sb.wait_ready("recorder", 60.0)          # SIH's truth flows: PX4 is up
        if "relay" in cmds:
            sb.spawn("relay", cmds["relay"])
            sb.wait_ready("relay", 10.0)
        for name in ("sensors", "mapper", "controller", "bridge"):  # the sensed mission's before the trees come
            if name in cmds:
                sb.spawn(name, cmds[name])
        if "gcs" in cmds:  # the operator's upload first: the mission tool reads it at once
            sb.spawn("gcs", cmds["gcs"])
            sb.wait_ready("gcs", 150.0)          # PX4's estimator has its origin, the mission is on PX4
        sb.spawn("mission", cmds["mission"])

    def watch(self, plan: Plan, t0: float) -> str | None:
        """Until the mission tool exits, or something it needs dies, or the wall-clock limit;
        a failsafe flight: its faults injected, until FAULT_WATCH_S after the last."""
        watched = [n for n in ("sim", "controller", "bridge", "recorder", "logger", "sensors", "mapper", "gcs")
                   if n in self.sandbox.procs]
        faults = sorted((px4_faults.parse_fault(f) for f in self.spec.faults), key=lambda f: f[1])
        path_t0 = None
        while True:
            time.sleep(0.1)
            now = time.monotonic()
            if faults and path_t0 is None and px4_faults.path_started(self.out):
                path_t0 = now
            while faults and path_t0 is not None and now - path_t0 >= faults[0][1]:
                self._inject(*faults.pop(0), watched)
                self.last_fault = now
            if self.last_fault is not None and not faults and now - self.last_fault > FAULT_WATCH_S:
                self.events.append(f"failsafe flight over {FAULT_WATCH_S:g} s after its last fault")
                return None
            if self.exited("mission"):
                return None
            for name in watched:
                if self.exited(name):
                    self.events.append(f"{name} exited rc={self.returncode(name)} at {time.monotonic() - t0:.1f} s")
                    return f"{name}_died" if name != "controller" else "controller_died"
            if time.monotonic() - t0 > plan.wall_timeout:
                return "wall_timeout"

    def _inject(self, action: str, at: float, dur: float, watched: list) -> None:
        """One fault (px4_faults.py), recorded in harness.json's events with its wall time."""
        sb = self.sandbox
        if action == "kill_mppid":
            watched.remove("controller")
            sb.procs["controller"].send_signal(signal.SIGKILL)
        elif action == "stop_bridge":
            watched.remove("bridge")
            sb.procs["bridge"].send_signal(signal.SIGSTOP)
        elif action == "link_cut":
            sb.procs["relay"].send_signal(signal.SIGUSR1)
        else:
            main, sub = px4_faults.GCS_MODES[action]
            sb.spawn("gcs", [sys.executable, "-m", "sitl_harness.px4_faults", "mode", str(main), str(sub)])
        self.events.append(f"fault {action}" + (f" for {dur:g} s" if dur else "") + f" at path+{at:g} s")
        self.faults_done.append({"action": action, "at_s": at, "for_s": dur, "wall_us": time.time_ns() // 1000})

    def score(self, info: dict) -> dict:
        from .. import px4_score
        res = px4_score.score_flight(self.out, self.spec, info)
        res["load_avg"] = {"start": info.get("load_avg_start"), "end": [round(x, 2) for x in os.getloadavg()]}
        return res

    def plot(self) -> list:
        from .. import ap_plots
        return ap_plots.plot_flight(self.out)
