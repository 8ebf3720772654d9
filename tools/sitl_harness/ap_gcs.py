"""The ground station of a flight through an autopilot's SITL whose mission names an
`autopilot_mission` (config/missions/survey_forest_sensed.yaml): the operator's part.

    python -m sitl_harness.ap_gcs --url URL [--dialect ardupilot|px4] --mission FILE --seed N
        [--home LAT,LON,ALT,HDG] --lcm-url URL --out DIR [--fly-auto | --loiter-push S | --position-push S]

ArduCopter SITL: `--url tcp:127.0.0.1:5763` (its third serial port), `--home` the SITL's.
PX4 SITL: `--dialect px4 --url udpin:127.0.0.1:14550` (PX4's GCS link, where QGroundControl
listens); no --home: the positions are placed about the estimator's origin (GPS_GLOBAL_ORIGIN,
asked for until PX4 has one), the frame of the legs, the trees and the score.

1. Uploads the mission's legs to the autopilot by the mission protocol, as QGroundControl does
   (MISSION_COUNT, the autopilot's MISSION_REQUEST_INT answered with MISSION_ITEM_INT, MISSION_ACK):
   NAV_TAKEOFF, DO_CHANGE_SPEED, a NAV_WAYPOINT per goal leg (its radius the acceptance radius),
   NAV_LAND at the last one; ArduPilot's numbering puts home first as item 0, PX4's numbers the
   items from 0 with no home item; positions from the legs' local ENU metres (pymavlink's
   gps_offset). The legs named in `guided_legs` (ArduPilot) are a guided segment for the
   companion computer: DO_GUIDED_LIMITS (a 60 s timeout) and NAV_GUIDED_ENABLE 1 before them,
   NAV_GUIDED_ENABLE 0 after. Then `{"event": "ready"}` on stdout.
2. Publishes the world: the mission's trees (its forest for the seed) as obstacles_t on
   MPPI_WORLD, which only the sensors read, twice a second; world.json records them, the
   waypoints and the forest's extent for the score (survey.py).
3. With --fly-auto (the autopilot's own controller, `--controller auto`, and a mission with guided
   segments, which mppid flies inside AUTO): the autopilot's mission mode (ArduCopter AUTO, PX4
   AUTO.MISSION), arm, MISSION_START,
   then MISSION_ITEM_REACHED followed to the last waypoint and the landing; mission.jsonl and
   mission_summary.json as the mission tool writes them (the score reads both).
   With --loiter-push S (`--controller loiter`, a mission with no `autopilot_mission`): GUIDED
   take-off, Loiter, the pitch stick pushed forward for S s towards what is ahead, LAND.
   With --position-push S (PX4, `--controller position`): PX4's AUTO.TAKEOFF, then the sticks
   as MANUAL_CONTROL at STICK_HZ, Position mode, the pitch stick pushed forward for S s, Land.
Without either it publishes until it is stopped: `mppid-mission from-autopilot` flies.
"""
from __future__ import annotations

import argparse
import json
import math
import os
import signal
import sys
import threading
import time
from pathlib import Path

os.environ.setdefault("MAVLINK20", "1")
from pymavlink import mavextra, mavutil, mavwp  # noqa: E402

M = mavutil.mavlink
REL = M.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT
WORLD_HZ = 2.0
AUTO_MODE, GUIDED_MODE, LOITER_MODE, LAND_MODE = 3, 4, 5, 9   # ArduCopter's custom modes
PUSH_PWM = 1200            # the pitch stick pushed forward (1500 centred, 1000 full forward)
GUIDED_TIMEOUT_S = 60.0    # DO_GUIDED_LIMITS before each guided segment: AUTO goes on after it
DIALECTS = ("ardupilot", "px4")
# PX4's AUTO.MISSION as SET_MODE's custom mode: main mode 4 (bits 16-23), sub mode 4 (bits 24-31),
# px4_custom_mode.h.
PX4_AUTO_MISSION = (4 << 16) | (4 << 24)
PX4_AUTO_TAKEOFF = (4 << 16) | (2 << 24)
PX4_AUTO_LOITER = (4 << 16) | (3 << 24)   # Hold: where PX4's take-off ends
PX4_POSCTL_MAIN = 3                       # Position mode's main mode
STICK_HZ = 20.0            # MANUAL_CONTROL, as a joystick on a ground station sends it
PUSH_STICK = 600           # MANUAL_CONTROL x, 60 % forward: ArduCopter's 1200 us (PUSH_PWM)
STICK_MID = 500            # MANUAL_CONTROL z at mid: PX4's Position mode holds the altitude
SETTLE_S = 3.0             # the sticks centred before the push and after it
ORIGIN_TIMEOUT_S = 120.0


