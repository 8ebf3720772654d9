"""The robustness map (`tools/sitl robustness`, docs/robustness.md): how the controller flies
plants it is not told about, one mismatch at a time. For each base scenario (a forest: its
success; a tracking task: its RMSE) and each cell of the map, a variant scenario file is
written with the plant changed, and one campaign flies them all:

    mass      plant.params.mass x 0.8, 0.9, 1.1, 1.2
    motor     the thrust a command buys x 0.9, 1.1: plant.params.k_force (16-state quadrotor),
              plant.thrust_gain (the rate-controlled plants)
    wind      a steady wind of 1, 2, 3 m/s across the path (y), acting through drag: the plant
              gets drag/mass = 0.2 /s where it has none (forest_4m_robust's 0.05 N s/m on
              0.25 kg; 0.2 N s/m on 1 kg), which the model does not have either
    delay     timing.actuation_delay 10, 20 ms, the controller not told (its latency
              compensation knows only its own compute and transport)
    noise     the published state's noise at forest_4m_robust's levels, and twice them

Writes OUT/scenarios/*.yaml, the campaign (OUT/summary.json, summary.md, per-flight folders)
and OUT/robustness.md (the map, the command, the machine).
"""
from __future__ import annotations

import datetime
import os
import platform
import subprocess
import sys
from pathlib import Path

import yaml

from . import paths
from .results import load_campaign

# Per model: the mass and motor constant of core's defaults (what a scenario's plant has
# when it does not say) and the drag the wind cells give a plant without one.
MODEL_DEFAULTS = {
    "quadrotor": {"mass": 0.25, "k_force": 6.11e-8, "drag": 0.05},
    "quadrotor_rate": {"mass": 1.0, "drag": 0.2},
    "quadrotor_rate_body": {"mass": 1.0, "drag": 0.2},
}
ROBUST_NOISE = {"position": 0.01, "velocity": 0.02, "attitude": 0.005, "rate": 0.01, "other": 5.0}

CELLS = [
    ("nominal", "nominal", {}),
    ("mass_080", "mass -20 %", {"mass": 0.8}),
    ("mass_090", "mass -10 %", {"mass": 0.9}),
    ("mass_110", "mass +10 %", {"mass": 1.1}),
    ("mass_120", "mass +20 %", {"mass": 1.2}),
    ("motor_090", "motor constant -10 %", {"motor": 0.9}),
    ("motor_110", "motor constant +10 %", {"motor": 1.1}),
    ("wind_1", "wind 1 m/s", {"wind": 1.0}),
    ("wind_2", "wind 2 m/s", {"wind": 2.0}),
    ("wind_3", "wind 3 m/s", {"wind": 3.0}),
    ("delay_10", "actuation delay 10 ms, not told", {"delay": 0.010}),
    ("delay_20", "actuation delay 20 ms, not told", {"delay": 0.020}),
    ("noise_1", "sensor noise x1 (forest_4m_robust's)", {"noise": 1.0}),
    ("noise_2", "sensor noise x2", {"noise": 2.0}),
]


def variant(base: dict, change: dict) -> dict:
    """The base scenario with one cell's change to its plant, timing, wind or noise."""
    doc = yaml.safe_load(yaml.safe_dump(base))  # a deep copy
    plant = doc["plant"]
    model = plant["model"]
    params = plant.setdefault("params", {}) or {}
    plant["params"] = params
    d = MODEL_DEFAULTS[model]
    if "mass" in change:
        params["mass"] = round(params.get("mass", d["mass"]) * change["mass"], 6)
    if "motor" in change:
        if model == "quadrotor":
            params["k_force"] = params.get("k_force", d["k_force"]) * change["motor"]
        else:
            plant["thrust_gain"] = change["motor"]
    if "wind" in change:
        if not params.get("drag"):
            params["drag"] = d["drag"]
        doc["wind"] = {"mean": [0.0, change["wind"], 0.0], "gust_std": 0.0}
    if "delay" in change:
        doc.setdefault("timing", {})["actuation_delay"] = change["delay"]
    if "noise" in change:
        doc["noise"] = {k: v * change["noise"] for k, v in ROBUST_NOISE.items()}
    return doc


