"""The map to the autopilot: mppid-mapper's local map (local_map_t) as OBSTACLE_DISTANCE, and for
ArduPilot also OBSTACLE_DISTANCE_3D, so the autopilot's own avoidance and the ground station's
proximity view see what mppid sees, whether mppid flies or not (docs/sensing.md, "The map to the
autopilot").

OBSTACLE_DISTANCE: 72 sectors of 5 degrees, MAV_FRAME_BODY_FRD, angle_offset 0: sector j is
centred on the bearing 5 j degrees clockwise from the nose, as both autopilots read it (ArduPilot's
AP_Proximity_MAV puts distance j at j * increment + angle_offset; PX4's collision prevention bins
by round(angle / 5)). The bearing is about the vertical (the vehicle's heading only): PX4 turns
the sectors by the heading alone. A sector's distance [cm] is that of the nearest occupied map
cell whose centre lies in the sector's wedge and within the height band around the vehicle,
horizontally, less half a cell (the cell's near face), clipped up to min_distance. A sector with
no such cell within max_distance says "no obstacle": max_distance + 1, as the MAVLink message
defines it; UINT16_MAX ("unknown") only where the map's window ends before max_distance. Both
matter to PX4: it refuses to move into a sector of UINT16_MAX unless CP_GO_NO_DATA is set, and
takes max_distance + 1 as free; ArduPilot ignores both.

OBSTACLE_DISTANCE_3D (ArduPilot only): the nearest cell of each sector that holds one, nearest
first, at most max_3d_points, each a point in MAV_FRAME_BODY_FRD (the full attitude: ArduPilot
rotates them back with its own), all with one time_boot_ms: ArduPilot takes a new time_boot_ms
as a new set and clears its proximity boundary.

When: on the autopilot's own clock. Each state the bridge builds (state.py) carries the
autopilot's time; when it passes the next multiple of 1 / rate_hz a tick is due, and the sender
thread computes and sends that tick from the latest map and that state, stamped with the state's
time. So the messages per second of the link's clock are rate_hz however loaded the machine is,
as long as the autopilot's telemetry comes. A map older than max_map_age_s (since it arrived;
mppid-mapper publishes only when a sensor frame came) sends nothing: both autopilots drop
proximity data after 0.5 s, as they should. Skipped ticks are counted.
"""
from __future__ import annotations

import logging
import math
import struct
import threading
import time
from collections import deque

import numpy as np

from . import realtime
from .autopilots.base import mavlink
from .layout import QuadrotorRate as Q

log = logging.getLogger("mppi_mavlink")

SECTORS = 72
SECTOR_DEG = 360.0 / SECTORS
UNKNOWN = 65535                       # UINT16_MAX: the MAVLink message's "unknown / not used"
COUNTERS = ("obstacle_distance_sent", "obstacle_distance_3d_sent", "obstacle_stale", "obstacle_no_map",
            "obstacle_maps", "obstacle_maps_rejected", "obstacle_ticks_dropped")

DEFAULTS = {
    "enabled": True,                  # send the map to the autopilot while the link is up
    "map_channel": "MPPI_LOCAL_MAP",  # local_map_t (mppid-mapper's output)
    "rate_hz": 15.0,                  # ticks per second of the autopilot's clock (both time out at 0.5 s)
    "min_distance_m": 0.2,            # nearer obstacles are sent at this distance
    "max_distance_m": 10.0,           # farther: "no obstacle" (max_distance + 1)
    "band_below_m": 1.0,              # the height band around the vehicle that counts
    "band_above_m": 1.0,
    "max_map_age_s": 0.5,             # an older map sends nothing
    "max_3d_points": 16,              # ArduPilot: OBSTACLE_DISTANCE_3D per tick (0: none)
}