def item(seq, cmd, home, east=0.0, north=0.0, z=0.0, p=(0, 0, 0, 0), frame=REL):
    """A MISSION_ITEM_INT as a ground station writes it: `east`, `north` metres from `home`
    (lat, lon deg); lat, lon 0 where both are 0."""
    lat, lon = (0.0, 0.0) if (east, north) == (0.0, 0.0) else mavextra.gps_offset(home[0], home[1], east, north)
    cls = M.MAVLink_mission_item_int_message
    kind = [M.MAV_MISSION_TYPE_MISSION] if "mission_type" in cls.fieldnames else []  # MAVLink 2's extension
    return cls(1, 1, seq, frame, cmd, 0, 1, *p, int(round(lat * 1e7)), int(round(lon * 1e7)), z, *kind)


def mission_items(doc: dict, home, dialect: str = "ardupilot") -> list:
    """The legs as a ground station writes them for the dialect: ArduPilot's home is item 0
    (`home` lat, lon, alt AMSL), PX4's first item is 0 and has no home before it; positions
    about `home`'s latitude and longitude."""
    if dialect not in DIALECTS:
        raise ValueError(f"dialect {dialect!r}: one of {', '.join(DIALECTS)}")
    goals = [leg["goal"] for leg in doc["legs"] if "goal" in leg]
    if len(goals) != len(doc["legs"]):
        raise ValueError("autopilot_mission: every leg a goal (each a NAV_WAYPOINT)")
    guided = set(doc["autopilot_mission"].get("guided_legs", []))
    if guided and dialect == "px4":
        raise ValueError("autopilot_mission.guided_legs: ArduPilot's NAV_GUIDED_ENABLE, which PX4 has not")
    items = []
    if dialect == "ardupilot":
        items.append(item(0, M.MAV_CMD_NAV_WAYPOINT, home, z=home[2], frame=M.MAV_FRAME_GLOBAL_INT))

    def add(cmd, east=0.0, north=0.0, z=0.0, p=(0, 0, 0, 0), frame=REL):
        items.append(item(len(items), cmd, home, east, north, z, p, frame))
    add(M.MAV_CMD_NAV_TAKEOFF, z=float(doc["takeoff"]))
    if dialect == "px4":  # where the vehicle stands, as QGroundControl writes it (lat, lon 0 is a place)
        items[-1].x, items[-1].y = int(round(home[0] * 1e7)), int(round(home[1] * 1e7))
    # PX4 takes a command item in MAV_FRAME_MISSION only (in a global frame its lat, lon 0 must be
    # INT32_MAX, "unset"): as QGroundControl writes it. ArduPilot reads either.
    add(M.MAV_CMD_DO_CHANGE_SPEED, p=(1, float(doc["autopilot_mission"]["speed"]), -1, 0),
        frame=M.MAV_FRAME_MISSION if dialect == "px4" else REL)
    for i, g in enumerate(goals):
        if i in guided and i - 1 not in guided:  # a segment for the companion: limits, then enable
            add(M.MAV_CMD_DO_GUIDED_LIMITS, p=(GUIDED_TIMEOUT_S, 0, 0, 0))
            add(M.MAV_CMD_NAV_GUIDED_ENABLE, p=(1, 0, 0, 0))
        add(M.MAV_CMD_NAV_WAYPOINT, *map(float, g["at"]), p=(0, float(g.get("radius", 1.0)), 0, 0))
        if i in guided and i + 1 not in guided:
            add(M.MAV_CMD_NAV_GUIDED_ENABLE, p=(0, 0, 0, 0))
    if doc.get("land", True):
        add(M.MAV_CMD_NAV_LAND, float(goals[-1]["at"][0]), float(goals[-1]["at"][1]))
    return items


def last_waypoint(items) -> int:
    return max(m.seq for m in items if m.command == M.MAV_CMD_NAV_WAYPOINT)


