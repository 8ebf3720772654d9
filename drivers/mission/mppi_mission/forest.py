"""Virtual trees: a jittered hexagonal lattice of vertical cylinders (the layout of the
simulator's forests, sim/README.md, with this module's own random stream), for missions
whose obstacles only mppid knows about and for the simulated autopilot's test worlds."""
from __future__ import annotations

import math
import random


def make_forest(f: dict, keep_out: list) -> list[tuple[float, float, float]]:
    """(x, y, radius) of each tree: spacing, +-jitter/2 of it, radius +- radius_jitter, in
    x_range x y_range, clear of every keep_out (x, y) point by clear_radius, no two closer
    than 0.5 m surface to surface; f["seed"] fixes the layout."""
    rng = random.Random(int(f.get("seed", 1)))
    sp = float(f["spacing"])
    jit = float(f.get("jitter", 0.0)) * sp
    x0, x1 = f["x_range"]
    y0, y1 = f["y_range"]
    out = []
    row = 0
    y = y0
    while y <= y1:
        x = x0 + (sp / 2 if row % 2 else 0.0)
        while x <= x1:
            cx = x + rng.uniform(-jit / 2, jit / 2)
            cy = y + rng.uniform(-jit / 2, jit / 2)
            r = float(f["radius"]) + rng.uniform(-1, 1) * float(f.get("radius_jitter", 0.0))
            ok = all(math.hypot(cx - k[0], cy - k[1]) > float(f.get("clear_radius", 2.0)) + r for k in keep_out)
            ok = ok and all(math.hypot(cx - o[0], cy - o[1]) > r + o[2] + 0.5 for o in out)
            if ok:
                out.append((cx, cy, r))
            x += sp
        y += sp * math.sqrt(3) / 2
        row += 1
    return out


def clearance(p, trees, vehicle_radius: float) -> float:
    """Distance from a point to the nearest tree's surface, less the vehicle's radius."""
    return min((math.hypot(p[0] - x, p[1] - y) - r - vehicle_radius for x, y, r in trees), default=math.inf)
