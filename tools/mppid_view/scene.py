"""What each mppi_lcm channel becomes in rerun's scene. One Scene serves the live view and the
log conversion, so a flight looks the same live and afterwards.

Entities (the blueprint arranges them):
  /world/obstacles            Cylinders3D, each as the simulator last sent it (moving ones move)
  /world/vehicles/<j>         Points3D, the vehicle; /world/vehicles/<j>/trail LineStrips3D
  /world/plan                 LineStrips3D, the plan's predicted path per vehicle (magenta)
  /world/rollouts/top         LineStrips3D, the lowest-cost sampled rollouts, coloured by weight
  /world/rollouts/random      LineStrips3D, a random subsample of the others, coloured by weight
  /world/goal                 Points3D, each vehicle's goal; /world/reference the reference path
  /world/map/occupied         Boxes3D, the local map's occupied cells (local_map_t: distance <= 0)
                              within MAP_BAND_M of the vehicle's altitude, at most every MAP_EVERY_S
  /world/sensors/<s>/points   Points3D, a sensor frame's returns (point_cloud_t, world frame; a
                              subsample), /world/sensors/<s>/rays a few of its rays from the sensor
  /timing/compute_ms          Scalars: each command's cycle start -> command out
  /timing/state_to_command_ms Scalars: each command's state sample -> command out (age + compute)
  /timing/misses              Scalars: the daemon's deadline misses so far (status)
  /optimizer/ess              Scalars: the effective sample size (status)
Time: the timeline "time", the flight's: seconds since the first state's sample time, each message
stamped with the newest state's (a lock-step flight flies faster than the wall clock; real time
or lock-step, the plots and the scene then share the simulator's seconds).
"""
from __future__ import annotations

import math
from collections import deque

import numpy as np
import rerun as rr

# Colours a screenshot test can find (lines are drawn unlit, so these pixels stay pure).
PLAN_RGB = (255, 0, 255)
TRAIL_RGB = (0, 220, 220)
GOAL_RGB = (255, 220, 0)
OBSTACLE_RGB = (70, 150, 60)
MAP_RGB = (230, 120, 40)
SENSOR_RGB = {"depth": (250, 250, 250), "lidar": (120, 200, 255)}
RAY_RGB = (160, 160, 160)
MAP_EVERY_S = 0.5       # flight seconds between drawn maps (a map is 0.5 M cells, 10 Hz)
MAP_BAND_M = 1.0        # the occupied cells drawn: within this of the vehicle's altitude
SENSOR_EVERY_S = 0.25   # between drawn sensor frames
SENSOR_POINTS = 2000    # returns drawn per frame, at most
SENSOR_RAYS = 48        # rays drawn per frame
# Rollouts: weight (log scale, relative to the fan's largest) from LOW to HIGH.
ROLLOUT_LOW_RGB = np.array((40, 110, 255), dtype=np.float32)
ROLLOUT_HIGH_RGB = np.array((255, 90, 0), dtype=np.float32)
OBSTACLE_HEIGHT = 6.0  # m: the simulator's trunks are infinite cylinders; drawn this tall
TRAIL_POINTS = 2000     # positions kept per vehicle
TRAIL_EVERY = 10        # states between trail updates

MODEL_QUADROTOR, MODEL_QUADROTOR_RATE, MODEL_CARTPOLE, MODEL_RACECAR = 1, 2, 3, 4
REFERENCE_CIRCLE, REFERENCE_FIGURE_EIGHT = 1, 2

CHANNELS = ("MPPI_STATE", "MPPI_PLAN", "MPPI_ROLLOUTS", "MPPI_OBSTACLES", "MPPI_REFERENCE", "MPPI_COMMAND",
            "MPPI_STATUS", "MPPI_LOCAL_MAP")
