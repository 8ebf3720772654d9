"""The bridge's settings: one YAML file (config/bridge/*.yaml), `--set section.key=value`
overrides, validated into one frozen snapshot at start-up. Unknown keys are errors.

`vehicle.file` names the vehicle file (config/vehicles/*.yaml, relative to the settings
file) that mppid flies with too: the thrust map's mass, gravity and hover thrust come from
it, and a value the settings also give differently is refused, naming both files."""
from __future__ import annotations

import copy
import math
from dataclasses import dataclass
from pathlib import Path

import yaml

from . import autopilots, fence, obstacle_distance
from . import vehicle as vehicle_file

DEFAULTS = {
    "mavlink": {
        "url": "udpin:127.0.0.1:14540",   # pymavlink connection string (serial: /dev/ttyACM0, baud below)
        "baud": 921600,
        "dialect": "px4",                 # px4 | ardupilot
        "system_id": 1,                   # the bridge's own ids: the autopilot's system,
        "component_id": 191,              # MAV_COMP_ID_ONBOARD_COMPUTER
        "target_component": 1,            # MAV_COMP_ID_AUTOPILOT1
        "heartbeat_timeout_s": 1.0,       # autopilot HEARTBEAT overdue this long past its period: link lost
        "reconnect_period_s": 2.0,        # re-open a lost serial/TCP link this often
        "param_timeout_s": 1.0,           # per PARAM_REQUEST_READ attempt
        "param_retries": 3,
        "command_timeout_s": 1.0,         # per COMMAND_LONG attempt (COMMAND_ACK)
        "command_retries": 3,
        "mode_confirm_timeout_s": 2.0,    # mode seen in the HEARTBEAT after the ACK
        "signing_key_file": None,         # MAVLink 2 signing key (signing.py); None: an unsigned link
        "signing_link_id": 0,             # the link id in the bridge's signatures
    },
    "lcm": {
        "url": "udpm://239.255.76.67:7667?ttl=0",
        "state_channel": "MPPI_STATE",
        "command_channel": "MPPI_COMMAND",
        "status_channel": "MPPI_STATUS",
        "params_channel": "MPPI_PARAMS",          # `identify`: the request to mppid ...
        "param_result_channel": "MPPI_PARAM_RESULT",  # ... and its answer
        "link_channel": "MPPI_MAVLINK_LINK",
        "link_hz": 2.0,
    },
    "vehicle": {
        "file": None,                     # the vehicle file (mass, gravity, hover_thrust from it)
        "name": None,                     # the vehicle file's name (set from it)
        "mass": 1.0,                      # kg: the controller's model.mass (from vehicle.file when given)
        "gravity": 9.81,
        "hover_thrust": None,             # 0..1; None: read MPC_THR_HOVER / MOT_THST_HOVER
        "state_source": "auto",           # odometry | split | auto
    },
    "forwarding": {
        "status_timeout_s": 2.5,          # mppid's status (1 Hz + on mode changes) older: unhealthy
        "max_state_age_s": 0.25,          # a command answering an older state is not forwarded
        "forward_hold_plan": True,        # MODE_HOLD_PLAN commands (deadline guard) are forwarded
        "restart_gap_s": 1.0,             # a seq step back after this long a silence: mppid restarted
        "disengage_after_s": 0.5,         # engaged, nothing forwarded this long: disengage (failsafe.py)
    },
    "telemetry": {
        "request": True,                  # ask for the streams below on every link-up (ArduPilot sends none unasked)
        "state_hz": 50.0,                 # the messages states are built from (telemetry.py)
        "status_hz": 2.0,                 # SYS_STATUS, EXTENDED_SYS_STATE
        "min_state_hz": 30.0,             # states slower than this over the last second: refuse to fly
        "grace_s": 2.0,                   # after a link-up, before the rate is judged
    },
    "offboard": {
        "min_rate_hz": 5.0,               # stream at least this fast (PX4 needs > 2 Hz) ...
        "prestream_s": 1.0,               # ... for this long before OFFBOARD is requested
        "wait_s": 3.0,                    # how long `offboard` waits for such a stream
        "takeoff_wait_s": 30.0,           # ArduPilot: how long `offboard` waits for a take-off to end
    },
    "takeoff": {"altitude": 2.0},         # m above home
    # The geofence (fence.py), in the autopilot's local frame, ENU: engaged and outside it, the
    # bridge disengages and holds (failsafe.py); `offboard` outside it is refused.
    "fence": {"shape": None,              # box | cylinder | None (no fence)
              "center": None, "radius": None,       # cylinder: [x, y], m
              "min": None, "max": None,             # box: [x, y] corners, m
              "min_z": None, "max_z": None},        # m, either shape
    "control": {"socket": "/run/mppid-mavlink/control.sock"},
    # SCHED_FIFO for the threads on the latency path once the bridge is built (realtime.py);
    # 0: time-shared. The unit gives 85 (`run --realtime 85`), above mppid's loop (80).
    "realtime": {"priority": 0},
    "trace": {"file": None},              # JSONL of every forwarded setpoint (latency measurement)
    # The map to the autopilot: mppid-mapper's map as OBSTACLE_DISTANCE(_3D) (obstacle_distance.py).
    "obstacle_distance": obstacle_distance.DEFAULTS,
}


