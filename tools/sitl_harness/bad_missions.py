"""The missions `mppid-mission from-autopilot` must refuse before anything flies (docs/missions.md,
"Missions planned in a ground station"), in one place: the CI test against the simulated
autopilot (test/mavlink/test_autopilot_mission.py) and `tools/sitl refusals` against the real
autopilots' SITL (refusals.py) upload these same missions and expect the same answers.

Each is a list of rows, one an item after ArduPilot's home, the first item numbered 1 as the
ground station numbers it: (command, east, north, z, params, options), east and north metres
from home (0, 0: no position), z metres above home (MAV_FRAME_GLOBAL_RELATIVE_ALT_INT unless
options' `frame` says otherwise). mission() writes them as each autopilot stores them: ArduPilot's
home as item 0, PX4's items from 0 with its take-off at home (lat, lon 0 is a place for PX4, as
QGroundControl writes it) and DO_JUMP's target as PX4's index (the number less 1).

Every command here is one both real autopilots store (PX4 answers MAV_MISSION_UNSUPPORTED to an
item it has no use for, NAV_SPLINE_WAYPOINT among them, and never holds it)."""
from __future__ import annotations

from dataclasses import dataclass

from .ap_gcs import M, item

MISSION_FRAME = {"frame": M.MAV_FRAME_MISSION}
# The bridge's geofence the `fence` mission leaves (its `fence` settings: a 25 m cylinder about
# the local frame's origin, where the vehicle stands).
FENCE = ["fence.shape=cylinder", "fence.center=[0, 0]", "fence.radius=25"]


@dataclass(frozen=True)
class BadMission:
    name: str
    rows: tuple | None          # None: the mission cleared (MISSION_CLEAR_ALL)
    number: int | None          # the item the refusal names, as the ground station numbers it
    reason: tuple[str, ...]     # words of the refusal (any one of them: see `endless`)
    what: str                   # the mission in words (refusals.py's table)


TAKEOFF = (M.MAV_CMD_NAV_TAKEOFF, 0, 0, 2.0)
BAD = (
    BadMission("unflyable", (TAKEOFF, (M.MAV_CMD_NAV_WAYPOINT, 4.0, 0.0, 2.0),
                             (M.MAV_CMD_NAV_LOITER_UNLIM, 4.0, 4.0, 2.0)),
               3, ("NAV_LOITER_UNLIM: mppid cannot fly it",), "a command mppid does not fly (NAV_LOITER_UNLIM)"),
    BadMission("after_land", (TAKEOFF, (M.MAV_CMD_NAV_WAYPOINT, 4.0, 0.0, 2.0), (M.MAV_CMD_NAV_LAND, 4.0, 0.0, 0.0),
                              (M.MAV_CMD_NAV_WAYPOINT, 0.0, 4.0, 2.0)),
               4, ("NAV_WAYPOINT after the landing (item 3)",), "an item after the NAV_LAND"),
    BadMission("fence", (TAKEOFF, (M.MAV_CMD_NAV_WAYPOINT, 40.0, 0.0, 2.0)),
               2, ("NAV_WAYPOINT leaves the geofence",), "a leg out of the bridge's 25 m geofence"),
    # DO_JUMP to item 2 with repeat -1 (for ever). PX4 keeps the repeat count as an unsigned
    # 16-bit number: what it gives back for -1 is a count the tool unrolls past its limit.
    BadMission("endless", (TAKEOFF, (M.MAV_CMD_NAV_WAYPOINT, 4.0, 0.0, 2.0),
                           (M.MAV_CMD_DO_JUMP, 0, 0, 0, (2, -1, 0, 0), MISSION_FRAME)),
               3, ("repeat -1 loops for ever", "DO_JUMP unrolls the mission past 1000 items"),
               "a DO_JUMP repeated for ever"),
    BadMission("empty", None, None, ("the autopilot's mission is empty",), "no mission (cleared)"),
)


def _row(row) -> tuple:
    """(command, east, north, z, params, options) with the defaults filled in."""
    opts = row[-1] if isinstance(row[-1], dict) else {}
    row = row[:-1] if opts else row
    cmd, east, north, z, p = (tuple(row) + (0.0, 0.0, 0.0, (0, 0, 0, 0))[len(row) - 1:])[:5]
    return cmd, float(east), float(north), float(z), tuple(p), opts


def mission(dialect: str, home, *rows) -> list:
    """The rows as MISSION_ITEM_INTs in the dialect's numbering, about `home` (lat, lon deg,
    alt m AMSL): ArduPilot's home first as item 0; PX4's from 0."""
    first = 1 if dialect == "ardupilot" else 0
    out = [item(0, M.MAV_CMD_NAV_WAYPOINT, home, z=home[2], frame=M.MAV_FRAME_GLOBAL_INT)] if first else []
    for k, row in enumerate(rows):
        cmd, east, north, z, p, opts = _row(row)
        if cmd == M.MAV_CMD_DO_JUMP:   # the target as the dialect numbers it
            p = (p[0] - 1 + first,) + p[1:]
        m = item(first + k, cmd, home, east, north, z, p, opts.get("frame", M.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT))
        if dialect == "px4" and cmd == M.MAV_CMD_NAV_TAKEOFF and (east, north) == (0.0, 0.0):
            m.x, m.y = int(round(home[0] * 1e7)), int(round(home[1] * 1e7))
        out.append(m)
    return out