# The sensors' frames: on the flight's sensor bus (tools/sitl: the next UDP port), or anywhere.
SENSOR_CHANNELS = ("MPPI_DEPTH", "MPPI_LIDAR")
# Heavy messages: decoding each costs the view more than drawing one now and then.
DECODE_EVERY_S = {"MPPI_LOCAL_MAP": MAP_EVERY_S, "MPPI_DEPTH": SENSOR_EVERY_S, "MPPI_LIDAR": SENSOR_EVERY_S}


def lcm_types() -> dict:
    """{channel: mppi_lcm type} of the channels the scene draws."""
    from mppi_lcm import (command_t, controller_status_t, local_map_t, obstacles_t, plan_t, point_cloud_t,
                          reference_t, rollouts_t, vehicle_state_t)
    return {"MPPI_STATE": vehicle_state_t, "MPPI_PLAN": plan_t, "MPPI_ROLLOUTS": rollouts_t,
            "MPPI_OBSTACLES": obstacles_t, "MPPI_REFERENCE": reference_t, "MPPI_COMMAND": command_t,
            "MPPI_STATUS": controller_status_t, "MPPI_LOCAL_MAP": local_map_t, "MPPI_DEPTH": point_cloud_t,
            "MPPI_LIDAR": point_cloud_t}


def vehicle_positions(msg) -> np.ndarray:
    """(vehicles, 3) positions of a vehicle_state_t, by its model."""
    x = np.asarray(msg.x, dtype=np.float32)
    m, nx = max(1, msg.vehicle_count), max(1, msg.nx)
    per = x[: m * nx].reshape(m, nx)
    if msg.model in (MODEL_QUADROTOR, MODEL_QUADROTOR_RATE):
        return per[:, :3].copy()
    pos = np.zeros((m, 3), dtype=np.float32)
    pos[:, 0] = per[:, 0]
    if msg.model == MODEL_RACECAR:
        pos[:, 1] = per[:, 1]
    return pos


def rollout_colors(weight: np.ndarray) -> np.ndarray:
    """RGB per rollout: log10 of its weight over the largest shown, -6..0, LOW -> HIGH."""
    w = np.asarray(weight, dtype=np.float64)
    top = w.max() if w.size and w.max() > 0 else 1.0
    rel = np.clip((np.log10(np.maximum(w / top, 1e-12)) + 6.0) / 6.0, 0.0, 1.0)[:, None]
    return (ROLLOUT_LOW_RGB * (1.0 - rel) + ROLLOUT_HIGH_RGB * rel).astype(np.uint8)


def reference_path(msg, points: int = 200) -> np.ndarray | None:
    """The reference's path (costs/reference.hpp's shapes), or None for a hold or waypoints."""
    if msg.kind not in (REFERENCE_CIRCLE, REFERENCE_FIGURE_EIGHT) or msg.radius <= 0:
        return None
    a = np.linspace(0.0, 2.0 * math.pi, points, dtype=np.float32)
    c = np.asarray(msg.center, dtype=np.float32)
    p = np.repeat(c[None, :], points, axis=0)
    if msg.kind == REFERENCE_CIRCLE:
        p[:, 0] += msg.radius * np.cos(a)
        p[:, 1] += msg.radius * np.sin(a)
    else:
        p[:, 0] += msg.radius * np.sin(a)
        p[:, 1] += 0.5 * msg.radius * np.sin(2.0 * a)
    return p


def occupied_cells(msg, z: float | None, band: float = MAP_BAND_M) -> np.ndarray:
    """Centres (n, 3) of a local_map_t's occupied cells (distance <= 0), those within `band` of
    altitude z (all with z None)."""
    nx, ny, nz = msg.nx, msg.ny, msg.nz
    d = np.asarray(msg.distance_mm, dtype=np.int16)
    if nx <= 0 or ny <= 0 or nz <= 0 or d.size != nx * ny * nz:
        return np.zeros((0, 3), np.float32)
    k, j, i = np.nonzero(d.reshape(nz, ny, nx) <= 0)
    c = (np.stack([i, j, k], axis=1).astype(np.float32) + 0.5) * msg.resolution + np.asarray(msg.origin, np.float32)
    return c if z is None else c[np.abs(c[:, 2] - z) <= band]


