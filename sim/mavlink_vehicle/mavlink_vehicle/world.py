"""The flight's world and mission, for tests: what a mission planner and a perception stack
would give mppid on a real vehicle (reference_t, obstacles_t on LCM), and the referee
(collisions, goal, tracking error) that reads the plant's truth.

A world file (sim/mavlink_vehicle/worlds/*.yaml):
    start: [x, y]            take-off spot on the ground, ENU m
    altitude: 2.0            the hold point before the mission: start at this height
    reference: {kind: circle, center: [0,0,2], radius: 3, speed: 2}   or  {kind: waypoint}
    goal: [x, y, z]          waypoint missions; goal_radius
    forest: {spacing, jitter, radius, radius_jitter, x_range, y_range, clear_radius, seed}
    mission: {settle_hold: 1.0, duration: 10.0, settle: 3.0, timeout: 40}
    vehicle_radius: 0.2
The mission starts once the vehicle has held the hold point (within 0.5 m; `start: on_hold`)
or its altitude (`start: on_offboard`) for settle_hold seconds under offboard control; circle missions then run `duration` s (the RMSE counts
after `settle` s), waypoint missions until the goal (or `timeout`).
"""
from __future__ import annotations

import math

import yaml

from mppi_mavlink.layout import QuadrotorRate as Q
from mppi_mission import forest


def load_world(path) -> dict:
    w = yaml.safe_load(open(path)) or {}
    w.setdefault("altitude", 2.0)
    w.setdefault("vehicle_radius", 0.2)
    w.setdefault("goal_radius", 1.0)
    m = w.setdefault("mission", {})
    m.setdefault("settle_hold", 1.0)
    m.setdefault("duration", 10.0)
    m.setdefault("settle", 3.0)
    m.setdefault("timeout", 40.0)
    m.setdefault("start", "on_hold")
    w["obstacles"] = make_forest(w["forest"], w) if w.get("forest") else []
    return w


def make_forest(f: dict, w: dict) -> list:
    """The mission tool's virtual forest (drivers/mission/mppi_mission/forest.py), clear of
    the start and the goal."""
    keep_out = [tuple(w["start"][:2])] + ([tuple(w["goal"][:2])] if w.get("goal") else [])
    return forest.make_forest(f, keep_out)


def circle_eval(ref: dict, t: float):
    c = ref["center"]
    r, v = float(ref["radius"]), float(ref["speed"])
    a = v / r * t
    return (c[0] + r * math.cos(a), c[1] + r * math.sin(a), c[2])


class Mission:
    def __init__(self, world: dict, mppi_lcm, lc, wall_us):
        self.w, self.mppi_lcm, self.lc, self.wall_us = world, mppi_lcm, lc, wall_us
        self.hold = (world["start"][0], world["start"][1], float(world["altitude"]))
        self.phase = "wait"          # wait -> run -> done | timeout
        self.held_since = None
        self.t0_wall_us = None
        self.t0 = None               # vehicle time of the mission start
        self.seq = 0
        self.events = []
        self.err2 = []               # (t, squared tracking error) for the RMSE
        self.min_clearance = float("inf")
        self.goal_time = None

    # Called at ~10 Hz by the vehicle.
    def update(self, t: float, x, offboard: bool, airborne: bool):
        p = x[Q.POS]
        if self.phase == "wait":
            # on_hold: within 0.5 m of the hold point; on_offboard: at altitude (a forest's
            # obstacle cost may hold the vehicle off the take-off spot).
            if self.w["mission"]["start"] == "on_offboard":
                near = abs(p[2] - self.hold[2]) < 0.5
            else:
                near = math.dist(p, self.hold) < 0.5
            if offboard and airborne and near:
                self.held_since = self.held_since if self.held_since is not None else t
                if t - self.held_since >= self.w["mission"]["settle_hold"]:
                    self.phase = "run"
                    self.t0, self.t0_wall_us = t, self.wall_us()
                    self.events.append({"event": "mission_start", "t": t})
            else:
                self.held_since = None
        elif self.phase == "run":
            m = self.w["mission"]
            kind = self.w["reference"]["kind"]
            if kind == "circle" and t - self.t0 >= m["duration"]:
                self._end("mission_done", t)
            elif kind == "waypoint" and math.dist(p, self.w["goal"]) < self.w["goal_radius"]:
                self.goal_time = t - self.t0
                self._end("mission_done", t, goal=True, time_to_goal=self.goal_time)
            elif t - self.t0 > m["timeout"]:
                self._end("mission_timeout", t)
        self.publish()

    def _end(self, what, t, **kw):
        self.phase = "done" if what == "mission_done" else "timeout"
        self.events.append({"event": what, "t": t, **kw})

    # Called at the truth-log rate while the mission runs.
    def record(self, t: float, x):
        if self.phase == "run" and self.w["reference"]["kind"] == "circle":
            tr = t - self.t0
            if tr >= self.w["mission"]["settle"]:
                r = circle_eval(self.w["reference"], tr)
                self.err2.append(sum((a - b) ** 2 for a, b in zip(x[Q.POS], r)))

    def clearance(self, x) -> float:
        best = forest.clearance(x, self.w["obstacles"], self.w["vehicle_radius"])
        self.min_clearance = min(self.min_clearance, best)
        return best

    def publish(self):
        lt = self.mppi_lcm
        ref = lt.reference_t()
        self.seq += 1
        ref.utime = self.wall_us()
        ref.seq = self.seq
        wr = self.w["reference"]
        ref.vehicle_count = 1
        if self.phase == "wait" or (self.phase != "run" and wr["kind"] != "circle"):
            goal = self.hold if self.phase == "wait" else tuple(self.w.get("goal", self.hold))
            ref.kind = lt.reference_t.KIND_HOLD if self.phase == "wait" else lt.reference_t.KIND_WAYPOINT
            ref.center = list(goal)
            ref.goals = [list(goal)]
            ref.t0_utime = ref.utime
        elif wr["kind"] == "circle":
            ref.kind = lt.reference_t.KIND_CIRCLE
            ref.center = [float(c) for c in wr["center"]]
            ref.radius = float(wr["radius"])
            ref.speed = float(wr["speed"])
            ref.t0_utime = self.t0_wall_us
            ref.goals = [list(circle_eval(wr, 0.0))]
        else:
            ref.kind = lt.reference_t.KIND_WAYPOINT
            ref.center = list(self.w["goal"])
            ref.goals = [list(self.w["goal"])]
            ref.t0_utime = self.t0_wall_us
        ref.yaw = 0.0
        self.lc.publish("MPPI_REFERENCE", ref.encode())
        obs = lt.obstacles_t()
        obs.utime, obs.seq = ref.utime, self.seq
        cyl = []
        for cx, cy, r in self.w["obstacles"][:64]:
            c = lt.cylinder_t()
            c.x, c.y, c.radius, c.vx, c.vy = cx, cy, r, 0.0, 0.0
            cyl.append(c)
        obs.n, obs.cylinders = len(cyl), cyl
        self.lc.publish("MPPI_OBSTACLES", obs.encode())

    def summary(self) -> dict:
        rmse = math.sqrt(sum(self.err2) / len(self.err2)) if self.err2 else None
        return {"phase": self.phase, "tracking_rmse": rmse, "tracking_samples": len(self.err2),
                "time_to_goal": self.goal_time, "min_clearance": None if math.isinf(self.min_clearance) else
                self.min_clearance, "obstacles": len(self.w["obstacles"]), "events": self.events}
