"""A sensed mission flown through an autopilot's SITL (flights/ardupilot.py, flights/px4.py): the
trees exist only in the world. What the flight adds to the autopilot's:

    the referee                + --lcm-url <sensor bus>: the SITL's truth as vehicle_state_t
                                 on SIM_TRUTH (truth_bus.py: ENU, body FLU -> ENU, the states'
                                 clock); ap_truth.py (ArduCopter's SIM_STATE, 50 Hz) or
                                 px4_truth.py (SIH's HIL_STATE_QUATERNION, asked for at 50 Hz)
    mppid-sensors              the simulator's sensors (sim/sensor_node.hpp: the same SensorRig
                                 as mppid-sim's) ray-casting the mission's trees, which the mission
                                 tool (or, for an uploaded survey, the ground station) sends on
                                 MPPI_WORLD, from that truth; point_cloud_t on the sensor bus at
                                 the sensors' rates and latency
    mppid-mapper               the frames -> local_map_t on MPPI_LOCAL_MAP (flights/sim.py's)

Why the referee publishes the truth: it already reads the SITL's truth (ArduCopter: SIM_STATE on
the SITL's second serial port; PX4: SIH's truth on its display link) and converts it into the
bridge's local frame (the estimator's origin, the frame of LOCAL_POSITION_NED, the mission's
trees' and mppid's), so the camera's pose and the score's come from one conversion; a second MAVLink reader in C++ would repeat it (and the SITL
has no third serial port configured). The trees come from the mission tool because it owns them:
it places them (the forest of the flight's seed, from where the mission starts) and records them
for the referee (mission.jsonl), so the sensed trees, the scored trees and rate_forest's are one
list.

The sensors run as the simulator's do, above mppid (SCHED_FIFO 90 where allowed: the world is
not the flight computer's load); the referee, now the camera's pose source, at 79 (below mppid).
"""
from __future__ import annotations

from pathlib import Path

from .. import paths
from .base import LOGGER_RECV_BUF, SIM_FIFO_PRIORITY, FlightError, FlightSpec, sensor_bus
from .sim import log_exclusions as _log_exclusions
from .sim import mapper_command, realtime_priorities
from .sim import sensed as _sensed

REFEREE_FIFO_PRIORITY = 79  # the referee (the camera's pose source): below the daemon

TREE_HEIGHT = 10.0  # m: a mission's forest with no `height`


def sensed(mission: dict) -> bool:
    """A sensor on and the trees kept from mppid (sensing.publish_obstacles: false)."""
    return _sensed(mission) and (mission.get("sensing") or {}).get("publish_obstacles", True) is False


def log_exclusions(mission: dict) -> tuple[str, ...]:
    return _log_exclusions(mission) if sensed(mission) else ()


def controller_url(spec: FlightSpec, mission: dict) -> str:
    """mppid's bus; for a sensed mission with a receive buffer that holds a few 1 MB maps."""
    return f"{spec.lcm_url}&recv_buf_size={LOGGER_RECV_BUF}" if sensed(mission) else spec.lcm_url


def sensors_command(spec: FlightSpec, mission_path: Path, mission: dict, out: Path) -> list[str]:
    exe = paths.find_binary("mppid-sensors")
    if exe is None:
        raise FlightError("mppid-sensors not built (searched %s)" % ", ".join(map(str, paths.build_dirs())))
    forest = (mission.get("obstacles") or {}).get("forest") or {}
    return [str(exe), "--sensing", str(mission_path), "--seed", str(spec.seed), "--lcm-url", spec.lcm_url,
            "--sensor-lcm-url", sensor_bus(spec.lcm_url), "--tree-height", f"{float(forest.get('height', TREE_HEIGHT)):g}",
            "--stats", str(out / "sensors_stats.json")]


def mounted(mission: dict, mount: Path, out: Path) -> Path:
    """The mission's `sensing:` with an airframe's mounting over it (`mount`'s `sensing:` keys,
    for the sensors the mission has), written to OUT/sensing.yaml for mppid-sensors' --sensing:
    where a camera points is the vehicle's, not the mission's."""
    import yaml
    sensing = dict(mission.get("sensing") or {})
    for sensor, keys in ((yaml.safe_load(mount.read_text()) or {}).get("sensing") or {}).items():
        if isinstance(sensing.get(sensor), dict):
            sensing[sensor] = {**sensing[sensor], **keys}
    path = out / "sensing.yaml"
    path.write_text(yaml.safe_dump({"sensing": sensing}, sort_keys=False))
    return path


def add_sensing(spec: FlightSpec, mission_path: Path, mission: dict, out: Path, cmds: dict, fifo: bool,
                mount: Path | None = None) -> dict:
    """The autopilot flight's commands with the sensors (on the airframe's `mount`, if given), the
    mapper and the truth on the bus."""
    sensing = mounted(mission, mount, out) if mount is not None else mission_path
    cmds = {**cmds, "recorder": cmds["recorder"] + ["--lcm-url", sensor_bus(spec.lcm_url)],
            "sensors": sensors_command(spec, sensing, mission, out),
            "mapper": mapper_command(spec, mission, out)}
    if not fifo:
        return cmds
    cmds = {**cmds, **realtime_priorities({"mapper": cmds["mapper"]})}
    cmds["sensors"] = ["chrt", "-f", str(SIM_FIFO_PRIORITY)] + cmds["sensors"]
    cmds["recorder"] = ["chrt", "-f", str(REFEREE_FIFO_PRIORITY)] + cmds["recorder"]
    return cmds