def cloud_world(msg) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A point_cloud_t in the world frame: (sensor position (3,), points (n, 3), hit (n,))."""
    w, x, y, z = (float(v) for v in msg.orientation)
    n = math.sqrt(w * w + x * x + y * y + z * z) or 1.0
    w, x, y, z = w / n, x / n, y / n, z / n
    R = np.array([[1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
                  [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
                  [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)]], np.float32)
    p = np.stack([np.asarray(msg.x, np.float32), np.asarray(msg.y, np.float32), np.asarray(msg.z, np.float32)], 1)
    o = np.asarray(msg.position, np.float32)
    return o, p @ R.T + o, np.asarray(msg.hit, np.int8)


class Scene:
    """Logs decoded mppi_lcm messages into a rerun RecordingStream."""

    def __init__(self, rec: rr.RecordingStream):
        self.rec = rec
        self.t0_us: int | None = None   # the first state's sample time
        self.now_us = 0                 # the newest state's
        self.trails: dict[int, deque] = {}
        self.states = 0
        self.handlers = {"MPPI_STATE": self.state, "MPPI_PLAN": self.plan, "MPPI_ROLLOUTS": self.rollouts,
                         "MPPI_OBSTACLES": self.obstacles, "MPPI_REFERENCE": self.reference,
                         "MPPI_COMMAND": self.command, "MPPI_STATUS": self.status,
                         "MPPI_LOCAL_MAP": self.local_map, "MPPI_DEPTH": self.depth, "MPPI_LIDAR": self.lidar}
        self.altitude: float | None = None  # vehicle 0's, for the map's band
        self.drawn_at: dict[str, float] = {}

    def log(self, channel: str, msg) -> bool:
        """Draws one message; False for a channel not drawn."""
        h = self.handlers.get(channel)
        if h is None:
            return False
        if channel == "MPPI_STATE":
            self.advance(msg)
        t0 = self.t0_us if self.t0_us is not None else self.now_us
        self.rec.set_time("time", duration=(self.now_us - t0) * 1e-6)
        h(msg)
        return True

    def advance(self, state) -> None:
        """The flight's clock to a vehicle_state_t's sample time (a state not drawn: the live
        view draws only the newest of a burst)."""
        if self.t0_us is None:
            self.t0_us = state.sample_utime
        self.now_us = max(self.now_us, state.sample_utime)

    def due(self, what: str, every: float) -> bool:
        """At most one `what` drawn per `every` flight seconds."""
        now = self.now_us * 1e-6
        if now - self.drawn_at.get(what, -math.inf) < every:
            return False
        self.drawn_at[what] = now
        return True

    def state(self, msg) -> None:
        pos = vehicle_positions(msg)
        self.states += 1
        if len(pos):
            self.altitude = float(pos[0][2])
        for j, p in enumerate(pos):
            self.rec.log(f"world/vehicles/{j}", rr.Points3D([p], radii=rr.Radius.ui_points(8.0), colors=[TRAIL_RGB]))
            trail = self.trails.setdefault(j, deque(maxlen=TRAIL_POINTS))
            trail.append(p)
            if self.states % TRAIL_EVERY == 1 and len(trail) > 1:
                self.rec.log(f"world/vehicles/{j}/trail",
                             rr.LineStrips3D([np.asarray(trail)], radii=rr.Radius.ui_points(2.0), colors=[TRAIL_RGB]))

    def plan(self, msg) -> None:
        pos = np.asarray(msg.pos, dtype=np.float32).reshape(-1, 3)
        if len(pos) == 0 or msg.horizon <= 0:
            return
        per = msg.horizon + 1
        strips = [pos[i:i + per] for i in range(0, len(pos) - per + 1, per)] or [pos]
        self.rec.log("world/plan", rr.LineStrips3D(strips, radii=rr.Radius.ui_points(3.0), colors=[PLAN_RGB]))

    def rollouts(self, msg) -> None:
        n, m, s = msg.count, max(1, msg.vehicles), max(1, msg.steps)
        if n <= 0:
            return
        xyz = np.asarray(msg.pos, dtype=np.float32).reshape(n, m, s, 3)
        colors = rollout_colors(np.asarray(msg.weight, dtype=np.float32))
        for name, sel in (("top", slice(0, msg.top)), ("random", slice(msg.top, n))):
            paths = xyz[sel].reshape(-1, s, 3)
            if len(paths) == 0:
                self.rec.log(f"world/rollouts/{name}", rr.Clear(recursive=False))
                continue
            self.rec.log(f"world/rollouts/{name}",
                         rr.LineStrips3D(list(paths), radii=rr.Radius.ui_points(1.0 if name == "random" else 1.5),
                                         colors=np.repeat(colors[sel], m, axis=0)))

    def obstacles(self, msg) -> None:
        if msg.n <= 0:
            self.rec.log("world/obstacles", rr.Clear(recursive=False))
            return
        c = msg.cylinders
        centers = [(o.x, o.y, 0.5 * OBSTACLE_HEIGHT) for o in c]
        self.rec.log("world/obstacles", rr.Cylinders3D(lengths=[OBSTACLE_HEIGHT] * len(c), radii=[o.radius for o in c],
                                                       centers=centers, colors=[OBSTACLE_RGB]))

    def reference(self, msg) -> None:
        if msg.vehicle_count > 0:
            self.rec.log("world/goal", rr.Points3D(np.asarray(msg.goals, dtype=np.float32).reshape(-1, 3),
                                                   radii=rr.Radius.ui_points(10.0), colors=[GOAL_RGB]))
        path = reference_path(msg)
        if path is not None:
            self.rec.log("world/reference", rr.LineStrips3D([path], radii=rr.Radius.ui_points(2.0), colors=[GOAL_RGB]))

    def command(self, msg) -> None:
        self.rec.log("timing/compute_ms", rr.Scalars(msg.compute_us * 1e-3))
        self.rec.log("timing/state_to_command_ms", rr.Scalars((msg.age_us + msg.compute_us) * 1e-3))

    def status(self, msg) -> None:
        self.rec.log("timing/misses", rr.Scalars(float(msg.misses)))
        self.rec.log("optimizer/ess", rr.Scalars(float(msg.ess)))

    def local_map(self, msg) -> None:
        if not self.due("map", MAP_EVERY_S):
            return
        c = occupied_cells(msg, self.altitude)
        if not len(c):
            self.rec.log("world/map/occupied", rr.Clear(recursive=False))
            return
        half = [0.5 * msg.resolution] * 3
        self.rec.log("world/map/occupied", rr.Boxes3D(centers=c, half_sizes=[half] * len(c), colors=[MAP_RGB],
                                                      fill_mode="solid"))

    def depth(self, msg) -> None:
        self.cloud("depth", msg)

    def lidar(self, msg) -> None:
        self.cloud("lidar", msg)

    def cloud(self, name: str, msg) -> None:
        if msg.n <= 0 or not self.due(name, SENSOR_EVERY_S):
            return
        o, p, hit = cloud_world(msg)
        hits = p[hit != 0]
        step = max(1, len(hits) // SENSOR_POINTS)
        self.rec.log(f"world/sensors/{name}/points",
                     rr.Points3D(hits[::step], radii=rr.Radius.ui_points(1.5), colors=[SENSOR_RGB[name]]))
        rays = p[:: max(1, len(p) // SENSOR_RAYS)]
        self.rec.log(f"world/sensors/{name}/rays",
                     rr.LineStrips3D([np.stack([o, q]) for q in rays], radii=rr.Radius.ui_points(0.5),
                                     colors=[RAY_RGB]))