class SettingsError(ValueError):
    pass


def _merge(base: dict, over: dict, path=""):
    for k, v in (over or {}).items():
        if k not in base:
            raise SettingsError(f"{path}{k}: unknown setting")
        if isinstance(base[k], dict):
            if not isinstance(v, dict):
                raise SettingsError(f"{path}{k}: expected a map")
            _merge(base[k], v, f"{path}{k}.")
        else:
            base[k] = v


def _parse_scalar(text: str):
    v = yaml.safe_load(text)
    return v


@dataclass(frozen=True)
class Settings:
    raw: dict

    def __getitem__(self, section):
        return self.raw[section]


def load(path: str | Path | None = None, sets: list[str] | None = None) -> Settings:
    s = copy.deepcopy(DEFAULTS)
    given: dict[str, str] = {}  # vehicle.* keys given explicitly -> where
    folder = Path(".")
    if path:
        doc = yaml.safe_load(Path(path).read_text()) or {}
        if not isinstance(doc, dict):
            raise SettingsError(f"{path}: expected a map")
        doc.pop("description", None)
        _merge(s, doc)
        given.update({k: str(path) for k in (doc.get("vehicle") or {})})
        folder = Path(path).parent
    for kv in sets or []:
        if "=" not in kv:
            raise SettingsError(f"--set {kv}: expected section.key=value")
        key, val = kv.split("=", 1)
        parts = key.split(".")
        if len(parts) != 2:
            raise SettingsError(f"--set {key}: expected section.key")
        _merge(s, {parts[0]: {parts[1]: _parse_scalar(val)}})
        if parts[0] == "vehicle":
            given[parts[1]] = f"--set {key}"
            if parts[1] == "file":
                folder = Path(".")
    validate(s)
    if s["vehicle"]["file"] is not None:
        _take_vehicle_file(s, given, folder)
    return Settings(s)


def _take_vehicle_file(s: dict, given: dict[str, str], folder: Path):
    """mass, gravity and hover_thrust from the vehicle file; refuses a different explicit value."""
    f = s["vehicle"]["file"]
    if not isinstance(f, str) or not f:
        raise SettingsError(f"vehicle.file: must be a file name or null, got {f!r}")
    p = Path(f) if Path(f).is_absolute() else folder / f
    try:
        v = vehicle_file.load(p)
    except vehicle_file.VehicleError as e:
        raise SettingsError(str(e)) from None
    for key in ("mass", "gravity", "hover_thrust"):
        if key in given and s["vehicle"][key] != v[key]:
            raise SettingsError(f"vehicle.{key}: {given[key]} gives {s['vehicle'][key]!r} but the vehicle file {p} "
                                f"gives {v[key]!r} (mppid flies the vehicle file's: keep it there only)")
        s["vehicle"][key] = v[key]
    s["vehicle"]["file"] = str(p)
    s["vehicle"]["name"] = v["name"]
    validate(s)