def upload(conn, items, timeout=30.0) -> int:
    """The mission protocol's upload; the MISSION_ACK's type."""
    wp = mavwp.MAVWPLoader(target_system=1, target_component=1)
    for m in items:
        wp.add(m)
    conn.mav.mission_count_send(1, 1, wp.count(), M.MAV_MISSION_TYPE_MISSION)
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        m = conn.recv_match(type=["MISSION_REQUEST_INT", "MISSION_REQUEST", "MISSION_ACK"], blocking=True, timeout=1)
        if m is None or (getattr(m, "target_system", 255), getattr(m, "target_component", 190)) != (255, 190):
            continue  # another link's exchange
        if m.get_type() == "MISSION_ACK":
            return m.type
        conn.mav.send(wp.wp(m.seq))
    raise TimeoutError("the autopilot never acknowledged the mission")


def upload_when_ready(conn, items, wait_s: float = 60.0) -> int:
    """upload(), again while the autopilot's mission storage is not up yet (MAV_MISSION_NO_SPACE
    for a while after PX4's start); the last MISSION_ACK's type."""
    result, t0 = upload(conn, items), time.monotonic()
    while result == M.MAV_MISSION_NO_SPACE and time.monotonic() - t0 < wait_s:
        time.sleep(1.0)
        result = upload(conn, items)
    return result


def clear(conn, timeout=10.0) -> int:
    """MISSION_CLEAR_ALL, as a ground station's "remove all": the MISSION_ACK's type."""
    conn.mav.mission_clear_all_send(1, 1, M.MAV_MISSION_TYPE_MISSION)
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        m = conn.recv_match(type="MISSION_ACK", blocking=True, timeout=1)
        if m is not None and (m.target_system, m.target_component) == (255, 190):
            return m.type
    raise TimeoutError("the autopilot never acknowledged the mission's clearing")


def publish_world(lcm_url: str, trees, stop: threading.Event):
    import lcm
    from mppi_mavlink import lcm_types
    from mppi_mission.vehicles import obstacles_message
    types, lc, seq = lcm_types.import_mppi_lcm(), lcm.LCM(lcm_url), 0
    while not stop.wait(1.0 / WORLD_HZ):
        seq += 1
        lc.publish("MPPI_WORLD", obstacles_message(types, trees, time.time() * 1e6, seq).encode())


def _command(conn, cmd, *params, timeout=5.0) -> bool:
    conn.mav.command_long_send(1, 1, cmd, 0, *(list(params) + [0] * (7 - len(params))))
    ack = conn.recv_match(type="COMMAND_ACK", blocking=True, timeout=timeout,
                          condition=f"COMMAND_ACK.command=={cmd}")
    return ack is not None and ack.result == M.MAV_RESULT_ACCEPTED


def origin_of(conn, timeout: float = ORIGIN_TIMEOUT_S) -> list[float]:
    """The estimator's origin (lat, lon deg, alt m AMSL), asked for until the autopilot has one."""
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        conn.mav.command_long_send(1, 1, M.MAV_CMD_REQUEST_MESSAGE, 0, M.MAVLINK_MSG_ID_GPS_GLOBAL_ORIGIN,
                                   0, 0, 0, 0, 0, 0)
        m = conn.recv_match(type="GPS_GLOBAL_ORIGIN", blocking=True, timeout=2.0)
        if m is not None:
            return [m.latitude * 1e-7, m.longitude * 1e-7, m.altitude * 1e-3]
    raise TimeoutError(f"the autopilot had no estimator origin (GPS_GLOBAL_ORIGIN) in {timeout:g} s")


def fly_auto(conn, last_wp: int, log, say, timeout: float, dialect: str = "ardupilot") -> dict:
    """The autopilot flies the uploaded mission in its mission mode (ArduCopter AUTO, PX4
    AUTO.MISSION); the summary (outcome 'done' when the last waypoint was reached and the
    vehicle landed and disarmed)."""
    reached, t0 = [], time.monotonic()
    if not _arm(conn, AUTO_MODE if dialect == "ardupilot" else PX4_AUTO_MISSION):
        return {"outcome": "not armed in 90 s", "reached": reached}
    say("armed in the mission mode")
    _command(conn, M.MAV_CMD_MISSION_START, 0, 0)
    while time.monotonic() - t0 < timeout:
        m = conn.recv_match(type=["MISSION_ITEM_REACHED", "HEARTBEAT", "STATUSTEXT"], blocking=True, timeout=1)
        if m is None:
            continue
        if m.get_type() == "MISSION_ITEM_REACHED" and m.seq not in reached:
            reached.append(m.seq)
            log({"event": "reached", "seq": m.seq, "wall_us": int(time.time() * 1e6)})
            say(f"item {m.seq} reached")
        elif m.get_type() == "STATUSTEXT":
            log({"event": "statustext", "text": m.text})
        elif m.get_type() == "HEARTBEAT" and m.get_srcSystem() == 1 and m.type == M.MAV_TYPE_QUADROTOR:
            if last_wp in reached and not m.base_mode & M.MAV_MODE_FLAG_SAFETY_ARMED:
                return {"outcome": "done", "reached": reached}
    return {"outcome": f"not finished in {timeout:g} s (items reached: {reached})", "reached": reached}


