"""The score of a flight through PX4 SITL with SIH (flights/px4.py): px4_truth.py's record
turned into truth.jsonl (ap_truth.py's format), then scored as ArduCopter's flights are
(ap_score.py: per leg, the true and the estimated distance to the reference; crashes, tilt,
the forest's clearance), plus what only PX4 shows: its clock against ours, and how old the
bridge's states looked to mppid.

The truth's local frame is PX4's estimator's: SIH's geodetic position projected as PX4
projects GPS (its MapProjection: azimuthal equidistant on a sphere of 6 371 000 m) about the
estimator's origin (GPS_GLOBAL_ORIGIN; without one, about the first truth sample, shifted
onto the estimate there). Its times: PX4's boot clock for PX4's own controller (the mission
tool ran on it); for mppid, the boot clock mapped onto this host's wall clock by
mppi_mavlink.clock_sync, as the bridge maps the states' (SIH's clock runs ~1 % slow).
"""
from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
from mppi_mavlink import frames
from mppi_mavlink.layout import QuadrotorRate as Q

from . import ap_score
from .logs import read_jsonl

PX4_EARTH_R = 6_371_000.0   # CONSTANTS_RADIUS_OF_EARTH (PX4's geo library)


def project(lat_e7, lon_e7, ref_lat_e7, ref_lon_e7):
    """(north, east) [m] of points from a reference, as PX4's MapProjection::project."""
    lat, lon = np.radians(np.asarray(lat_e7, float) * 1e-7), np.radians(np.asarray(lon_e7, float) * 1e-7)
    lat0, lon0 = math.radians(ref_lat_e7 * 1e-7), math.radians(ref_lon_e7 * 1e-7)
    cos_dlon = np.cos(lon - lon0)
    c = np.arccos(np.clip(math.sin(lat0) * np.sin(lat) + math.cos(lat0) * np.cos(lat) * cos_dlon, -1.0, 1.0))
    k = np.where(np.abs(c) > 0, c / np.where(np.abs(c) > 0, np.sin(c), 1.0), 1.0)
    north = k * (math.cos(lat0) * np.sin(lat) - math.sin(lat0) * np.cos(lat) * cos_dlon) * PX4_EARTH_R
    east = k * np.cos(lat) * np.sin(lon - lon0) * PX4_EARTH_R
    return north, east


def _local(truth, est, origin) -> np.ndarray:
    """ENU positions of the truth in the estimator's frame."""
    lat, lon, alt = (np.array([r[k] for r in truth], float) for k in ("lat", "lon", "alt"))
    if origin:
        n, e = project(lat, lon, origin["lat_e7"], origin["lon_e7"])
        return np.stack([e, n, alt * 1e-3 - origin["alt_mm"] * 1e-3], axis=1)
    n, e = project(lat, lon, lat[0], lon[0])
    X = np.stack([e, n, (alt - alt[0]) * 1e-3], axis=1)
    if est:  # the estimate at the first truth sample (at rest): the shared origin
        e0 = min(est, key=lambda r: abs(r["boot_us"] - truth[0]["boot_us"]))
        X += np.array(e0["est"])
    return X


def _mission_clock(truth, clock: str) -> np.ndarray:
    boot = np.array([r["boot_us"] for r in truth], float)
    if clock == "boot":
        return boot
    from mppi_mavlink import clock_sync
    sync = clock_sync.ClockSync()
    return np.array([sync.update(int(r["boot_us"]), int(r["wall_us"])) for r in truth], float)


