"""A mission: what the operator asks the vehicle to do, as a file (config/missions/*.yaml)
or built from the command line. Validated at load; an error names the field.

    name: circle_3ms
    frame: start          # start (default): x, y relative to where the mission starts, z above
                          # home; local: the autopilot's local frame as it is
    task: quadrotor_rate_forest    # the mppid task file it is meant for, and the settings over it
    mppid: {set: [cost.w_speed=8]} # that mppid flies it with (the harness passes them)
    takeoff: 2.0          # arm and take off with the autopilot's own take-off (through the bridge)
    land: true            # land at the end (default: when it took off)
    vehicle_radius: 0.2
    yaw: hold             # the heading: hold (default: the one the vehicle has at the hand-over),
                          # path (facing along each line, waypoint segment or towards a goal), or
                          # degrees (0: +x, counter-clockwise); a leg's own `yaw` overrides it.
                          # Curves take hold or degrees: mppid's reference carries one held yaw.
    obstacles:            # virtual trees: only mppid knows them (published on MPPI_OBSTACLES)
      trees: [[x, y, r], ...]
      forest: {spacing: 4, jitter: 0.5, radius: 0.3, radius_jitter: 0.1, x_range: [4, 26],
               y_range: [-8, 8], clear_radius: 2.5}     # seeded by --seed
    legs:
      - hold: {for: 3}                                  # where the last leg ended (or [x, y, z] `at`)
      - goal: {at: [40, 0, 2], radius: 1.0, timeout: 40}
      - line: {to: [10, 0, 2], speed: 2}
      - waypoints: {points: [[10, 0, 2], [10, 10, 2]], speed: 2}
      - circle: {center: [-5, 0, 2], radius: 5, speed: 3, laps: 2}
      - figure_eight: {center: [0, 0, 2], radius: 5, speed: 3, laps: 1}
    sensing:              # the trees are sensed, not told (the simulator's sensing block, read
      publish_obstacles: false  # by the harness's sensor node): the trees go on MPPI_WORLD (the
      depth_camera: {...}       # world's, for the sensors), not MPPI_OBSTACLES; the map mppid
                                # gets is mppid-mapper's (docs/sensing.md)
    mapper: {config: config/mapper/mapper.yaml, set: []}   # the harness's mppid-mapper
    score: {settle: 3.0}  # tracking error counts this long after a path reaches full speed
    fence: {shape: cylinder, center: [0, 0], radius: 30, min_z: 0.5, max_z: 10}
                          # or {shape: box, min: [x, y], max: [x, y], ...}: every leg is checked
                          # against it before flight, vehicle_radius inside (the mission's frame;
                          # the start taken at x, y = 0 at the take-off altitude); the bridge
                          # holds the vehicle at its own (config/bridge: fence)

Every path starts at rest, ramps to its speed over `ramp` seconds (default: speed / 1 m/s²,
at least 1 s) and ramps down to rest at its end, from the point where the previous leg ended;
a circle or figure-eight begins at its point nearest to there, reached first along a line if
it is more than 0.5 m away, and ends after its laps where it began.
"""
from __future__ import annotations

import copy
import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import yaml

from mppi_mavlink import fence as fence_mod

from . import forest, reference

LEG_KEYS = {
    "hold": {"at", "for", "yaw"},
    "goal": {"at", "radius", "timeout", "yaw"},
    "line": {"to", "speed", "ramp", "yaw"},
    "waypoints": {"points", "speed", "ramp", "yaw"},
    "circle": {"center", "radius", "speed", "ramp", "laps", "yaw"},
    "figure_eight": {"center", "radius", "speed", "ramp", "laps", "yaw"},
}
TOP_KEYS = {"name", "description", "task", "mppid", "frame", "takeoff", "land", "vehicle_radius", "obstacles", "legs",
            "score", "fence", "yaw", "sensing", "mapper", "autopilot_mission", "wall_timeout"}
WORLD_CHANNEL = "MPPI_WORLD"  # a sensed mission's trees: the world's, which only the sensors see
CURVES = ("circle", "figure_eight")
TRANSIT_SPEED = 2.0  # m/s: the line to a curve's start point, when the vehicle is off it
ON_PATH = 0.5        # m: closer than this to a curve's start point needs no transit


class PlanError(ValueError):
    pass