def _arm(conn, mode, timeout=90.0) -> bool:
    """The mode (asked again until the autopilot's heartbeat shows it: a request before its start-up
    ends is dropped), then armed; False when not within `timeout`."""
    t0 = time.monotonic()
    while time.monotonic() - t0 < timeout:
        conn.mav.set_mode_send(1, M.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED, mode)
        hb = conn.recv_match(type="HEARTBEAT", blocking=True, timeout=2,
                             condition=f"HEARTBEAT.type=={M.MAV_TYPE_QUADROTOR}")
        if hb is not None and hb.custom_mode == mode and _command(conn, M.MAV_CMD_COMPONENT_ARM_DISARM, 1):
            return True
        time.sleep(1.0)
    return False


def fly_loiter_push(conn, log, say, seconds: float, altitude: float) -> dict:
    """With mppid not flying: the pilot's stick pushes ArduCopter in Loiter towards what is ahead
    of its nose (RC_CHANNELS_OVERRIDE, pitch forward, throttle centred) for `seconds`; its simple
    avoidance, fed by the mapper through the bridge's OBSTACLE_DISTANCE, should stop it short."""
    # ArduCopter streams nothing to this link unasked: its altitude, 10 Hz.
    _command(conn, M.MAV_CMD_SET_MESSAGE_INTERVAL, M.MAVLINK_MSG_ID_GLOBAL_POSITION_INT, 100000)
    if not _arm(conn, GUIDED_MODE):
        return {"outcome": "not armed in 90 s"}
    _command(conn, M.MAV_CMD_NAV_TAKEOFF, 0, 0, 0, 0, 0, 0, altitude)
    up = conn.recv_match(type="GLOBAL_POSITION_INT", blocking=True, timeout=30,
                         condition=f"GLOBAL_POSITION_INT.relative_alt>{900 * altitude}")
    if up is None:
        return {"outcome": f"the take-off to {altitude:g} m did not end in 30 s"}

    def sticks(pitch):
        conn.mav.rc_channels_override_send(1, 1, 1500, pitch, 1500, 1500, 0, 0, 0, 0)
    sticks(1500)
    conn.mav.set_mode_send(1, M.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED, LOITER_MODE)
    say(f"Loiter, the pitch stick at {PUSH_PWM} for {seconds:g} s")
    log({"event": "push", "wall_us": int(time.time() * 1e6), "pwm": PUSH_PWM})
    t_end = time.monotonic() + seconds
    while time.monotonic() < t_end:
        sticks(PUSH_PWM)
        time.sleep(0.1)
    sticks(1500)
    log({"event": "released", "wall_us": int(time.time() * 1e6)})
    conn.mav.set_mode_send(1, M.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED, LAND_MODE)
    down = conn.recv_match(type="HEARTBEAT", blocking=True, timeout=60,
                           condition="HEARTBEAT.type==2 and not HEARTBEAT.base_mode & 128")
    return {"outcome": "done" if down is not None else "not landed in 60 s"}


def watch(conn, seconds: float, until=None, pitch: int | None = None):
    """The autopilot's messages for `seconds`, or until `until(message)` holds for one: that
    message, else None. With `pitch`, the ground station's sticks meanwhile: MANUAL_CONTROL at
    STICK_HZ, that pitch, roll and yaw centred, the throttle at mid."""
    end, due = time.monotonic() + seconds, 0.0
    while (now := time.monotonic()) < end:
        if pitch is not None and now >= due:
            conn.mav.manual_control_send(1, pitch, 0, STICK_MID, 0, 0)
            due = now + 1.0 / STICK_HZ
        wait = (min(due, end) if pitch is not None else end) - time.monotonic()
        m = conn.recv_match(blocking=True, timeout=max(0.0, wait))
        if m is not None and until is not None and m.get_srcSystem() == 1 and until(m):
            return m
    return None