def validate(s: dict, error) -> None:
    """The `obstacle_distance` section; error(message) raises naming the field."""
    o = s["obstacle_distance"]

    def num(key, lo, hi):
        v = o[key]
        if not isinstance(v, (int, float)) or isinstance(v, bool) or not math.isfinite(v) or not lo <= v <= hi:
            error(f"obstacle_distance.{key}: must be a number in [{lo}, {hi}], got {v!r}")

    if not isinstance(o["enabled"], bool):
        error(f"obstacle_distance.enabled: must be true or false, got {o['enabled']!r}")
    if not isinstance(o["map_channel"], str) or not o["map_channel"]:
        error(f"obstacle_distance.map_channel: must be an LCM channel name, got {o['map_channel']!r}")
    num("rate_hz", 10.0, 50.0)
    num("min_distance_m", 0.0, 100.0)
    num("max_distance_m", 0.5, 655.0)   # max_distance + 1 [cm] must stay below UINT16_MAX
    num("band_below_m", 0.0, 100.0)
    num("band_above_m", 0.0, 100.0)
    num("max_map_age_s", 0.05, 10.0)
    num("max_3d_points", 0, 64)
    if not isinstance(o["max_3d_points"], int):
        error(f"obstacle_distance.max_3d_points: must be an integer in [0, 64], got {o['max_3d_points']!r}")
    if o["min_distance_m"] >= o["max_distance_m"]:
        error(f"obstacle_distance.min_distance_m ({o['min_distance_m']:g}) must be below "
              f"obstacle_distance.max_distance_m ({o['max_distance_m']:g})")


# ---- the map ------------------------------------------------------------------------------------
_HEADER = struct.Struct(">8sqq3ff3ifi")   # local_map_t up to its array, LCM's big-endian encoding


class MapCells:
    """The occupied cells of one local_map_t: centres (world ENU) in ascending z (so that a height
    band is a slice), and the window. Immutable."""

    def __init__(self, xyz: np.ndarray, lo, hi, resolution: float, seq: int, arrived: float):
        self.xyz = xyz
        self.z = np.ascontiguousarray(xyz[:, 2])
        self.lo, self.hi = np.asarray(lo, float), np.asarray(hi, float)
        self.resolution, self.seq, self.arrived = resolution, seq, arrived
        self.n = len(xyz)


def decode_map(data: bytes, fingerprint: bytes, arrived: float) -> MapCells:
    """A local_map_t's occupied cells (distance < 0), read straight from the encoded message: the
    generated decoder would build a tuple of every cell (~0.5 million)."""
    if len(data) < _HEADER.size:
        raise ValueError(f"local_map_t: {len(data)} bytes, shorter than its header")
    fp, _utime, seq, ox, oy, oz, res, nx, ny, nz, _maxd, n = _HEADER.unpack_from(data)
    if fp != fingerprint:
        raise ValueError("local_map_t: wrong fingerprint (not a local_map_t)")
    if min(nx, ny, nz) <= 0 or n != nx * ny * nz or len(data) != _HEADER.size + 2 * n:
        raise ValueError(f"local_map_t: {nx} x {ny} x {nz} cells, n_cells {n}, {len(data)} bytes")
    if not (math.isfinite(res) and res > 0 and all(math.isfinite(c) for c in (ox, oy, oz))):
        raise ValueError(f"local_map_t: resolution {res}, origin ({ox}, {oy}, {oz})")
    dist = np.frombuffer(data, dtype=">i2", count=n, offset=_HEADER.size)
    idx = np.flatnonzero(dist < 0)          # ascending, so in ascending k (z): the index's slowest
    k, rest = np.divmod(idx, nx * ny)
    j, i = np.divmod(rest, nx)
    xyz = np.empty((len(idx), 3))
    origin = (ox, oy, oz)
    for axis, a in enumerate((i, j, k)):
        xyz[:, axis] = origin[axis] + (a + 0.5) * res
    return MapCells(xyz, origin, (ox + nx * res, oy + ny * res, oz + nz * res), res, seq, arrived)


