"""What each mppi_lcm channel becomes in rerun's scene. One Scene serves the live view and the
log conversion, so a flight looks the same live and afterwards.

Entities (the blueprint arranges them):
  /world/obstacles            Cylinders3D, each as the simulator last sent it (moving ones move)
  /world/vehicles/<j>         Points3D, the vehicle; /world/vehicles/<j>/trail LineStrips3D
  /world/plan                 LineStrips3D, the plan's predicted path per vehicle (magenta)
  /world/rollouts/top         LineStrips3D, the lowest-cost sampled rollouts, coloured by weight
  /world/rollouts/random      LineStrips3D, a random subsample of the others, coloured by weight
  /world/goal                 Points3D, each vehicle's goal; /world/reference the reference path
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
# Rollouts: weight (log scale, relative to the fan's largest) from LOW to HIGH.
ROLLOUT_LOW_RGB = np.array((40, 110, 255), dtype=np.float32)
ROLLOUT_HIGH_RGB = np.array((255, 90, 0), dtype=np.float32)
OBSTACLE_HEIGHT = 6.0  # m: the simulator's trunks are infinite cylinders; drawn this tall
TRAIL_POINTS = 2000     # positions kept per vehicle
TRAIL_EVERY = 10        # states between trail updates

MODEL_QUADROTOR, MODEL_QUADROTOR_RATE, MODEL_CARTPOLE, MODEL_RACECAR = 1, 2, 3, 4
REFERENCE_CIRCLE, REFERENCE_FIGURE_EIGHT = 1, 2

CHANNELS = ("MPPI_STATE", "MPPI_PLAN", "MPPI_ROLLOUTS", "MPPI_OBSTACLES", "MPPI_REFERENCE", "MPPI_COMMAND",
            "MPPI_STATUS")


def lcm_types() -> dict:
    """{channel: mppi_lcm type} of the channels the scene draws."""
    from mppi_lcm import (command_t, controller_status_t, obstacles_t, plan_t, reference_t, rollouts_t,
                          vehicle_state_t)
    return {"MPPI_STATE": vehicle_state_t, "MPPI_PLAN": plan_t, "MPPI_ROLLOUTS": rollouts_t,
            "MPPI_OBSTACLES": obstacles_t, "MPPI_REFERENCE": reference_t, "MPPI_COMMAND": command_t,
            "MPPI_STATUS": controller_status_t}


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
                         "MPPI_COMMAND": self.command, "MPPI_STATUS": self.status}

    def log(self, channel: str, msg) -> bool:
        """Draws one message; False for a channel not drawn."""
        h = self.handlers.get(channel)
        if h is None:
            return False
        if channel == "MPPI_STATE":
            if self.t0_us is None:
                self.t0_us = msg.sample_utime
            self.now_us = max(self.now_us, msg.sample_utime)
        t0 = self.t0_us if self.t0_us is not None else self.now_us
        self.rec.set_time("time", duration=(self.now_us - t0) * 1e-6)
        h(msg)
        return True

    def state(self, msg) -> None:
        pos = vehicle_positions(msg)
        self.states += 1
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