def _heartbeat(m) -> bool:
    """The autopilot's own HEARTBEAT (not a ground station's or the bridge's, which PX4 forwards)."""
    return m.get_type() == "HEARTBEAT" and m.type == M.MAV_TYPE_QUADROTOR


def _px4_main_mode(m) -> int:
    return (m.custom_mode >> 16) & 0xFF


def fly_position_push(conn, log, say, seconds: float, altitude: float) -> dict:
    """With mppid not flying: PX4's AUTO.TAKEOFF (MIS_TAKEOFF_ALT), then the ground station's
    sticks (MANUAL_CONTROL, centred, throttle at mid), Position mode, the pitch stick pushed
    forward for `seconds` towards what is ahead of the nose, released, Land; PX4's collision
    prevention, fed by the mapper through the bridge's OBSTACLE_DISTANCE, should stop it short."""
    if not _arm(conn, PX4_AUTO_TAKEOFF):
        return {"outcome": "not armed in 90 s"}
    say(f"armed in AUTO.TAKEOFF, climbing to {altitude:g} m")
    up = watch(conn, 60.0, lambda m: m.get_type() == "GLOBAL_POSITION_INT" and m.relative_alt > 900 * altitude)
    if up is None or watch(conn, 30.0, lambda m: _heartbeat(m) and m.custom_mode == PX4_AUTO_LOITER) is None:
        return {"outcome": f"the take-off to {altitude:g} m did not end in Hold"}
    watch(conn, SETTLE_S, pitch=0)   # PX4 has valid sticks before Position mode is asked for
    conn.mav.command_long_send(1, 1, M.MAV_CMD_DO_SET_MODE, 0, M.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED,
                               PX4_POSCTL_MAIN, 0, 0, 0, 0, 0)
    if watch(conn, 5.0, lambda m: _heartbeat(m) and _px4_main_mode(m) == PX4_POSCTL_MAIN, pitch=0) is None:
        return {"outcome": "PX4 did not take Position mode in 5 s"}
    say(f"Position mode, the pitch stick at {PUSH_STICK / 1000:g} for {seconds:g} s")
    log({"event": "push", "wall_us": int(time.time() * 1e6), "stick": PUSH_STICK / 1000})
    left = watch(conn, seconds, lambda m: _heartbeat(m) and _px4_main_mode(m) != PX4_POSCTL_MAIN, pitch=PUSH_STICK)
    log({"event": "released", "wall_us": int(time.time() * 1e6)})
    summary = {}
    if left is not None:   # e.g. collision prevention's own Hold, after 5 s without obstacle data
        summary["left_position_mode"] = f"{left.custom_mode:#x}"
        say(f"PX4 left Position mode during the push: custom mode {left.custom_mode:#x}")
    watch(conn, SETTLE_S, pitch=0)
    conn.mav.command_long_send(1, 1, M.MAV_CMD_NAV_LAND, 0, 0, 0, 0, math.nan, math.nan, math.nan, math.nan)
    down = watch(conn, 60.0, lambda m: _heartbeat(m) and not m.base_mode & M.MAV_MODE_FLAG_SAFETY_ARMED, pitch=0)
    return {"outcome": "done" if down is not None else "not landed in 60 s", **summary}


def _args(argv):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--url", required=True)
    ap.add_argument("--dialect", choices=DIALECTS, default="ardupilot")
    ap.add_argument("--mission", type=Path, required=True)
    ap.add_argument("--seed", type=int, required=True)
    ap.add_argument("--home", help="lat,lon,alt,heading (the SITL's --home; ArduPilot)")
    ap.add_argument("--lcm-url", required=True)
    ap.add_argument("--out", type=Path, required=True)
    ap.add_argument("--fly-auto", action="store_true", help="fly it with the autopilot's AUTO")
    ap.add_argument("--loiter-push", type=float, default=0.0, metavar="SECONDS",
                    help="instead: take off, Loiter, the pitch stick pushed forward this long, land (ArduPilot)")
    ap.add_argument("--position-push", type=float, default=0.0, metavar="SECONDS",
                    help="instead: take off, Position mode, the pitch stick pushed forward this long, land (PX4)")
    ap.add_argument("--timeout", type=float, default=180.0)
    a = ap.parse_args(argv)
    if a.dialect == "ardupilot" and not a.home:
        ap.error("--home: ArduPilot's mission starts with its home (the SITL's --home)")
    if a.loiter_push > 0 and a.dialect != "ardupilot" or a.position_push > 0 and a.dialect != "px4":
        ap.error("--loiter-push is ArduCopter's Loiter (--dialect ardupilot), --position-push PX4's Position "
                 "mode (--dialect px4)")
    return a


