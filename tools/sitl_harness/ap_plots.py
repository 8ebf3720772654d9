"""PNG plots of a flight through ArduCopter SITL (ardupilot.py): path.png, the true path over
the virtual trees with the references the mission asked for (top view) and the altitude and
tracking error against time; timing.png, mppid's timing (plots.py's, from its commands)."""
from __future__ import annotations

import json
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
from mppi_mavlink.layout import QuadrotorRate as Q  # noqa: E402

from . import ap_score, plots  # noqa: E402
from .logs import read_jsonl  # noqa: E402

# How each plant is named in the title (harness.json's `autopilot`).
PLANT_NAMES = {"ardupilot": "ArduCopter SITL", "px4": "PX4 SITL (SIH)"}


def plot_flight(out: Path) -> list[Path]:
    out = Path(out)
    truth = [r for r in read_jsonl(out / "truth.jsonl") if "x" in r]
    mission = read_jsonl(out / "mission.jsonl")
    if not truth or not mission:
        return []
    made = [_path(out, truth, mission)]
    head = next((m for m in mission if m.get("event") == "mission"), {})
    if head.get("clock") == "state":  # mppid flew (the baseline has no controller of ours)
        made.append(plots._timing(out, []))
    return [p for p in made if p]


def _path(out, truth, mission):
    from mppi_mission import reference
    head = next((m for m in mission if m.get("event") == "mission"), {})
    t_truth = ap_score._truth_clock(truth, head.get("clock", "state"))
    X = np.array([r["x"] for r in truth])
    steps = [m for m in mission if m.get("event") == "step"]
    fig, (top, side) = plt.subplots(1, 2, figsize=(13, 5.2), gridspec_kw={"width_ratios": [1.1, 1.4]})
    for x, y, r in head.get("trees") or []:
        top.add_patch(plt.Circle((x, y), r, color="tab:green", alpha=0.6))
    err_t, err = [], []
    for i, s in enumerate(steps):
        t_end = steps[i + 1]["t0_us"] if i + 1 < len(steps) else t_truth[-1]
        sel = (t_truth >= s["t0_us"]) & (t_truth < t_end)
        if not sel.any():
            continue
        ref = reference.evaluate(s["ref"], (t_truth[sel] - s["t0_us"]) * 1e-6)[0]
        top.plot(ref[:, 0], ref[:, 1], "k--", lw=0.8)
        err_t.append(t_truth[sel])
        err.append(np.linalg.norm(X[sel] - ref, axis=1))
    top.plot(X[:, Q.PX], X[:, Q.PY], lw=1.0, c="tab:blue", label="true path")
    top.set_aspect("equal")
    top.set_xlabel("x east [m]")
    top.set_ylabel("y north [m]")
    top.legend(loc="best", fontsize=8)
    t0 = t_truth[0]
    side.plot((t_truth - t0) * 1e-6, X[:, Q.PZ], c="tab:blue", lw=0.9, label="altitude [m]")
    if err:
        side.plot((np.concatenate(err_t) - t0) * 1e-6, np.concatenate(err), c="tab:red", lw=0.8,
                  label="distance to the reference [m]")
    side.set_xlabel("time [s]")
    side.legend(loc="upper right", fontsize=8)
    score = json.loads((out / "score.json").read_text()) if (out / "score.json").is_file() else {}
    plant = PLANT_NAMES.get(score.get("autopilot", "ardupilot"), score.get("autopilot"))
    fig.suptitle(f"{head.get('name', '')} seed {head.get('seed', '')} through {plant}: "
                 f"{score.get('reason', '')}", fontsize=10)
    fig.tight_layout()
    p = out / "path.png"
    fig.savefig(p, dpi=80)
    plt.close(fig)
    return p
