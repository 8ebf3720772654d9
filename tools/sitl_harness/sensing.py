"""What a sensed flight sensed and when (scenarios with sensing:, docs/sensing.md): from the
mapper's sensed.jsonl (each map's newly occupied x-y columns, with the time since the first
frame and the sensor's position), the world's trees (world.json) and the true path
(truth.jsonl): per tree, when it first entered the map and how far the vehicle then was, and
the closest approach; the mapper's and the sensors' timings beside."""
from __future__ import annotations

from pathlib import Path

import numpy as np
from mppi_mavlink.layout import QuadrotorRate as Q

from . import logs

PASSED_WITHIN_M = 3.0  # a tree the vehicle came this close to (surface) is one it had to see


def read_sensed(path: Path) -> list[dict]:
    """The mapper's sensed.jsonl (a line cut by the mapper's end skipped)."""
    return logs.read_jsonl(path)


def first_sightings(trees: list, records: list[dict], resolution: float) -> list[dict | None]:
    """For each tree (x, y, r, ...): the first record with a column within r + 0.75 cell of its
    centre: {"t", "range" (sensor to surface, m)}; None if never."""
    first: list[dict | None] = [None] * len(trees)
    for rec in records:
        cols = np.asarray(rec.get("columns", []), float).reshape(-1, 2)
        if not len(cols):
            continue
        for i, tr in enumerate(trees):
            if first[i] is not None:
                continue
            if np.min(np.hypot(cols[:, 0] - tr[0], cols[:, 1] - tr[1])) <= tr[2] + 0.75 * resolution:
                s = rec.get("sensor", [np.nan] * 3)
                first[i] = {"t": float(rec["t"]), "range": float(np.hypot(s[0] - tr[0], s[1] - tr[1]) - tr[2])}
    return first


def closest_approaches(trees: list, t: np.ndarray, xy: np.ndarray) -> list[tuple[float, float]]:
    """Per tree: (the vehicle's least distance to its surface, when)."""
    res = []
    for tr in trees:
        d = np.hypot(xy[:, 0] - tr[0], xy[:, 1] - tr[1]) - tr[2]
        k = int(np.nanargmin(d))
        res.append((float(d[k]), float(t[k])))
    return res


def sensing_figures(out: Path, world: dict, t: np.ndarray | None, X: np.ndarray | None) -> dict:
    """score.json's "sensing" for a sensed flight (a sensed.jsonl in `out`), else {}."""
    out = Path(out)
    if not (out / "sensed.jsonl").is_file():
        return {}
    stats = logs.read_json(out / "mapper_stats.json") or {}
    sim = logs.read_json(out / "sim_summary.json") or {}
    trees = [o for o in world.get("obstacles", []) if len(o) >= 3]
    first = first_sightings(trees, read_sensed(out / "sensed.jsonl"), float(stats.get("resolution", 0.25)))
    res = {"trees": len(trees), "trees_sensed": sum(f is not None for f in first),
           "mapper": {k: stats[k] for k in ("frames", "maps", "integrate_ms", "integrate_cpu_ms", "publish_ms",
                                             "publish_cpu_ms", "map_age_ms", "cells") if k in stats},
           "sensors": sim.get("sensors", {})}
    if t is None or X is None or not len(t) or not trees:
        return {"sensing": res}
    per_tree = []
    for i, (dmin, tmin) in enumerate(closest_approaches(trees, t, X[:, Q.PX:Q.PY + 1])):
        if dmin > PASSED_WITHIN_M:
            continue
        f = first[i]
        per_tree.append({"tree": i, "x": round(trees[i][0], 2), "y": round(trees[i][1], 2),
                         "closest_m": round(dmin, 3), "closest_t": round(tmin, 2),
                         "first_sensed_t": None if f is None else round(f["t"], 2),
                         "first_sensed_range_m": None if f is None else round(f["range"], 2)})
    seen = [p for p in per_tree if p["first_sensed_t"] is not None]
    res.update({"passed": len(per_tree), "passed_unsensed": [p["tree"] for p in per_tree if p["first_sensed_t"] is None],
                "min_first_sensed_range_m": min((p["first_sensed_range_m"] for p in seen), default=None),
                # How long before the closest approach the tree was in the map, at the least.
                "min_warning_s": min((round(p["closest_t"] - p["first_sensed_t"], 2) for p in seen), default=None),
                "per_tree": per_tree})
    return {"sensing": res}