@dataclass
class Mission:
    name: str
    legs: list[dict]
    frame: str = "start"
    takeoff: float | None = None
    land: bool = False
    vehicle_radius: float = 0.2
    obstacles: dict = field(default_factory=dict)
    settle: float = 3.0
    task: str | None = None
    fence: fence_mod.Fence | None = None
    yaw: str | float = "hold"
    sensing: dict = field(default_factory=dict)

    @property
    def trees_channel(self) -> str | None:
        """Where the trees go: MPPI_OBSTACLES (mppid's, the default) or, when the mission's
        sensing says publish_obstacles: false, MPPI_WORLD (the sensors')."""
        return WORLD_CHANNEL if self.sensing.get("publish_obstacles", True) is False else None

    def trees(self, origin_xy, seed: int) -> list[tuple[float, float, float]]:
        """The virtual trees in local coordinates (the forest seeded by `seed`)."""
        ox, oy = origin_xy
        out = [(float(x) + ox, float(y) + oy, float(r)) for x, y, r in self.obstacles.get("trees", [])]
        f = self.obstacles.get("forest")
        if f:
            f = {**f, "seed": seed}
            keep = [(0.0, 0.0)] + [tuple(leg["goal"]["at"][:2]) for leg in self.legs if "goal" in leg]
            out += [(x + ox, y + oy, r) for x, y, r in forest.make_forest(f, keep)]
        return out


def load(path: str | Path) -> Mission:
    doc = yaml.safe_load(Path(path).read_text())
    if not isinstance(doc, dict):
        raise PlanError(f"{path}: expected a map")
    return from_dict(doc, default_name=Path(path).stem)


def from_dict(doc: dict, default_name="mission") -> Mission:
    unknown = set(doc) - TOP_KEYS
    if unknown:
        raise PlanError(f"{sorted(unknown)[0]}: unknown field (fields: {', '.join(sorted(TOP_KEYS))})")
    legs, yaw = _checked_legs(doc)
    frame = doc.get("frame", "start")
    if frame not in ("start", "local"):
        raise PlanError(f"frame: start or local, got {frame!r}")
    takeoff = doc.get("takeoff")
    if takeoff is not None and not _num(takeoff, 0.5, 100):
        raise PlanError(f"takeoff: an altitude in [0.5, 100] m, got {takeoff!r}")
    obstacles = _checked_obstacles(doc)
    score = doc.get("score") or {}
    settle = score.get("settle", 3.0)
    if not _num(settle, 0, 600):
        raise PlanError("score.settle: seconds in [0, 600]")
    vr = doc.get("vehicle_radius", 0.2)
    if not _num(vr, 0, 5):
        raise PlanError("vehicle_radius: metres in [0, 5]")
    sensing = doc.get("sensing") or {}
    if not isinstance(sensing, dict) or not isinstance(sensing.get("publish_obstacles", True), bool):
        raise PlanError("sensing: a mapping (the simulator's sensing block), publish_obstacles true or false")
    try:
        fence = fence_mod.parse(doc.get("fence"))
    except fence_mod.FenceError as e:
        raise PlanError(str(e)) from None
    m = Mission(name=str(doc.get("name", default_name)), legs=copy.deepcopy(legs), frame=frame,
                takeoff=None if takeoff is None else float(takeoff),
                land=bool(doc.get("land", takeoff is not None)), vehicle_radius=float(vr),
                obstacles=obstacles, settle=float(settle), task=doc.get("task"), fence=fence, yaw=yaw,
                sensing=sensing)
    check_fence(m)
    return m


def _checked_legs(doc: dict) -> tuple[list, object]:
    """The legs (each checked, its yaw against the mission's) and the mission's yaw."""
    legs = doc.get("legs")
    if not isinstance(legs, list) or not legs:
        raise PlanError("legs: a list of at least one leg")
    yaw = doc.get("yaw", "hold")
    _check_yaw("yaw", yaw)
    for i, leg in enumerate(legs):
        _check_leg(i, leg)
        kind, a = next(iter(leg.items()))
        _check_yaw(f"legs[{i}].{kind}.yaw", a.get("yaw", yaw), kind)
    return legs, yaw


def _checked_obstacles(doc: dict) -> dict:
    """obstacles: trees [x, y, radius] and/or a forest."""
    obstacles = doc.get("obstacles") or {}
    if set(obstacles) - {"trees", "forest"}:
        raise PlanError("obstacles: trees and/or forest")
    for j, tr in enumerate(obstacles.get("trees", [])):
        if not (isinstance(tr, list) and len(tr) == 3 and all(_num(c) for c in tr) and tr[2] > 0):
            raise PlanError(f"obstacles.trees[{j}]: [x, y, radius] with radius > 0")
    return obstacles


def check_fence(m: Mission, dt: float = 0.05):
    """Every leg inside the mission's fence, vehicle_radius inside it, sampled every `dt` s of
    its reference; the first point outside names its leg."""
    breach = fence_breach(m, dt)
    if breach is not None:
        raise PlanError(f"fence: legs[{breach[0]}].{breach[1]}")