def write_variants(bases: list[str], out: Path) -> list[tuple[str, str, str, Path]]:
    """(base label, cell id, cell label, file) for every base and cell."""
    folder = out / "scenarios"
    folder.mkdir(parents=True, exist_ok=True)
    files = []
    for b in bases:
        spec = paths.scenario_path(b)
        base = yaml.safe_load(Path(spec).read_text())
        label = base.get("name") or Path(spec).stem
        if base["plant"]["model"] not in MODEL_DEFAULTS:
            raise ValueError(f"{b}: the map is for the quadrotors (plant model {base['plant']['model']})")
        for cell, text, change in CELLS:
            doc = variant(base, change)
            doc["name"] = f"{label}__{cell}"
            doc["description"] = f"{label} with {text} (tools/sitl robustness)"
            path = folder / f"{doc['name']}.yaml"
            path.write_text(yaml.safe_dump(doc, sort_keys=False))
            files.append((label, cell, text, path))
    return files


def machine() -> str:
    cpu = "?"
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                cpu = line.split(":", 1)[1].strip()
                break
    except OSError:
        pass
    commit = os.environ.get("MPPID_COMMIT", "")  # a copied tree (tools/gpu) names its commit so
    try:
        commit = commit or subprocess.run(["git", "-C", str(paths.ROOT), "rev-parse", "--short", "HEAD"],
                                          capture_output=True, text=True, timeout=10).stdout.strip()
    except (OSError, subprocess.SubprocessError):
        commit = "?"
    return f"{platform.node()}: {cpu}, {os.cpu_count()} CPUs, {platform.system()} {platform.release()}; commit {commit}"


def table(files, runs: dict) -> tuple[str, dict]:
    """The map: a row per cell, per base scenario its successes and its figure (time to goal
    for goal scenarios, RMSE for tracking); and the totals."""
    bases = list(dict.fromkeys(b for b, *_ in files))
    head = "| cell | " + " | ".join(f"{b}: success | {b}: figure" for b in bases) + " |"
    lines = [head, "|---|" + "---:|---|" * len(bases)]
    totals = {b: [0, 0] for b in bases}
    for cell, text, _ in CELLS:
        row = [text]
        for b in bases:
            rs = runs.get(f"{b}__{cell}", [])
            k = sum(1 for r in rs if r.get("success"))
            totals[b][0] += k
            totals[b][1] += len(rs)
            ok = [r for r in rs if r.get("success")]
            rmse = [r["tracking_rmse"] for r in ok if r.get("tracking_rmse") is not None]
            ttg = [r["time_to_goal"] for r in ok if r.get("time_to_goal") is not None]
            fig = (f"RMSE {sum(rmse) / len(rmse):.3f} m (max {max(rmse):.3f})" if rmse
                   else f"goal in {sum(ttg) / len(ttg):.2f} s" if ttg else "-")
            fails = sorted({(r.get("reason") or "?").split(" at t=")[0] for r in rs if not r.get("success")})
            row += [f"{k}/{len(rs)}" + (f" ({'; '.join(fails)})" if fails else ""), fig]
        lines.append("| " + " | ".join(row) + " |")
    return "\n".join(lines) + "\n", totals


def run_map(bases: list[str], seeds: list[int], out: Path, realtime: bool, sets=(), latency=None,
            realtime_jobs: int = 1) -> Path:
    from .campaign import run_campaign

    out = Path(out).resolve()
    files = write_variants(bases, out)
    started = datetime.datetime.now(datetime.timezone.utc)
    load0 = os.getloadavg()
    run_campaign([str(p) for *_, p in files], seeds, out, realtime=realtime, sets=sets, latency=latency, plots=False,
                 realtime_jobs=realtime_jobs)
    load1 = os.getloadavg()
    data = load_campaign(out)
    body, totals = table(files, data.by_scenario())
    total_k = sum(k for k, _ in totals.values())
    total_n = sum(n for _, n in totals.values())
    clock = "real time" if realtime else data.summary["clock"]
    command = " ".join(["tools/sitl"] + sys.argv[1:])
    text = (f"# Robustness map\n\n`{command}`\n\n"
            f"{clock}; seeds {data.summary['seeds'][0]}-{data.summary['seeds'][-1]} "
            f"({len(seeds)} per cell); {total_n} flights; {started:%Y-%m-%d %H:%M} UTC; "
            f"load average {load0[0]:.1f} at the start, {load1[0]:.1f} at the end.\n\nMachine: {machine()}\n\n"
            + body + "\nSuccess over the map: " +
            "; ".join(f"{b} {k}/{n} ({100 * k / n:.0f} %)" for b, (k, n) in totals.items()) +
            f"; all {total_k}/{total_n} ({100 * total_k / max(total_n, 1):.1f} %).\n")
    (out / "robustness.md").write_text(text)
    return out / "robustness.md"
