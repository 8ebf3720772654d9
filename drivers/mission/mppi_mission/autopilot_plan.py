"""The autopilot's mission (its items as the bridge read them: `mission download`) as the
mission tool's plan (plan.py): legs in the autopilot's local frame, ENU, each leg knowing the
item it flies. What it cannot fly is refused, naming the item as the ground station numbers
it (the first item is 1: ArduPilot's seq, PX4's seq + 1, ArduPilot's item 0 being home).

    NAV_TAKEOFF           the autopilot's take-off to its altitude (the mission's `takeoff`);
                          none when the vehicle is already flying
    NAV_WAYPOINT          a line to it at the mission's speed, then until within its acceptance
                          radius (param2; 0: DEFAULT_RADIUS), then its hold time (param1)
    NAV_LOITER_TIME       a line to it (lat, lon 0: where the vehicle is), held param1 s
    NAV_LAND              a line to above it (lat, lon 0: where it is), then the landing
    NAV_RETURN_TO_LAUNCH  the autopilot's own: the legs before it flown, the vehicle is handed
                          back there (`handback_item`: ArduPilot AUTO from this item, PX4
                          AUTO.RTL; from_autopilot.py)
    DO_CHANGE_SPEED       the lines after it at param2 m/s (-1, 0: unchanged)
    CONDITION_YAW         the heading param1 deg (param4 1: relative, param3 -1: counter-
                          clockwise) held at where it is while it turns, and by the legs after it
    DO_JUMP               to item param1, param2 times more (unrolled; -1, for ever, refused, and
                          so is a mission unrolled past MAX_LEGS: PX4 gives a -1 back as 65535)
Positions: MAV_FRAME_GLOBAL(_INT) (altitude above mean sea level) and
MAV_FRAME_GLOBAL_RELATIVE_ALT(_INT) (above home) against the local frame's origin
(GPS_GLOBAL_ORIGIN) and home (HOME_POSITION), flat earth (a mission spans a few km at most).
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
from mppi_mavlink import fence as fence_mod
from pymavlink import mavutil

from . import plan as plan_mod

mavlink = mavutil.mavlink
EARTH_RADIUS = 6378137.0
DEFAULT_RADIUS = 1.0      # m: a waypoint's acceptance radius when it gives none
MAX_LEGS = 1000           # DO_JUMPs unrolled past this: refused
ABSOLUTE_FRAMES = (mavlink.MAV_FRAME_GLOBAL, mavlink.MAV_FRAME_GLOBAL_INT)
RELATIVE_FRAMES = (mavlink.MAV_FRAME_GLOBAL_RELATIVE_ALT, mavlink.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT)
NAV = {mavlink.MAV_CMD_NAV_TAKEOFF, mavlink.MAV_CMD_NAV_WAYPOINT, mavlink.MAV_CMD_NAV_LOITER_TIME,
       mavlink.MAV_CMD_NAV_LAND, mavlink.MAV_CMD_NAV_RETURN_TO_LAUNCH}


class Refusal(ValueError):
    def __init__(self, number: int | None, reason: str):
        self.number, self.reason = number, reason
        super().__init__(f"mission item {number}: {reason}" if number is not None else f"mission: {reason}")


def command_name(cmd: int) -> str:
    e = mavlink.enums["MAV_CMD"].get(cmd)
    return e.name.replace("MAV_CMD_", "") if e is not None else f"command {cmd}"


@dataclass
class Converted:
    mission: plan_mod.Mission
    leg_items: list[int]                 # the seq each leg flies
    numbers: dict[int, int]              # seq -> the number the ground station shows
    names: dict[int, str]                # seq -> its command's name
    takeoff_item: int | None = None
    count: int = 0
    handback_item: int | None = None     # the NAV_RETURN_TO_LAUNCH the autopilot flies itself
    dialect: str = "px4"
    notes: list[str] = field(default_factory=list)


class _Frame:
    """Global positions -> local ENU: the origin (lat, lon, alt AMSL) and home."""

    def __init__(self, origin, home):
        self.lat0, self.lon0, self.alt0 = origin
        self.home_alt = home[2]
        self.home = self.local(home[0], home[1], home[2])

    def local(self, lat, lon, alt_amsl):
        north = math.radians(lat - self.lat0) * EARTH_RADIUS
        east = math.radians(lon - self.lon0) * EARTH_RADIUS * math.cos(math.radians(self.lat0))
        return np.array([east, north, alt_amsl - self.alt0])

    def point(self, it, number, here):
        """The item's position, local ENU; lat, lon 0: above `here`."""
        if it["frame"] in RELATIVE_FRAMES:
            alt = self.home_alt + it["z"]
        elif it["frame"] in ABSOLUTE_FRAMES:
            alt = it["z"]
        else:
            name = mavlink.enums["MAV_FRAME"][it["frame"]].name if it["frame"] in mavlink.enums["MAV_FRAME"] else \
                str(it["frame"])
            raise Refusal(number, f"{command_name(it['command'])} in frame {name}: mppid flies global frames only "
                                  f"(MAV_FRAME_GLOBAL, MAV_FRAME_GLOBAL_RELATIVE_ALT)")
        if it["x"] == 0 and it["y"] == 0:
            return np.array([here[0], here[1], alt - self.alt0])
        return self.local(it["x"] * 1e-7, it["y"] * 1e-7, alt)