def fence_breach(m: Mission, dt: float = 0.05, start=None) -> tuple[int, str] | None:
    """The first leg leaving the fence and why ('<kind> leaves it at (x, y, z): <why>'), or
    None; flown from `start` (default: x, y = 0 at the take-off altitude or the first leg's)."""
    if m.fence is None:
        return None
    first_z = next((leg_a[k][2] for leg in m.legs for leg_a in leg.values() for k in ("at", "to", "center")
                    if k in (leg_a or {})), 0.0)
    here = np.array([0.0, 0.0, m.takeoff if m.takeoff is not None else first_z]) if start is None else \
        np.asarray(start, float)
    for i in range(len(m.legs)):
        for step in steps(m, i, here, np.zeros(3)):
            if step.duration is None or step.kind in ("hold", "goal"):
                pts = [np.asarray(step.ref["center"], float)]
            else:
                pts = reference.evaluate(step.ref, np.arange(0.0, step.duration + dt, dt))[0]
            for p in pts:
                why = m.fence.breach(p, m.vehicle_radius)
                if why:
                    return i, f"{step.kind} leaves it at ({p[0]:.1f}, {p[1]:.1f}, {p[2]:.1f}): {why}"
            here = step.end
    return None


def _num(v, lo=-1e6, hi=1e6) -> bool:
    return isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v) and lo <= v <= hi


def _check_yaw(where: str, v, kind: str = ""):
    if _num(v, -360, 360) or v == "hold":
        return
    if v == "path":
        if kind in CURVES:
            raise PlanError(f"{where}: path faces along lines only: mppid's reference carries one held heading, "
                            f"so a {kind} takes hold or degrees")
        return
    raise PlanError(f"{where}: hold, path or degrees in [-360, 360], got {v!r}")


def _point(v) -> bool:
    return isinstance(v, list) and len(v) == 3 and all(_num(c) for c in v)


def _check_points(where: str, kind: str, a: dict):
    """The leg's points: each [x, y, z]; a goal's `at`, a line's `to`, the waypoints' list."""
    for key in ("at", "to", "center"):
        if key in a and not _point(a[key]):
            raise PlanError(f"{where}.{key}: a point [x, y, z]")
    if kind in ("goal",) and "at" not in a:
        raise PlanError(f"{where}.at: required")
    if kind == "line" and "to" not in a:
        raise PlanError(f"{where}.to: required")
    if kind == "waypoints" and not (isinstance(a.get("points"), list) and a["points"]
                                    and all(_point(p) for p in a["points"])):
        raise PlanError(f"{where}.points: a list of points [x, y, z]")


def _check_curve(where: str, a: dict):
    """A circle's or figure-eight's center, radius and speed (required), radius and laps in range."""
    for key in ("center", "radius", "speed"):
        if key not in a:
            raise PlanError(f"{where}.{key}: required")
    if not _num(a["radius"], 0.5, 1000):
        raise PlanError(f"{where}.radius: metres in [0.5, 1000]")
    if not _num(a.get("laps", 1), 0.1, 1000):
        raise PlanError(f"{where}.laps: in [0.1, 1000]")


def _check_leg(i: int, leg):
    if not isinstance(leg, dict) or len(leg) != 1 or next(iter(leg)) not in LEG_KEYS:
        raise PlanError(f"legs[{i}]: one of {', '.join(LEG_KEYS)}, as `- kind: {{...}}`")
    kind, a = next(iter(leg.items()))
    a = a or {}
    leg[kind] = a
    where = f"legs[{i}].{kind}"
    if set(a) - LEG_KEYS[kind]:
        raise PlanError(f"{where}.{sorted(set(a) - LEG_KEYS[kind])[0]}: unknown (fields: {sorted(LEG_KEYS[kind])})")
    _check_points(where, kind, a)
    if kind in ("circle", "figure_eight"):
        _check_curve(where, a)
    if kind in ("line", "waypoints", "circle", "figure_eight") and not _num(a.get("speed", 1.0), 0.05, 30):
        raise PlanError(f"{where}.speed: m/s in [0.05, 30]")
    if "ramp" in a and not _num(a["ramp"], 0, 60):
        raise PlanError(f"{where}.ramp: seconds in [0, 60]")
    for key, lo, hi in (("for", 0, 1e6), ("radius", 0.05, 100), ("timeout", 0.1, 1e4)):
        if key in a and kind in ("hold", "goal") and not _num(a[key], lo, hi):
            raise PlanError(f"{where}.{key}: in [{lo}, {hi}]")


