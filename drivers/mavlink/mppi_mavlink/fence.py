"""A geofence: a box or a cylinder (x, y) plus altitude limits (z), in the autopilot's local
frame, ENU, metres (a mission file's in the mission's frame). Pure: `parse` validates one,
`breach` says why a point is outside ('' inside). The mission tool checks every leg against
one before flight (drivers/mission); the bridge holds the vehicle at it (failsafe.py)."""
from __future__ import annotations

import math
from dataclasses import dataclass

KEYS = {"shape", "center", "radius", "min", "max", "min_z", "max_z"}


class FenceError(ValueError):
    pass


@dataclass(frozen=True)
class Fence:
    shape: str                    # box | cylinder
    center: tuple = (0.0, 0.0)    # cylinder
    radius: float = 0.0
    lo: tuple = (0.0, 0.0)        # box corners
    hi: tuple = (0.0, 0.0)
    min_z: float = -math.inf
    max_z: float = math.inf

    def breach(self, p, margin: float = 0.0) -> str:
        """Why p (x, y, z) is outside, `margin` metres inside the fence counting as outside."""
        x, y, z = (float(c) for c in p[:3])
        if not all(math.isfinite(c) for c in (x, y, z)):
            return "position unknown"
        if z > self.max_z - margin:
            return f"z {z:.2f} m above the fence's max_z {self.max_z:g} m"
        if z < self.min_z + margin:
            return f"z {z:.2f} m below the fence's min_z {self.min_z:g} m"
        if self.shape == "cylinder":
            d = math.hypot(x - self.center[0], y - self.center[1])
            if d > self.radius - margin:
                return f"{d:.2f} m from the fence's centre, radius {self.radius:g} m"
        elif not (self.lo[0] + margin <= x <= self.hi[0] - margin and self.lo[1] + margin <= y <= self.hi[1] - margin):
            return f"({x:.2f}, {y:.2f}) outside the fence's box {list(self.lo)}..{list(self.hi)}"
        return ""


def _num(where, key, v):
    if not isinstance(v, (int, float)) or isinstance(v, bool) or not math.isfinite(v):
        raise FenceError(f"{where}.{key}: a number, got {v!r}")
    return float(v)


def _xy(where, key, v):
    if not (isinstance(v, list) and len(v) == 2):
        raise FenceError(f"{where}.{key}: [x, y]")
    return tuple(_num(where, key, c) for c in v)


def parse(d, where: str = "fence") -> Fence | None:
    """A fence from its map (None or {} for none); an error names the field."""
    if not d:
        return None
    if not isinstance(d, dict) or set(d) - KEYS:
        raise FenceError(f"{where}: a map of {', '.join(sorted(KEYS))}")
    z = {k: _num(where, k, d[k]) for k in ("min_z", "max_z") if d.get(k) is not None}
    if z.get("min_z", -math.inf) >= z.get("max_z", math.inf):
        raise FenceError(f"{where}: min_z must be below max_z")
    if d.get("shape") == "cylinder":
        r = _num(where, "radius", d.get("radius"))
        if r <= 0:
            raise FenceError(f"{where}.radius: metres > 0")
        return Fence("cylinder", center=_xy(where, "center", d.get("center", [0.0, 0.0])), radius=r, **z)
    if d.get("shape") == "box":
        lo, hi = _xy(where, "min", d.get("min")), _xy(where, "max", d.get("max"))
        if not (lo[0] < hi[0] and lo[1] < hi[1]):
            raise FenceError(f"{where}: min must be below max in x and y")
        return Fence("box", lo=lo, hi=hi, **z)
    raise FenceError(f"{where}.shape: box or cylinder, got {d.get('shape')!r}")