def unrolled(items: list[dict], first: int, start: int, number) -> list[dict]:
    """The items in flight order from `start`, DO_JUMPs taken (each param2 times)."""
    out, left, i, by_seq = [], {}, start, {it["seq"]: k for k, it in enumerate(items)}
    jump = None      # the DO_JUMP taken last: what an unrolling past MAX_LEGS is named by
    while i < len(items):
        it = items[i]
        if it["command"] != mavlink.MAV_CMD_DO_JUMP:
            out.append(it)
            i += 1
        else:
            target, repeat = int(it["param1"]), int(it["param2"])
            if repeat < 0:
                raise Refusal(number(it["seq"]), "DO_JUMP with repeat -1 loops for ever: mppid flies missions "
                                                 "that end")
            if target not in by_seq or target < first:
                raise Refusal(number(it["seq"]), f"DO_JUMP to item {target}: no such item")
            left.setdefault(i, repeat)
            if left[i] > 0:
                left[i] -= 1
                jump = it["seq"]
                i = by_seq[target]
            else:
                i += 1
        if len(out) > MAX_LEGS:
            raise Refusal(number(it["seq"] if jump is None else jump),
                          f"DO_JUMP unrolls the mission past {MAX_LEGS} items")
    return out


class _Builder:
    """Legs item by item, from where the vehicle is (`here`)."""

    def __init__(self, frame: _Frame, here, speed: float, heading_deg: float | None, airborne: bool):
        self.frame, self.here, self.speed = frame, np.asarray(here, float), speed
        self.yaw, self.airborne = heading_deg, airborne
        self.legs, self.leg_items = [], []
        self.yaw_set = False
        self.takeoff = self.takeoff_item = None
        self.land_item = self.handback_item = None
        self.start = self.here.copy()         # where the first leg starts (after the take-off)

    def add(self, seq, kind, args):
        if self.yaw_set:
            args = {**args, "yaw": round(self.yaw, 6)}
        self.legs.append({kind: args})
        self.leg_items.append(seq)

    def line_to(self, seq, p):
        if np.linalg.norm(p - self.here) > 0.05:
            self.add(seq, "line", {"to": [float(c) for c in p], "speed": self.speed})
        self.here = np.asarray(p, float)

    def item(self, it, number):
        cmd, seq = it["command"], it["seq"]
        if self.land_item is not None:
            raise Refusal(number, f"{command_name(cmd)} after the landing (item {self.land_number}): the mission ends "
                                  f"there")
        if cmd == mavlink.MAV_CMD_NAV_TAKEOFF:
            return self._takeoff(it, number)
        if cmd == mavlink.MAV_CMD_NAV_WAYPOINT:
            p = self.frame.point(it, number, self.here)
            self.line_to(seq, p)
            radius = it["param2"] if it["param2"] > 0 else DEFAULT_RADIUS
            self.add(seq, "goal", {"at": [float(c) for c in p], "radius": float(radius), "timeout": 60.0})
            if it["param1"] > 0:
                self.add(seq, "hold", {"for": float(it["param1"])})
        elif cmd == mavlink.MAV_CMD_NAV_LOITER_TIME:
            self.line_to(seq, self.frame.point(it, number, self.here))
            self.add(seq, "hold", {"for": float(max(it["param1"], 0.0))})
        elif cmd == mavlink.MAV_CMD_NAV_RETURN_TO_LAUNCH:
            self.handback_item = seq
            self.land_item, self.land_number = seq, number
        elif cmd == mavlink.MAV_CMD_NAV_LAND:
            # where it is (lat, lon 0), or above the point given; its altitude: the ground's
            p = self.here if it["x"] == 0 and it["y"] == 0 else self.frame.point(it, number, self.here)
            self.line_to(seq, np.array([p[0], p[1], self.here[2]]))
            if not self.legs or self.leg_items[-1] != seq:
                self.add(seq, "hold", {"for": 0.5})
            self.land_item, self.land_number = seq, number
        elif cmd == mavlink.MAV_CMD_DO_CHANGE_SPEED:
            if it["param2"] > 0:
                if it["param2"] > 30:
                    raise Refusal(number, f"DO_CHANGE_SPEED to {it['param2']:g} m/s: mppid flies up to 30 m/s")
                self.speed = float(it["param2"])
        elif cmd == mavlink.MAV_CMD_CONDITION_YAW:
            self._yaw(it, number)
        else:
            raise Refusal(number, f"{command_name(cmd)}: mppid cannot fly it (it flies NAV_TAKEOFF, NAV_WAYPOINT, "
                                  f"NAV_LOITER_TIME, NAV_LAND, NAV_RETURN_TO_LAUNCH, DO_CHANGE_SPEED, CONDITION_YAW, "
                                  f"DO_JUMP)")
        return None

    def _takeoff(self, it, number):
        if self.legs:
            raise Refusal(number, "NAV_TAKEOFF after the mission's first leg")
        p = self.frame.point({**it, "x": 0, "y": 0}, number, self.here)
        alt = float(p[2] - self.frame.home[2])
        if not 0.5 <= alt <= 100:
            raise Refusal(number, f"NAV_TAKEOFF to {alt:.1f} m above home: mppid takes off to 0.5..100 m")
        self.takeoff_item = it["seq"]
        if not self.airborne:
            self.takeoff = alt
            self.here = self.start = np.array([self.here[0], self.here[1], p[2]])

    def _yaw(self, it, number):
        angle = float(it["param1"])
        if it["param4"] >= 1:   # relative: param3 -1 counter-clockwise, else clockwise (NED)
            if self.yaw is None:
                raise Refusal(number, "CONDITION_YAW relative to a heading not known yet")
            self.yaw -= angle * (-1.0 if it["param3"] < 0 else 1.0)
        else:
            self.yaw = 90.0 - angle          # NED heading (from north, clockwise) -> ENU degrees
        self.yaw = math.remainder(self.yaw, 360.0)
        self.yaw_set = True
        rate = it["param2"] if it["param2"] > 0 else 45.0
        self.add(it["seq"], "hold", {"for": float(max(2.0, min(angle, 360.0) / rate))})


