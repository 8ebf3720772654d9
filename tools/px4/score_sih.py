"""The score of a flight through PX4 SIH (fly_sih.py), from SIH's truth.

Inputs in the flight's folder: truth.jsonl (HIL_STATE_QUATERNION: SIH's groundtruth, with
receive times), estimate.jsonl (LOCAL_POSITION_NED from the GCS link), mission.jsonl (each
step's reference and its epoch on the state stream's clock: this machine's wall clock as the
bridge maps PX4's boot time onto it).

- PX4's clock: boot time against receive time, a least-squares line over the flight: its
  rate error (ppm) and how far behind it fell.
- The truth on the mission's clock: its boot times mapped by mppi_mavlink.clock_sync, as the
  bridge maps the states'. Its position: geodetic -> ENU about the first truth sample (the
  vehicle at rest at home, where PX4's estimator takes its origin), shifted by the estimate
  there, so truth and estimate share the local frame.
- Per leg (as tools/sitl_harness scores ArduCopter): RMS and largest distance between the
  true position and the reference, from `settle` s after a path's ramp (a hold's start), and
  the same from PX4's estimate. Crash: truth below 5 cm while the mission flew, after take-off.
"""
from __future__ import annotations

import json
import math
import sys
from pathlib import Path

import numpy as np
from mppi_mavlink import clock_sync
from sitl_harness.logs import read_jsonl

ROOT = Path(__file__).resolve().parents[2]
EARTH_R = 6_378_137.0


def clock_rate(boot_us: np.ndarray, wall_us: np.ndarray) -> dict:
    """PX4's clock against ours: the least-squares slope of boot vs receive time."""
    if boot_us.size < 10:
        return {}
    w = (wall_us - wall_us[0]) * 1e-6
    b = (boot_us - boot_us[0]) * 1e-6
    slope = np.polyfit(w, b, 1)[0]
    return {"px4_clock_rate_ppm": round(float((slope - 1.0) * 1e6)), "seconds": round(float(w[-1]), 1),
            "px4_behind_at_end_s": round(float(w[-1] - b[-1]), 3)}


def truth_enu(truth: list[dict], est: list[dict]) -> tuple[np.ndarray, np.ndarray]:
    """(times on the mission's clock [us], ENU positions [m]) of the truth."""
    sync = clock_sync.ClockSync()
    t = np.array([sync.update(r["time_usec"], r["wall_us"]) for r in truth], float)
    lat = np.radians([r["lat"] * 1e-7 for r in truth])
    lon = np.radians([r["lon"] * 1e-7 for r in truth])
    alt = np.array([r["alt"] * 1e-3 for r in truth])
    east = (lon - lon[0]) * EARTH_R * math.cos(lat[0])
    north = (lat - lat[0]) * EARTH_R
    X = np.stack([east, north, alt - alt[0]], axis=1)
    if est:  # the estimate's position at the first truth sample (at rest): the shared origin
        e0 = min(est, key=lambda r: abs(r["wall_us"] - truth[0]["wall_us"]))
        X += np.array([e0["y"], e0["x"], -e0["z"]])
    return t, X


def estimate_enu(est: list[dict]) -> tuple[np.ndarray, np.ndarray]:
    sync = clock_sync.ClockSync()
    t = np.array([sync.update(r["time_boot_ms"] * 1000, r["wall_us"]) for r in est], float)
    return t, np.array([[r["y"], r["x"], -r["z"]] for r in est], float)


def legs(mission: list[dict], t_truth, X, t_est, E, settle: float) -> dict:
    from mppi_mission import reference
    steps = [m for m in mission if m.get("event") == "step" and m["leg"] >= 0]
    res = {}
    for i, s in enumerate(steps):
        if s.get("transit") or s["kind"] == "goal":
            continue
        t_end = steps[i + 1]["t0_us"] if i + 1 < len(steps) else max(t_truth[-1], t_est[-1]) + 1
        start = settle + (float(s["ref"].get("ramp", 0.0)) if s["kind"] != "hold" else 0.0)
        row = {"speed": s["ref"].get("speed")}
        for name, tt, P in (("", t_truth, X), ("_estimate", t_est, E)):
            t = (tt - s["t0_us"]) * 1e-6
            sel = (t >= start) & (tt < t_end)
            if s["duration"] is not None:
                sel &= t <= s["duration"]
            if not sel.any():
                continue
            e = np.linalg.norm(P[sel] - reference.evaluate(s["ref"], t[sel])[0], axis=1)
            row[f"rmse{name}"], row[f"max{name}"] = float(np.sqrt(np.mean(e ** 2))), float(e.max())
            row[f"samples{name}"] = int(sel.sum())
        if "rmse" in row:
            res[f"leg{s['leg']}_{s['kind']}"] = row
    return res


