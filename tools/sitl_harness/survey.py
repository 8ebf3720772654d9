"""The figures of a survey uploaded to the autopilot (ap_gcs.py's world.json), from the SITL's
truth, the same for every controller:

    waypoints_reached     the mission's waypoints the true position came within their acceptance
                          radius of, in order (each after the one before)
    time_to_last_item_s   from the take-off (the truth first 0.5 m up) to the last waypoint reached
    forest_mean_speed     the mean true speed while among the trees (inside the forest's x and y
                          extent, airborne): the legs through the forest
    min_clearance         (ap_score) the closest trunk, surface to the vehicle's radius
"""
from __future__ import annotations

import json
import statistics
from pathlib import Path

import numpy as np

AIRBORNE_Z = 0.5


def load_world(out: Path) -> dict | None:
    p = Path(out) / "world.json"
    return json.loads(p.read_text()) if p.is_file() else None


def figures(world: dict, t_s: np.ndarray, X: np.ndarray, V: np.ndarray) -> dict:
    """t_s: the truth's times (s), X its positions, V its velocities (ENU); none without waypoints."""
    if "waypoints" not in world:
        return {}
    up = np.flatnonzero(X[:, 2] > AIRBORNE_Z)
    res = {"waypoints": len(world["waypoints"]), "waypoints_reached": 0, "time_to_last_item_s": None,
           "forest_mean_speed": None, "last_item_index": None}
    if not up.size:
        return res
    i = up[0]
    for wp, r in zip(world["waypoints"], world["acceptance"]):
        d = np.linalg.norm(X[i:, :2] - np.asarray(wp[:2], float), axis=1)
        near = np.flatnonzero(d <= r)
        if not near.size:
            break
        i += int(near[0])
        res["waypoints_reached"] += 1
    if res["waypoints_reached"] == res["waypoints"]:
        res["time_to_last_item_s"] = float(t_s[i] - t_s[up[0]])
        res["last_item_index"] = int(i)
    (x0, x1), (y0, y1) = world["forest_box"]
    inside = (X[:, 0] >= x0) & (X[:, 0] <= x1) & (X[:, 1] >= y0) & (X[:, 1] <= y1) & (X[:, 2] > AIRBORNE_Z)
    if inside.any():
        res["forest_mean_speed"] = float(np.mean(np.linalg.norm(V[inside], axis=1)))
    return res


def _median(vals, fmt="{:.1f}"):
    vals = [v for v in vals if isinstance(v, (int, float))]
    return fmt.format(statistics.median(vals)) if vals else "-"


def table_rows(mission: str, camps) -> list[str]:
    """One markdown row per controller for a survey mission: success, the time to the last
    waypoint and the mean speed among the trees (medians over the successful flights), the
    closest trunk (the least over all flights), deadline misses, the failures' reasons."""
    rows = []
    for label, runs in camps:
        rs = [r for r in runs if r["scenario"] == mission]
        if not rs:
            continue
        ok = [r for r in rs if r.get("success")]
        closest = [r["min_clearance"] for r in rs if isinstance(r.get("min_clearance"), (int, float))]
        misses = [r.get("deadline_misses") for r in rs if isinstance(r.get("deadline_misses"), int)]
        fails = "; ".join(sorted({str(r.get("reason")) for r in rs if not r.get("success")})) or "-"
        rows.append(f"| {mission} | {label} | {len(ok)}/{len(rs)} | {_median([r.get('time_to_last_item_s') for r in ok])} | "
                    f"{_median([r.get('forest_mean_speed') for r in ok], '{:.2f}')} | "
                    f"{f'{min(closest):.2f}' if closest else '-'} | {sum(misses) if misses else '-'} | {fails} |")
    return rows


TABLE_HEAD = ["| mission | controller | success | time to the last waypoint [s] | mean speed among the trees [m/s] "
              "| closest trunk [m] | deadline misses | failures |", "|---|---|---:|---:|---:|---:|---:|---|"]