def _finite(it: dict, number: int) -> dict:
    """The item with its unset (NaN) params as 0, their default here; a position or a heading
    that is not a number refused."""
    cmd = it["command"]
    if cmd in NAV and cmd != mavlink.MAV_CMD_NAV_RETURN_TO_LAUNCH and not math.isfinite(it["z"]):
        raise Refusal(number, f"{command_name(cmd)}: its altitude is not a number")
    if cmd == mavlink.MAV_CMD_CONDITION_YAW and not math.isfinite(it["param1"]):
        raise Refusal(number, "CONDITION_YAW: its angle is not a number")
    return {**it, **{k: 0.0 for k in ("param1", "param2", "param3", "param4") if not math.isfinite(it[k])}}


def convert(dl: dict, here, heading_deg: float | None = None, airborne: bool = False, speed: float = 2.0,
            start_seq: int | None = None, end_seq: int | None = None) -> Converted:
    """The plan of the mission `dl` (the bridge's `mission download`), flown from `here`
    (local ENU) with the heading `heading_deg` (ENU degrees, None unknown), from item
    `start_seq` (None: the first) up to, not including, `end_seq` (None: to its end).
    Raises Refusal naming the item."""
    ardupilot = dl["dialect"] == "ardupilot"
    first = 1 if ardupilot else 0

    def number(seq):
        return seq if ardupilot else seq + 1

    items = [_finite(it, number(it["seq"])) for it in dl["items"]
             if it["seq"] >= first and (end_seq is None or it["seq"] < end_seq)]

    if not items:
        raise Refusal(None, "the autopilot's mission is empty: plan one in the ground station and upload it")
    if dl.get("origin") is None or dl.get("home") is None:
        raise Refusal(None, "the autopilot has no home or origin yet (no position fix)")
    start = first if start_seq is None or start_seq < first else start_seq
    frame = _Frame(dl["origin"], dl["home"])
    b = _Builder(frame, here, speed, heading_deg, airborne)
    for it in unrolled(items, first, start - first, number):
        b.item(it, number(it["seq"]))
    if not b.legs:
        raise Refusal(number(items[-1]["seq"]), "the mission has no leg mppid flies (NAV_WAYPOINT, NAV_LOITER_TIME, "
                                                "NAV_LAND, NAV_RETURN_TO_LAUNCH)")
    if b.takeoff is None and not airborne:
        raise Refusal(number(items[0]["seq"]), "the vehicle is on the ground and the mission has no NAV_TAKEOFF")
    doc = {"name": "autopilot", "frame": "local", "land": b.land_item is not None and b.handback_item is None,
           "legs": b.legs}
    if b.takeoff is not None:
        doc["takeoff"] = round(b.takeoff, 3)
    try:
        mission = plan_mod.from_dict(doc)
    except plan_mod.PlanError as e:   # a value out of the plan's range: the leg's item named
        leg = next((int(w[5:].split("]")[0]) for w in str(e).split() if w.startswith("legs[")), None)
        raise Refusal(None if leg is None else number(b.leg_items[leg]), str(e)) from None
    out = Converted(mission, b.leg_items, {it["seq"]: number(it["seq"]) for it in items},
                    {it["seq"]: command_name(it["command"]) for it in items}, b.takeoff_item, len(dl["items"]),
                    b.handback_item, dl["dialect"])
    _check_fence(out, dl.get("fence"), b.start)
    return out


def _check_fence(c: Converted, fence_doc, here):
    """Every leg inside the bridge's fence (its `fence` settings), from where the vehicle is."""
    try:
        c.mission.fence = fence_mod.parse(fence_doc or None)
    except fence_mod.FenceError as e:
        raise Refusal(None, f"the bridge's {e}") from None
    breach = plan_mod.fence_breach(c.mission, start=here)
    if breach is not None:
        leg, why = breach
        seq = c.leg_items[leg]
        raise Refusal(c.numbers[seq], f"{c.names[seq]} leaves the geofence: {why}")