def link_record(out: Path) -> dict:
    """From the LCM log: how old the states looked to mppid (utime - sample_utime: the
    bridge's mapping of PX4's clock) and how mppid's commands went (by mode)."""
    log = out / "flight.lcmlog"
    if not log.is_file():
        return {}
    import lcm
    import mppi_lcm
    command_t, vehicle_state_t = mppi_lcm.command_t, mppi_lcm.vehicle_state_t
    ages, modes, first = [], {}, {}
    ev_log = lcm.EventLog(str(log), "r")
    t_start = None
    for ev in ev_log:
        t_start = ev.timestamp if t_start is None else t_start
        if ev.channel == "MPPI_STATE":
            m = vehicle_state_t.decode(ev.data)
            ages.append((ev.timestamp, m.utime - m.sample_utime))
        elif ev.channel == "MPPI_COMMAND":
            m = command_t.decode(ev.data)
            name = {0: "normal", 1: "hold_plan", 2: "failsafe"}.get(m.mode, str(m.mode))
            modes[name] = modes.get(name, 0) + 1
            first.setdefault(name, round((ev.timestamp - t_start) * 1e-6, 2))
    ev_log.close()
    if not ages:
        return {"commands": modes}
    a = np.array([x for _, x in ages], float) * 1e-3
    t = (np.array([x for x, _ in ages], float) - ages[0][0]) * 1e-6
    return {"state_age_ms": {"p50": round(float(np.median(a)), 2), "p99": round(float(np.percentile(a, 99)), 2),
                             "max": round(float(a.max()), 2), "at_end": round(float(a[-1]), 2),
                             "first_over_100ms_s": round(float(t[a > 100][0]), 1) if (a > 100).any() else None},
            "commands": modes, "first_command_s": first}


def score(out: Path) -> dict:
    out = Path(out)
    truth = [r for r in read_jsonl(out / "truth.jsonl") if r.get("mavpackettype") == "HIL_STATE_QUATERNION"]
    est = [r for r in read_jsonl(out / "estimate.jsonl") if r.get("mavpackettype") == "LOCAL_POSITION_NED"]
    mission = read_jsonl(out / "mission.jsonl")
    summary = json.loads((out / "mission_summary.json").read_text()) if (out / "mission_summary.json").is_file() else {}
    res = {"mission_outcome": summary.get("outcome"), "truth_samples": len(truth), "estimate_samples": len(est),
           **link_record(out)}
    if truth:
        res["clock"] = clock_rate(np.array([r["time_usec"] for r in truth], float),
                                  np.array([r["wall_us"] for r in truth], float))
    if not truth or not est or not mission:
        res["reason"] = "no truth, estimate or mission record"
        return res
    head = next((m for m in mission if m.get("event") == "mission"), {})
    t_truth, X = truth_enu(truth, est)
    t_est, E = estimate_enu(est)
    res["legs"] = legs(mission, t_truth, X, t_est, E, float(head.get("settle", 3.0)))
    steps = [m["t0_us"] for m in mission if m.get("event") == "step"]
    air = np.flatnonzero(X[:, 2] > 0.5)
    if air.size and steps:
        fly = (t_truth >= max(steps[0], t_truth[air[0]])) & (t_truth <= steps[-1])
        res["ground_contact_in_mission"] = bool(np.any(X[fly, 2] < 0.05))
    res["max_speed"] = float(np.max(np.linalg.norm([[r["vx"], r["vy"], r["vz"]] for r in truth], axis=1)) / 100.0)
    paths = [v for k, v in res["legs"].items() if not k.endswith("_hold")]
    holds = [v for k, v in res["legs"].items() if k.endswith("_hold")]
    if paths:
        res["tracking_rmse"] = float(np.sqrt(np.mean([v["rmse"] ** 2 for v in paths])))
    if holds:
        res["hover_rmse"] = float(np.sqrt(np.mean([v["rmse"] ** 2 for v in holds])))
    return res


if __name__ == "__main__":
    print(json.dumps(score(Path(sys.argv[1])), indent=1))