def convert(out: Path) -> list[dict]:
    """truth_raw.jsonl -> truth.jsonl (ap_truth.py's lines, each with `mission_us`); the lines."""
    raw = read_jsonl(out / "truth_raw.jsonl")
    truth = [r for r in raw if "truth" in r]
    est = [r for r in raw if "est" in r]
    if not truth:
        return []
    mission = read_jsonl(out / "mission.jsonl") if (out / "mission.jsonl").is_file() else []
    clock = next((m.get("clock", "state") for m in mission if m.get("event") == "mission"), "state")
    origin = next((r for r in raw if r.get("event") == "origin"), None)
    X, t_mission = _local(truth, est, origin), _mission_clock(truth, clock)
    est_t = np.array([r["boot_us"] for r in est], float)
    lines, mode, armed = [], "", False
    events = iter(sorted((r for r in raw if "event" in r), key=lambda r: r["wall_us"]))
    ev = next(events, None)
    for i, r in enumerate(truth):
        while ev is not None and ev["wall_us"] <= r["wall_us"]:
            mode = ev["mode"] if ev["event"] == "mode" else mode
            armed = {"armed": True, "disarmed": False}.get(ev["event"], armed)
            lines.append({**ev, "boot_us": r["boot_us"]})
            ev = next(events, None)
        j = int(np.searchsorted(est_t, r["boot_us"], side="right")) - 1
        lines.append({"boot_us": r["boot_us"], "wall_us": r["wall_us"], "mission_us": int(t_mission[i]),
                      "x": [round(float(c), 4) for c in X[i]], "v": r["v"],
                      "tilt_deg": round(frames.tilt_deg(r["q"]), 2),
                      "est": est[j]["est"] if j >= 0 else None, "mode": mode, "armed": armed})
    with open(out / "truth.jsonl", "w") as f:
        f.writelines(json.dumps(line) + "\n" for line in lines)
    return lines


def clock_rate(truth: list[dict]) -> dict:
    """PX4's clock against ours: the least-squares slope of boot vs receive time."""
    rows = [r for r in truth if "x" in r]
    if len(rows) < 10:
        return {}
    w = np.array([r["wall_us"] for r in rows], float) * 1e-6
    b = np.array([r["boot_us"] for r in rows], float) * 1e-6
    slope = np.polyfit(w - w[0], b - b[0], 1)[0]
    return {"px4_clock_rate_ppm": round(float((slope - 1.0) * 1e6)),
            "px4_behind_at_end_s": round(float((w[-1] - w[0]) - (b[-1] - b[0])), 3)}


def state_ages(out: Path) -> dict:
    """How old the bridge's states looked to mppid (utime - sample_utime), from the LCM log."""
    from . import logs
    log = out / "flight.lcmlog"
    if not log.is_file():
        return {}
    states = [m for _, m in logs.read_lcm_log(log, {"MPPI_STATE"}).get("MPPI_STATE", [])]
    if not states:
        return {}
    a = np.array([m.utime - m.sample_utime for m in states], float) * 1e-3
    return {"state_age_ms": {"p50": round(float(np.median(a)), 2), "p99": round(float(np.percentile(a, 99)), 2),
                             "max": round(float(a.max()), 2)}}


def fault_report(truth: list[dict], fault: dict, window_s: float = 10.0) -> dict:
    """What PX4 did after a fault (a failsafe flight): its modes and messages, and the truth
    over the next `window_s`: the largest tilt, the lowest altitude, the horizontal drift."""
    t_f = fault["wall_us"]
    rel = lambda r: round((r["wall_us"] - t_f) * 1e-6, 2)  # noqa: E731
    after = [r for r in truth if "x" in r and 0 <= r["wall_us"] - t_f <= window_s * 1e6]
    events = [r for r in truth if "event" in r and r["wall_us"] >= t_f]
    rep = {**fault,
           "modes": [(rel(e), e["mode"]) for e in events if e["event"] == "mode"][:8],
           "armed": [(rel(e), e["event"]) for e in events if e["event"] in ("armed", "disarmed")][:4],
           "statustexts": [(rel(e), e["text"]) for e in events if e["event"] == "statustext"][:16]}
    if after:
        X = np.array([r["x"] for r in after])
        rep.update(alt_at_fault=round(float(X[0, Q.PZ]), 2), min_alt=round(float(X[:, Q.PZ].min()), 2),
                   max_tilt_deg=max(r["tilt_deg"] for r in after),
                   drift_m=round(float(np.max(np.linalg.norm(X[:, Q.PX:Q.PY + 1] - X[0, Q.PX:Q.PY + 1], axis=1))), 2))
    return rep


# vehicle_status.nav_state (PX4's uORB vehicle_status.msg).
NAV_STATES = {0: "MANUAL", 1: "ALTCTL", 2: "POSCTL", 3: "MISSION", 4: "HOLD", 5: "RTL", 10: "ACRO", 12: "DESCEND",
              13: "TERMINATION", 14: "OFFBOARD", 15: "STABILIZED", 17: "TAKEOFF", 18: "LAND", 19: "FOLLOW",
              20: "PRECLAND", 21: "ORBIT"}


