"""What the map to the autopilot costs (mppi_mavlink/obstacle_distance.py), one JSON line per case.

    .venv/bin/python drivers/mavlink/tools/obstacle_bench.py [--ticks 300] [--out FILE]

Per tick: the sectors (and ArduPilot's 3-D points) of a map seen from a moving pose, and the
messages encoded (onto a pymavlink encoder that writes nowhere): thread CPU time and wall time,
p50 / p99 / max in ms, and the bytes Python allocates per tick (tracemalloc, a separate pass).
Per map: reading a local_map_t of mppid-mapper's window (128 x 128 x 32 cells) for its occupied
cells. Cases: a forest as mppid-mapper maps forest_4m (trunks 4 m apart, 0.3 m radius, 0.3-8 m
high; ~9,000 occupied cells) and a map of 100,000 occupied cells scattered through the window
(the worst the settings' 0.5 million-cell window is likely to hold).
"""
from __future__ import annotations

import argparse
import json
import math
import os
import platform
import subprocess
import time
import tracemalloc
from pathlib import Path

import numpy as np

os.environ.setdefault("MAVLINK20", "1")
from pymavlink.dialects.v20 import all as dialect  # noqa: E402

from mppi_mavlink import autopilots, lcm_types, settings  # noqa: E402
from mppi_mavlink.obstacle_distance import ObstacleSender, decode_map  # noqa: E402

DIMS, RES, ORIGIN = (128, 128, 32), 0.25, (-16.0, -16.0, 0.0)


def forest_occupancy() -> np.ndarray:
    nx, ny, nz = DIMS
    k, j, i = np.meshgrid(np.arange(nz), np.arange(ny), np.arange(nx), indexing="ij")
    cx, cy, cz = (ORIGIN[0] + (i + 0.5) * RES, ORIGIN[1] + (j + 0.5) * RES, ORIGIN[2] + (k + 0.5) * RES)
    occ = np.zeros(DIMS[::-1], dtype=bool)
    for row in range(-5, 6):
        for col in range(-5, 6):
            x, y = 4.0 * col + 2.0 * (row % 2), 4.0 * math.sqrt(0.75) * row
            if abs(x) < 16 and abs(y) < 16 and (x, y) != (0.0, 0.0):
                occ |= ((cx - x) ** 2 + (cy - y) ** 2 <= 0.09) & (cz >= 0.3)
    return occ


def scattered_occupancy(n: int) -> np.ndarray:
    occ = np.zeros(DIMS[0] * DIMS[1] * DIMS[2], dtype=bool)
    occ[np.random.default_rng(1).choice(occ.size, n, replace=False)] = True
    return occ.reshape(DIMS[::-1])


def encode(occ: np.ndarray) -> bytes:
    m = lcm_types.import_mppi_lcm().local_map_t()
    m.utime, m.seq, m.origin, m.resolution = 1, 1, list(ORIGIN), RES
    m.nx, m.ny, m.nz, m.max_distance = *DIMS, 5.0
    m.n_cells = occ.size
    m.distance_mm = np.where(occ, -125, 2000).ravel().tolist()
    return m.encode()


class NullLink:
    def __init__(self):
        self.mav = dialect.MAVLink(None, srcSystem=1, srcComponent=191)
        self.mav.send = lambda m, force_mavlink1=False: m.pack(self.mav)

    def send(self, fn):
        fn(self.mav)
        return True


def pct(v, q):
    return round(float(np.percentile(v, q)), 3)


def run_case(name: str, data: bytes, dialect_name: str, ticks: int) -> dict:
    s = settings.load(None)
    fp = lcm_types.import_mppi_lcm().local_map_t._get_packed_fingerprint()
    snd = ObstacleSender(s, NullLink(), autopilots.load(dialect_name), {}, fp)
    read_ms = []
    for _ in range(10):
        t0 = time.perf_counter()
        decode_map(data, fp, 0.0)
        read_ms.append((time.perf_counter() - t0) * 1e3)
    snd.on_map("MAP", data)
    snd.latest = (data, float("inf"))        # never stale here

    def pose(k):
        a = 0.05 * k
        return (3.0 * math.cos(a), 3.0 * math.sin(a), 1.5), (math.cos(a / 2), 0.0, 0.0, math.sin(a / 2))
    cpu, wall = [], []
    for k in range(ticks):
        p, q = pose(k)
        c0, w0 = time.thread_time(), time.perf_counter()
        snd.tick(k * 66_667, p, q)
        cpu.append((time.thread_time() - c0) * 1e3)
        wall.append((time.perf_counter() - w0) * 1e3)
    tracemalloc.start()
    before = tracemalloc.get_traced_memory()[1]
    tracemalloc.reset_peak()
    for k in range(20):
        snd.tick(k * 66_667, *pose(k))
    peak = tracemalloc.get_traced_memory()[1] - before
    tracemalloc.stop()
    return {"case": name, "dialect": dialect_name, "occupied_cells": snd.map.n, "ticks": ticks,
            "tick_cpu_ms": {"p50": pct(cpu, 50), "p99": pct(cpu, 99), "max": round(max(cpu), 3)},
            "tick_wall_ms": {"p50": pct(wall, 50), "p99": pct(wall, 99), "max": round(max(wall), 3)},
            "tick_peak_alloc_kib": round(peak / 1024, 1),
            "map_read_ms": {"p50": pct(read_ms, 50), "max": round(max(read_ms), 3)},
            "sent_3d_per_tick": snd.counters["obstacle_distance_3d_sent"] / (ticks + 20)}


def machine() -> dict:
    load = os.getloadavg()
    commit = subprocess.run(["git", "rev-parse", "--short", "HEAD"], capture_output=True, text=True,
                            cwd=Path(__file__).parent).stdout.strip()
    return {"machine": platform.node(), "cpu": platform.processor() or platform.machine(), "cores": os.cpu_count(),
            "python": platform.python_version(), "numpy": np.__version__, "commit": commit,
            "utc": time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime()), "loadavg": [round(x, 2) for x in load]}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--ticks", type=int, default=300)
    ap.add_argument("--out", help="also append the lines to this file")
    a = ap.parse_args(argv)
    lines = [{"machine": machine()}]
    for name, occ in (("forest_4m", forest_occupancy()), ("scattered_100k", scattered_occupancy(100_000))):
        data = encode(occ)
        for d in ("px4", "ardupilot"):
            lines.append(run_case(name, data, d, a.ticks))
    text = "".join(json.dumps(line) + "\n" for line in lines)
    print(text, end="")
    if a.out:
        with open(a.out, "a") as f:
            f.write(text)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