def write_world(doc: dict, seed: int, out: Path) -> list:
    """The world's trees (the mission's, for the seed); world.json for the score: the trees, and
    for a survey its waypoints and the forest's extent."""
    from mppi_mission import plan
    trees = plan.from_dict(doc).trees((0.0, 0.0), seed)
    world = {"trees": trees, "vehicle_radius": float(doc.get("vehicle_radius", 0.2))}
    forest = (doc.get("obstacles") or {}).get("forest")
    if forest and "autopilot_mission" in doc:
        world.update(waypoints=[leg["goal"]["at"] for leg in doc["legs"]],
                     acceptance=[float(leg["goal"].get("radius", 1.0)) for leg in doc["legs"]],
                     forest_box=[forest["x_range"], forest["y_range"]])
    (out / "world.json").write_text(json.dumps(world))
    return trees


def _fly(a, doc, conn, items, trees, say) -> dict:
    """The ground station flies (AUTO, or the Loiter push), recording as the mission tool does."""
    with open(a.out / "mission.jsonl", "w", buffering=1) as f_log:
        def log(rec):
            f_log.write(json.dumps(rec) + "\n")
        log({"event": "mission", "name": doc["name"], "seed": a.seed, "origin": [0.0, 0.0, 0.0], "trees": trees,
             "vehicle_radius": float(doc.get("vehicle_radius", 0.2)), "clock": "boot", "settle": 3.0})
        if a.loiter_push > 0:
            flown = fly_loiter_push(conn, log, say, a.loiter_push, float(doc.get("takeoff", 2.0)))
        elif a.position_push > 0:
            flown = fly_position_push(conn, log, say, a.position_push, float(doc.get("takeoff", 2.0)))
        else:
            flown = fly_auto(conn, last_waypoint(items), log, say, a.timeout, a.dialect)
        controller = "loiter" if a.loiter_push > 0 else "position" if a.position_push > 0 else "auto"
        summary = {"mission": doc["name"], "seed": a.seed, "controller": controller, **flown}
        log({"event": "end", **summary})
    (a.out / "mission_summary.json").write_text(json.dumps(summary, indent=1))
    say(f"outcome: {summary['outcome']}")
    return summary


def main(argv=None) -> int:
    a = _args(argv)
    import yaml
    doc = yaml.safe_load(a.mission.read_text())
    trees = write_world(doc, a.seed, a.out)
    stop = threading.Event()
    signal.signal(signal.SIGTERM, lambda *_: stop.set())

    def say(text):
        print(f"[gcs] {text}", flush=True)

    conn = mavutil.mavlink_connection(a.url, source_system=255, source_component=190, autoreconnect=True)
    conn.wait_heartbeat(timeout=120)
    items = []
    if "autopilot_mission" in doc:
        home = [float(v) for v in a.home.split(",")] if a.home else origin_of(conn)
        items = mission_items(doc, home, a.dialect)
    if items:
        result = upload_when_ready(conn, items)
        if result != M.MAV_MISSION_ACCEPTED:
            say(f"the autopilot refused the mission: MISSION_ACK type {result}")
            return 1
        say(f"mission uploaded: {len(items)} items, {len(trees)} trees in the world")
    threading.Thread(target=publish_world, args=(a.lcm_url, trees, stop), daemon=True).start()
    print(json.dumps({"event": "ready"}), flush=True)
    if not (a.fly_auto or a.loiter_push > 0 or a.position_push > 0):
        while not stop.wait(0.5):
            pass
        return 0
    summary = _fly(a, doc, conn, items, trees, say)
    stop.set()
    return 0 if summary["outcome"] == "done" else 1


if __name__ == "__main__":
    sys.exit(main())