def validate(s: dict):
    def num(sec, key, lo, hi, allow_none=False):
        v = s[sec][key]
        if v is None and allow_none:
            return
        if not isinstance(v, (int, float)) or isinstance(v, bool) or not math.isfinite(v) or not (lo <= v <= hi):
            raise SettingsError(f"{sec}.{key}: must be a number in [{lo}, {hi}], got {v!r}")

    if s["mavlink"]["dialect"] not in autopilots.available():
        raise SettingsError(f"mavlink.dialect: must be one of {', '.join(autopilots.available())} "
                            f"(a file in mppi_mavlink/autopilots/), got {s['mavlink']['dialect']!r}")
    num("mavlink", "system_id", 1, 255)
    num("mavlink", "component_id", 1, 255)
    num("mavlink", "target_component", 0, 255)
    num("mavlink", "heartbeat_timeout_s", 0.1, 60)
    num("mavlink", "reconnect_period_s", 0.1, 60)
    num("mavlink", "param_timeout_s", 0.05, 30)
    num("mavlink", "param_retries", 1, 20)
    num("mavlink", "command_timeout_s", 0.05, 30)
    num("mavlink", "command_retries", 1, 20)
    num("mavlink", "mode_confirm_timeout_s", 0.1, 30)
    num("lcm", "link_hz", 0.1, 50)
    num("vehicle", "mass", 1e-3, 1e4)
    num("vehicle", "gravity", 0.1, 100)
    num("vehicle", "hover_thrust", 0.01, 0.99, allow_none=True)
    if s["vehicle"]["state_source"] not in ("odometry", "split", "auto"):
        raise SettingsError("vehicle.state_source: must be odometry, split or auto")
    num("forwarding", "status_timeout_s", 0.05, 60)
    num("forwarding", "max_state_age_s", 0.005, 10)
    num("forwarding", "restart_gap_s", 0.0, 60)
    num("forwarding", "disengage_after_s", 0.1, 10)
    num("offboard", "min_rate_hz", 2.0001, 1000)
    num("offboard", "prestream_s", 1.0, 60)
    num("offboard", "wait_s", 0.0, 60)
    num("offboard", "takeoff_wait_s", 0.0, 600)
    if not isinstance(s["telemetry"]["request"], bool):
        raise SettingsError(f"telemetry.request: must be true or false, got {s['telemetry']['request']!r}")
    num("telemetry", "state_hz", 1.0, 1000)
    num("telemetry", "status_hz", 0.1, 100)
    num("telemetry", "min_state_hz", 0.0, 1000)
    num("telemetry", "grace_s", 0.0, 60)
    if s["telemetry"]["min_state_hz"] > s["telemetry"]["state_hz"]:
        raise SettingsError(f"telemetry.min_state_hz ({s['telemetry']['min_state_hz']:g}) must not exceed "
                            f"telemetry.state_hz ({s['telemetry']['state_hz']:g})")
    num("takeoff", "altitude", 0.1, 1000)
    _integer(s, "realtime", "priority", 0, 99)
    try:
        fence.parse({k: v for k, v in s["fence"].items() if v is not None})
    except fence.FenceError as e:
        raise SettingsError(str(e)) from None
    _integer(s, "mavlink", "signing_link_id", 0, 255)
    k = s["mavlink"]["signing_key_file"]
    if k is not None and (not isinstance(k, str) or not k):
        raise SettingsError(f"mavlink.signing_key_file: must be a file name or null, got {k!r}")
    if not isinstance(s["mavlink"]["url"], str) or not s["mavlink"]["url"]:
        raise SettingsError("mavlink.url: must be a pymavlink connection string")
    obstacle_distance.validate(s, _raise)


def _integer(s: dict, sec: str, key: str, lo: int, hi: int):
    v = s[sec][key]
    if not isinstance(v, int) or isinstance(v, bool) or not lo <= v <= hi:
        raise SettingsError(f"{sec}.{key}: must be an integer in [{lo}, {hi}], got {v!r}")


def _raise(message: str):
    raise SettingsError(message)