# ---- legs at run time ------------------------------------------------------------------
@dataclass
class Step:
    """One reference the runner publishes until its end condition: a leg, or one piece of
    it (a transit line, a waypoint's line)."""
    leg: int
    kind: str                  # hold, goal, line, circle, figure_eight
    ref: dict                  # reference.py's dict (goal: a hold at the goal)
    duration: float | None     # s after t0; None: until reached (goal) or forever (hold)
    goal_radius: float = 1.0
    timeout: float | None = None
    transit: bool = False      # a line to a curve's start, not what the leg asked for

    @property
    def end(self) -> np.ndarray:
        if self.kind in ("hold", "goal"):
            return np.asarray(self.ref["center"], float)
        t = 1e9 if self.duration is None else self.duration
        return reference.evaluate(self.ref, [t])[0][0]

    @property
    def full_speed_at(self) -> float:
        return float(self.ref.get("ramp", 0.0))


def default_ramp(speed: float) -> float:
    return max(1.0, speed / 1.0)


def steps(mission: Mission, leg_index: int, here, origin, heading: float = 0.0) -> list[Step]:
    """The steps of one leg, started where the previous one ended (`here`, local ENU, with the
    heading `heading`, rad); `origin` maps the mission's x, y to local ones (frame: start).
    Each step's reference carries its yaw (rad, ENU)."""
    kind, a = next(iter(mission.legs[leg_index].items()))
    out = _steps(mission, leg_index, kind, a, np.asarray(here, float), origin)
    spec = a.get("yaw", mission.yaw)
    for st in out:
        st.ref["yaw"] = _yaw(spec, st, heading)
        heading = st.ref["yaw"]
    return out


def _yaw(spec, step: Step, heading: float) -> float:
    """The step's heading: held, in degrees, or along the step's line (towards its goal)."""
    if spec == "hold":
        return float(heading)
    if spec != "path":
        return math.radians(float(spec))
    if step.kind == "line":
        d = np.asarray(step.ref["end"], float) - np.asarray(step.ref["center"], float)
    elif step.kind == "goal":
        d = np.asarray(step.ref["center"], float) - np.asarray(step.ref.get("from", step.ref["center"]), float)
    else:
        return float(heading)
    return float(math.atan2(d[1], d[0])) if math.hypot(d[0], d[1]) > 1e-6 else float(heading)


def _steps(mission: Mission, leg_index: int, kind: str, a: dict, here, origin) -> list[Step]:
    def loc(p):
        p = np.asarray(p, float).copy()
        p[:2] += origin[:2]
        return p

    if kind == "hold":
        at = loc(a["at"]) if "at" in a else here
        return [Step(leg_index, "hold", {"kind": "hold", "center": at.tolist()}, a.get("for"))]
    if kind == "goal":
        at = loc(a["at"])
        return [Step(leg_index, "goal", {"kind": "hold", "center": at.tolist(), "from": here.tolist()}, None,
                     goal_radius=float(a.get("radius", 1.0)), timeout=a.get("timeout", 60.0))]
    speed = float(a.get("speed", 1.0))
    ramp = float(a.get("ramp", default_ramp(speed)))
    if kind in ("line", "waypoints"):
        pts = [a["to"]] if kind == "line" else a["points"]
        out, prev = [], here
        for p in pts:
            out.append(_line(leg_index, prev, loc(p), speed, ramp))
            prev = loc(p)
        return out
    laps, radius = float(a.get("laps", 1.0)), float(a["radius"])
    speed = reference.line_speed(laps * 2 * math.pi * radius, speed, ramp)  # a lap too short to reach it
    ref = {"kind": kind, "center": loc(a["center"]).tolist(), "radius": radius, "speed": speed, "ramp": ramp}
    ref["phase"] = _nearest_phase(ref, here)
    ref["end_s"] = reference.duration(ref, laps)
    start = reference.evaluate({**ref, "speed": 0.0}, [0.0])[0][0]
    curve = Step(leg_index, kind, ref, ref["end_s"])
    if np.linalg.norm(start - here) <= ON_PATH:
        return [curve]
    t_speed = min(TRANSIT_SPEED, speed)
    return [_line(leg_index, here, start, t_speed, default_ramp(t_speed), transit=True), curve]


def _line(leg, a, b, speed, ramp, transit=False) -> Step:
    ref = {"kind": "line", "center": np.asarray(a, float).tolist(), "end": np.asarray(b, float).tolist(),
           "speed": speed, "ramp": ramp}
    return Step(leg, "line", ref, reference.duration(ref), transit=transit)


def _nearest_phase(ref: dict, p) -> float:
    """The curve parameter whose point is nearest p (circle: exactly; figure-eight: on a grid)."""
    c = np.asarray(ref["center"], float)
    if ref["kind"] == "circle":
        return float(math.atan2(p[1] - c[1], p[0] - c[0]))
    a = np.linspace(0.0, 2 * np.pi, 720, endpoint=False)
    r = ref["radius"]
    d = (c[0] + r * np.sin(a) - p[0]) ** 2 + (c[1] + 0.5 * r * np.sin(2 * a) - p[1]) ** 2
    return float(a[int(np.argmin(d))])