def ulog_modes(out: Path, truth: list[dict], fault: dict, window_s: float = 30.0) -> list | None:
    """PX4's own record of its modes after a fault (the ULog's vehicle_status, to the
    millisecond; the GCS link's HEARTBEAT comes once a second): [(s after the fault, mode)].
    The fault's wall time goes onto PX4's clock through the nearest truth sample."""
    logs = sorted((out / "px4" / "log").glob("*/*.ulg"))
    rows = [r for r in truth if "x" in r]
    if not logs or not rows:
        return None
    try:
        from pyulog import ULog
    except ImportError:
        return None
    near = min(rows, key=lambda r: abs(r["wall_us"] - fault["wall_us"]))
    boot_f = near["boot_us"] + (fault["wall_us"] - near["wall_us"])
    st = next((d.data for d in ULog(str(logs[-1]), ["vehicle_status"]).data_list), None)
    if st is None:
        return None
    out_, last = [], None
    for t, n in zip(st["timestamp"], st["nav_state"]):
        if n != last and boot_f <= t <= boot_f + window_s * 1e6:
            out_.append((round((int(t) - boot_f) * 1e-6, 3), NAV_STATES.get(int(n), str(n))))
        last = n
    return out_


def _boot_us(truth: list[dict], wall_us: int) -> float:
    """A wall time on PX4's clock, through the nearest truth sample."""
    near = min((r for r in truth if "x" in r), key=lambda r: abs(r["wall_us"] - wall_us))
    return near["boot_us"] + (wall_us - near["wall_us"])


def ulog_collision_prevention(out: Path, truth: list[dict]) -> dict | None:
    """What PX4's collision prevention had while the stick was pushed (--controller position),
    from its ULog: the OBSTACLE_DISTANCE messages it took (obstacle_distance) and their rate, its
    map's nearest obstacle (obstacle_distance_fused, the 72 bins) at the release, and how often it
    adapted the stick's setpoint (collision_constraints)."""
    logs = sorted((out / "px4" / "log").glob("*/*.ulg"))
    ev = {m["event"]: m["wall_us"] for m in read_jsonl(out / "mission.jsonl") if m.get("event") in ("push", "released")}
    if not logs or {"push", "released"} - set(ev) or not any("x" in r for r in truth):
        return None
    try:
        from pyulog import ULog
    except ImportError:
        return None
    t0, t1 = _boot_us(truth, ev["push"]), _boot_us(truth, ev["released"])
    topics = {d.name: d.data for d in ULog(str(logs[-1]), ["obstacle_distance", "obstacle_distance_fused",
                                                            "collision_constraints"]).data_list}
    res = {}
    for name in ("obstacle_distance", "collision_constraints"):
        t = topics.get(name, {}).get("timestamp", np.array([]))
        n = int(np.count_nonzero((t >= t0) & (t <= t1)))
        res[f"{name}_msgs"] = n
        res[f"{name}_hz"] = round(n / ((t1 - t0) * 1e-6), 1)
    fused = topics.get("obstacle_distance_fused")
    if fused is not None and len(fused["timestamp"]):
        i = max(int(np.searchsorted(fused["timestamp"], t1, side="right")) - 1, 0)
        bins = np.array([fused[f"distances[{k}]"][i] for k in range(72)], float)
        j = int(np.argmin(bins))
        res["nearest_at_release_m"] = None if bins[j] >= 65535 else round(float(bins[j]) * 0.01, 2)
        res["nearest_bin_deg"] = 5 * j
    return res


def score_flight(out: Path, spec, info: dict) -> dict:
    out = Path(out)
    truth = convert(out)
    res = ap_score.score_flight(out, spec, info, autopilot="px4")
    res["px4_clock"] = clock_rate(truth)
    if spec.controller != "px4":
        res.update(state_ages(out))
    res.pop("state_to_command_samples_ms", None)
    if spec.controller == "position":
        res["collision_prevention"] = ulog_collision_prevention(out, truth)
    if info.get("faults"):
        res["faults"] = [{**fault_report(truth, f), "px4_modes": ulog_modes(out, truth, f)} for f in info["faults"]]
    return res