# ---- the sectors --------------------------------------------------------------------------------
def heading(q) -> float:
    """Yaw (ENU, counter-clockwise from east) of the body FLU -> ENU quaternion (w, x, y, z)."""
    w, x, y, z = q
    return math.atan2(2.0 * (w * z + x * y), 1.0 - 2.0 * (y * y + z * z))


def enu_to_body_frd(q, v: np.ndarray) -> np.ndarray:
    """World ENU vectors (rows) into the body FRD frame of attitude q (body FLU -> ENU)."""
    w, x, y, z = q
    r = np.array([[1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
                  [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
                  [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)]])
    flu = v @ r          # R^T v for each row
    return flu * np.array([1.0, -1.0, -1.0])


class Sectors:
    """OBSTACLE_DISTANCE's distances (and the 3-D points) of a map seen from a pose. Work buffers
    grow with the largest map seen and are reused: a tick allocates only its index arrays."""

    def __init__(self, o: dict):
        self.min_m, self.max_m = float(o["min_distance_m"]), float(o["max_distance_m"])
        self.below, self.above = float(o["band_below_m"]), float(o["band_above_m"])
        self.min_cm = int(round(self.min_m * 100))
        self.max_cm = int(round(self.max_m * 100))
        self.distances = np.full(SECTORS, UNKNOWN, dtype=np.uint16)   # the last tick's answer
        self.nearest = np.full(SECTORS, np.inf)                        # [m], per sector
        self.cap = -1
        self._grow(0)
        body_deg = np.arange(SECTORS) * SECTOR_DEG
        self.body_cw = np.radians(body_deg)                            # sector centres, clockwise

    def _grow(self, n: int):
        """Work buffers for up to n cells in the band (more than ever before: new ones)."""
        if n > self.cap:
            self.cap = max(n, 2 * self.cap)
            self.r = np.empty((self.cap, 3))
            self.d, self.cw, self.half, self.f = (np.empty(self.cap) for _ in range(4))
            self.lo, self.span, self.sector = (np.empty(self.cap, dtype=np.intp) for _ in range(3))
            self.wide = np.empty(self.cap, dtype=bool)

    def compute(self, cells: MapCells, p, q, want_points: int = 0):
        """Fills self.distances (cm) for the vehicle at p (ENU) with attitude q; returns the 3-D
        points (body FRD, nearest first, at most want_points) as an (m, 3) array."""
        a = int(np.searchsorted(cells.z, p[2] - self.below, side="left"))
        b = int(np.searchsorted(cells.z, p[2] + self.above, side="right"))
        m = b - a
        self._grow(m)
        yaw = heading(q)
        self.nearest.fill(np.inf)
        r, d, cw = self.r[:m], self.d[:m], self.cw[:m]
        if m:
            for axis in range(3):                         # the cells in the height band: a slice
                np.subtract(cells.xyz[a:b, axis], p[axis], out=r[:, axis])
            np.hypot(r[:, 0], r[:, 1], out=d)
            np.arctan2(r[:, 1], r[:, 0], out=cw)
            np.subtract(yaw, cw, out=cw)                  # clockwise from the nose
            self._fill(cw, d, cells.resolution, m)
        self._to_cm(cells, p, yaw)
        if not want_points or not m:
            return np.empty((0, 3))
        return self._points(q, r, d, cw, cells.resolution, want_points)

    def _fill(self, cw, d, res, m):
        """self.nearest from m cells at bearings cw (clockwise from the nose) and horizontal
        distances d: each cell in every sector its footprint's circumscribed circle reaches (near
        the vehicle a cell spans several sectors), at its distance less half a cell (its near
        face; d is changed so)."""
        inv = 1.0 / math.radians(SECTOR_DEG)
        half, f, lo, span = self.half[:m], self.f[:m], self.lo[:m], self.span[:m]
        np.arctan2(res * math.sqrt(0.5), d, out=half)
        np.subtract(cw, half, out=f)
        f *= inv
        np.rint(f, out=f)
        np.copyto(lo, f, casting="unsafe")
        np.add(cw, half, out=f)
        f *= inv
        np.rint(f, out=f)
        np.copyto(span, f, casting="unsafe")
        span -= lo
        d -= 0.5 * res
        np.remainder(lo, SECTORS, out=lo)
        np.minimum.at(self.nearest, lo, d)
        wide = self.wide[:m]
        np.greater_equal(span, 1, out=wide)
        near = np.flatnonzero(wide)                 # the few cells that span sectors
        for k in range(1, min(int(span.max(initial=0)), SECTORS - 1) + 1):
            near = near[span[near] >= k]
            np.minimum.at(self.nearest, (lo[near] + k) % SECTORS, d[near])

    def _to_cm(self, cells: MapCells, p, yaw: float):
        near = self.nearest
        found = near <= self.max_m
        cm = np.floor(np.clip(near, self.min_m, self.max_m) * 100.0)
        out = np.where(found, np.maximum(cm, self.min_cm), self.max_cm + 1)
        # No obstacle, but the map's window ends before max_distance along the sector: unknown.
        reach = self._window_reach(cells, p, yaw)
        out = np.where(~found & (reach < self.max_m), UNKNOWN, out)
        self.distances[:] = out

    def _window_reach(self, cells: MapCells, p, yaw: float) -> np.ndarray:
        """How far each sector's centre line runs inside the map's window (0 outside it)."""
        ang = yaw - self.body_cw
        dirs = (np.cos(ang), np.sin(ang))
        reach = np.full(SECTORS, np.inf)
        for axis in (0, 1):
            if not cells.lo[axis] <= p[axis] <= cells.hi[axis]:
                return np.zeros(SECTORS)
            dv = dirs[axis]
            with np.errstate(divide="ignore"):
                t = np.where(dv > 0, (cells.hi[axis] - p[axis]) / dv, np.where(dv < 0, (cells.lo[axis] - p[axis]) / dv,
                                                                                np.inf))
            np.minimum(reach, t, out=reach)
        return reach

    def _points(self, q, r, d, cw, res, want):
        """The nearest cell of each sector (by its centre's bearing) within max_distance, nearest
        first."""
        sector = self.sector[:len(d)]
        f = self.f[:len(d)]
        np.multiply(cw, 1.0 / math.radians(SECTOR_DEG), out=f)
        np.rint(f, out=f)
        np.copyto(sector, f, casting="unsafe")
        np.remainder(sector, SECTORS, out=sector)
        own = np.full(SECTORS, np.inf)
        np.minimum.at(own, sector, d)
        cand = np.flatnonzero((d == own[sector]) & (d <= self.max_m))
        _, first = np.unique(sector[cand], return_index=True)
        pick = cand[first]
        pick = pick[np.argsort(d[pick], kind="stable")][:want]
        v = r[pick]
        h = np.hypot(v[:, 0], v[:, 1])
        scale = np.maximum(h - 0.5 * res, max(self.min_m, 1e-3)) / np.maximum(h, 1e-9)
        v[:, 0] *= scale
        v[:, 1] *= scale
        return enu_to_body_frd(q, v)


# ---- the sender ---------------------------------------------------------------------------------
class ObstacleSender:
    """Ticks from the states (receive thread), maps from LCM (LCM thread), messages from its own
    thread. Counters in the bridge's `counters` (the control socket's `status`)."""

    def __init__(self, settings, link, profile, counters, fingerprint: bytes):
        self.o = settings["obstacle_distance"]
        self.link, self.counters, self.fingerprint = link, counters, fingerprint
        self.send_3d = profile.obstacle_distance_3d and self.o["max_3d_points"] > 0
        self.period_us = int(round(1e6 / self.o["rate_hz"]))
        self.sectors = Sectors(self.o)
        self.map: MapCells | None = None
        self.latest = self.read_from = None     # (local_map_t bytes, monotonic s at arrival)
        self.next_tick_us = None
        self.ticks = deque(maxlen=8)      # (autopilot us, position, attitude) due, oldest first
        self.cv = threading.Condition()
        self.thread = None
        for k in COUNTERS:
            counters.setdefault(k, 0)

    # ---- inputs -------------------------------------------------------------------------
    def on_map(self, _channel, data: bytes):
        """Kept as it came: the LCM thread also forwards mppid's commands, so the sender's thread
        reads the map, at its next tick."""
        self.latest = (data, time.monotonic())
        self.counters["obstacle_maps"] += 1

    def current_map(self) -> MapCells | None:
        """The newest map that reads well (a bad one is counted, and the one before stays)."""
        latest = self.latest
        if latest is not None and latest is not self.read_from:
            self.read_from = latest
            try:
                self.map = decode_map(latest[0], self.fingerprint, latest[1])
            except ValueError as e:
                self.counters["obstacle_maps_rejected"] += 1
                log.warning("%s", e)
        return self.map

    def on_state(self, boot_us: int, x) -> None:
        """A state built from the autopilot's telemetry at its time boot_us: a tick when due."""
        nxt, rate = self.next_tick_us, self.o["rate_hz"]
        if nxt is not None and boot_us < nxt - 2 * self.period_us:   # the autopilot's clock restarted
            nxt = None
        if nxt is not None and boot_us < nxt:
            return
        self.next_tick_us = math.ceil((math.floor(boot_us * rate / 1e6) + 1) * 1e6 / rate)
        with self.cv:
            if len(self.ticks) == self.ticks.maxlen:
                self.counters["obstacle_ticks_dropped"] += 1
            self.ticks.append((boot_us, tuple(x[Q.POS]), tuple(x[Q.QUAT])))
            self.cv.notify()

    # ---- the thread ---------------------------------------------------------------------
    def start(self, stop: threading.Event):
        if not self.o["enabled"]:
            return
        self.thread = realtime.thread(self._loop, "obstacle-distance", args=(stop,))
        self.thread.start()

    def _loop(self, stop: threading.Event):
        while not stop.is_set():
            with self.cv:
                if not self.ticks:
                    self.cv.wait(0.1)
                tick = self.ticks.popleft() if self.ticks else None
            if tick is not None:
                try:
                    self.tick(*tick)
                except Exception:
                    log.exception("obstacle distance")

    def tick(self, boot_us: int, p, q) -> bool:
        """One tick: the messages for the latest map seen from (p, q); False when none went out."""
        m = self.current_map()
        if m is None:
            self.counters["obstacle_no_map"] += 1
            return False
        if time.monotonic() - m.arrived > self.o["max_map_age_s"]:
            self.counters["obstacle_stale"] += 1
            return False
        points = self.sectors.compute(m, p, q, self.o["max_3d_points"] if self.send_3d else 0)
        self._send(boot_us, points)
        return True

    def _send(self, boot_us: int, points):
        s = self.sectors
        dist = s.distances.tolist()
        if self.link.send(lambda mv: mv.obstacle_distance_send(
                boot_us, mavlink.MAV_DISTANCE_SENSOR_UNKNOWN, dist, int(SECTOR_DEG), s.min_cm, s.max_cm, SECTOR_DEG, 0.0,
                mavlink.MAV_FRAME_BODY_FRD)):
            self.counters["obstacle_distance_sent"] += 1
        ms = (boot_us // 1000) & 0xFFFFFFFF
        for i, (x, y, z) in enumerate(points.tolist()):
            if self.link.send(lambda mv: mv.obstacle_distance_3d_send(
                    ms, mavlink.MAV_DISTANCE_SENSOR_UNKNOWN, mavlink.MAV_FRAME_BODY_FRD, i, x, y, z, s.min_m, s.max_m)):
                self.counters["obstacle_distance_3d_sent"] += 1
