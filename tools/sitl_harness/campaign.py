"""Campaigns: seeds x scenarios (names or YAML files), each flight a separate `sitl run`
process with its own network namespace and LCM URL, run by an engine (engine.py: local
processes, or Ray tasks); the summary is the same whatever the engine."""
from __future__ import annotations

import math
import sys
from pathlib import Path

import numpy as np

from . import paths
from .engine import FlightJob, Progress, make_engine, run_flights
from .results import load_campaign, write_campaign


def wilson(k: int, n: int, z: float = 1.96):
    """Wilson score interval of a success rate (95 % by default). It always holds k / n: at
    k = 0 and k = n its end is exactly 0 or 1 (in floating point c - h came out at 3e-17 for
    0/11, and c + h at 1 - 1e-16 for 6/6, an interval beside the rate that the campaign plot's
    error bars refused: 'yerr' must not contain negative values)."""
    if n == 0:
        return (0.0, 1.0)
    p = k / n
    d = 1 + z * z / n
    c = (p + z * z / (2 * n)) / d
    h = z * math.sqrt(p * (1 - p) / n + z * z / (4 * n * n)) / d
    return (min(p, max(0.0, c - h)), max(p, min(1.0, c + h)))


def parse_seeds(text: str, first_seed: int = 1) -> list[int]:
    """"20" -> 20 seeds from first_seed; "51-70" or "1,3,10-12" -> those seeds."""
    text = str(text).strip()
    if text.isdigit():
        n = int(text)
        if n < 1:
            raise ValueError("--seeds: at least one seed")
        return list(range(first_seed, first_seed + n))
    seeds: list[int] = []
    for part in text.split(","):
        a, dash, b = part.strip().partition("-")
        try:
            lo, hi = int(a), int(b) if dash else int(a)
        except ValueError:
            raise ValueError(f"--seeds: cannot read '{part}' (a count, or seeds such as 51-70 or 1,4,9-12)") from None
        if lo < 0 or hi < lo:
            raise ValueError(f"--seeds: bad range '{part}'")
        seeds += [k for k in range(lo, hi + 1) if k not in seeds]
    if not seeds:
        raise ValueError("--seeds: no seed")
    return seeds


def resolve_scenarios(names) -> list[tuple[str, str]]:
    """[(scenario as given: a name or a YAML file, label)]; the label (the scenario's `name`,
    else the file's stem) names its result folder. Raises FileNotFoundError or ValueError."""
    out, seen = [], {}
    for n in names:
        p = Path(n)
        spec = str(p.resolve()) if p.suffix in (".yaml", ".yml") and p.is_file() else n
        label = paths.scenario_label(spec)
        if label in seen:
            raise ValueError(f"scenarios {seen[label]} and {n} are both named '{label}'")
        seen[label] = n
        out.append((spec, label))
    return out


def make_jobs(scenarios, seeds, out: Path, backend="cpu", controller="mppid", realtime=False, sets=(), plots=True,
              timeout=0.0, ideal=False, latency=None, autopilot="sim", ardupilot_bin=None,
              px4_bin=None) -> list[FlightJob]:
    """One job per scenario and seed, scenario-major; folders out/<label>/seed_NNNN."""
    jobs = []
    for spec, label in scenarios:
        for seed in seeds:
            jobs.append(FlightJob(index=len(jobs), scenario=spec, label=label, seed=seed,
                                  out=Path(out) / label / f"seed_{seed:04d}", backend=backend, controller=controller,
                                  realtime=realtime, sets=list(sets), plots=plots, timeout=timeout, ideal=ideal,
                                  latency=latency, autopilot=autopilot, ardupilot_bin=ardupilot_bin,
                                  px4_bin=px4_bin))
    return jobs


def run_campaign(scenarios, seeds, out: Path, jobs: int | None = None, backend: str = "cpu", first_seed: int = 1,
                 controller: str = "mppid", realtime: bool = False, sets=(), engine: str = "local",
                 address: str | None = None, cpus_per_flight: float = 1.0, ideal: bool = False,
                 latency: float | None = None, realtime_jobs: int = 1, plots: bool = True, autopilot: str = "sim",
                 ardupilot_bin: str | None = None, px4_bin: str | None = None) -> dict:
    """Flies every scenario (names or YAML files) over the seeds (a count from first_seed, or
    a list) on the engine; writes summary.json, summary.md, summary.png; returns the summary."""
    out = Path(out).resolve()
    out.mkdir(parents=True, exist_ok=True)
    seed_list = list(range(first_seed, first_seed + seeds)) if isinstance(seeds, int) else list(seeds)
    resolved = resolve_scenarios(scenarios)
    if realtime:
        # Real-time flights compete for the CPU: one at a time, or realtime_jobs at once,
        # each pinned to its own share of the cores (a many-core machine).
        jobs = max(1, realtime_jobs)
    elif jobs is None and engine == "local":
        # Lock-step charging the measured latency: a second flight on the machine would
        # lengthen it. With --ideal, a fixed --latency or the stand-in, two at a time.
        jobs = 2 if (ideal or latency is not None or controller == "standin") else 1
    flights = make_jobs(resolved, seed_list, out, backend=backend, controller=controller, realtime=realtime, sets=sets,
                        plots=plots, ideal=ideal, latency=latency, autopilot=autopilot, ardupilot_bin=ardupilot_bin,
                        px4_bin=px4_bin)
    eng = make_engine(engine, jobs=jobs, address=address, cpus_per_flight=cpus_per_flight,
                      pin=realtime and jobs > 1)
    try:
        results = run_flights(eng, flights, Progress(len(flights)))
        desc = eng.describe()
    finally:
        eng.close()
    summary = summarize(results)
    summary["command"] = " ".join(sys.argv)
    summary["engine"] = desc
    summary["jobs"] = desc["jobs"]
    summary["sets"] = list(sets)
    summary["seeds"] = seed_list
    summary["autopilot"] = autopilot
    summary["clock"] = ("realtime" if realtime else "lockstep, " + (
        "ideal (no latency charged)" if ideal else f"fixed latency {latency:g} s" if latency is not None
        else "measured latency charged"))
    summary["scenario_files"] = {label: spec for spec, label in resolved}
    write_campaign(out, summary, results)
    (out / "summary.md").write_text(markdown(summary))
    try:
        from .campaign_plot import plot_campaign
        plot_campaign(out)
    except Exception as e:  # the table is the result; the plot is a convenience
        print(f"sitl: campaign plot failed: {e!r}", file=sys.stderr)
    return summary


def _stat(vals):
    vals = [v for v in vals if v is not None and isinstance(v, (int, float)) and math.isfinite(v)]
    if not vals:
        return None
    return {"mean": float(np.mean(vals)), "median": float(np.median(vals)), "min": float(np.min(vals)),
            "max": float(np.max(vals)), "n": len(vals)}


def summarize(results) -> dict:
    by = {}
    for r in results:
        by.setdefault(r.get("scenario"), []).append(r)
    rows = {}
    for scen, rs in sorted(by.items()):
        n, k = len(rs), sum(1 for r in rs if r.get("success"))
        ok = [r for r in rs if r.get("success")]
        reasons = {}
        for r in rs:
            if not r.get("success"):
                key = (r.get("reason") or "?").split(" at t=")[0]
                reasons[key] = reasons.get(key, 0) + 1
        rows[scen] = {
            "runs": n, "successes": k, "success_rate": k / n if n else 0.0, "wilson95": wilson(k, n),
            "time_to_goal": _stat([r.get("time_to_goal") for r in ok]),
            "tracking_rmse": _stat([r.get("tracking_rmse") for r in ok]),
            # Through an autopilot (ap_score.py): the hover error, the largest tilt.
            "hover_rmse": _stat([r.get("hover_rmse") for r in ok]),
            "max_tilt_deg": _stat([r.get("max_tilt_deg") for r in rs]),
            "min_clearance": _stat([r.get("min_clearance") for r in rs]),
            "mean_speed": _stat([r.get("mean_speed") for r in ok]),
            # Per flight: p99 over its cycles (timing.py); the column shows the worst flight.
            "compute_ms_p99": _stat([r.get("compute_ms_p99") for r in rs]),
            "compute_ms_p99_worst_window": _stat([r.get("compute_ms_p99_worst_window") for r in rs]),
            "deadline_misses": _stat([r.get("deadline_misses") for r in rs]),
            "failures": reasons,
            # Tasks flown again after a failed or lost attempt, and tasks that failed twice.
            "retried": [f"seed {r.get('seed')}: " + "; ".join(r["retried"]) for r in rs if r.get("retried")],
            "task_failures": sum(1 for r in rs if r.get("task_failed")),
            # Lock-step flights that lost determinism (a cycle took > 0.5 s of wall time).
            "lockstep_disturbed": sum(1 for r in rs if r.get("lockstep_republished")),
        }
    return {"scenarios": rows}


def markdown(summary) -> str:
    def f(s, key="mean", fmt="{:.2f}"):
        return fmt.format(s[key]) if s else "-"
    lines = ["| scenario | runs | success | 95 % CI (Wilson) | time to goal [s] | RMSE | min clearance [m] | mean speed [m/s] | compute p99 [ms] (worst flight) | failures |",
             "|---|---:|---:|---|---:|---:|---:|---:|---:|---|"]
    for scen, r in summary["scenarios"].items():
        lo, hi = r["wilson95"]
        fails = "; ".join(f"{k} x{v}" for k, v in r["failures"].items()) or "-"
        lines.append(f"| {scen} | {r['runs']} | {r['successes']}/{r['runs']} ({100 * r['success_rate']:.0f} %) | "
                     f"{100 * lo:.0f}-{100 * hi:.0f} % | {f(r['time_to_goal'])} | {f(r['tracking_rmse'], fmt='{:.3f}')} | "
                     f"{f(r['min_clearance'], 'min')} | {f(r['mean_speed'])} | {f(r['compute_ms_p99'], 'max')} | {fails} |")
    notes = []
    for scen, r in summary["scenarios"].items():
        for line in r.get("retried", []):
            notes.append(f"- {scen} {line}")
        if r.get("lockstep_disturbed"):
            notes.append(f"- {scen}: {r['lockstep_disturbed']} lock-step flight(s) waited > 0.5 s for a command "
                         "(the simulator republished the state): not reproducible")
        if r.get("task_failures"):
            notes.append(f"- {scen}: {r['task_failures']} flight(s) whose task failed twice (counted as failures)")
    if notes:
        lines += ["", "Notes (retries, task failures, disturbed lock-step flights):"] + notes
    return "\n".join(lines) + "\n"


# What a lock-step flight must reproduce whatever the engine or the machine's load: the
# outcome and the figures computed from the simulator's truth (not timings, not attempts).
OUTCOME_KEYS = ("scenario", "seed", "success", "reason", "sim_outcome", "harness_outcome", "time_to_goal", "sim_time",
                "min_clearance", "min_separation", "collisions", "tracking_rmse", "mean_speed", "laps")
SUMMARY_KEYS = ("runs", "successes", "success_rate", "wilson95", "time_to_goal", "tracking_rmse", "min_clearance",
                "mean_speed", "failures")


def _truth_path(folder: Path) -> list[str] | None:
    p = Path(folder) / "truth.jsonl"
    if not p.is_file():
        return None
    # The wall-clock answer time is the only field that depends on the machine.
    return [ln.split(',"lat_ms"')[0] for ln in p.read_text().splitlines()]


def compare_campaigns(a: Path, b: Path, truth: bool = True) -> list[str]:
    """Differences between two campaign folders in what lock-step must reproduce: each
    run's outcome fields, the summary's rows less the timing columns, and (truth) each
    flight's path in truth.jsonl. [] when they agree."""
    da, db = load_campaign(a), load_campaign(b)
    diffs = []
    ra, rb = da.by_key(), db.by_key()
    if set(ra) != set(rb):
        diffs.append(f"runs differ: only in {a}: {sorted(set(ra) - set(rb))}; only in {b}: {sorted(set(rb) - set(ra))}")
    for k in sorted(set(ra) & set(rb), key=str):
        mine = []
        for key in OUTCOME_KEYS:
            if ra[k].get(key) != rb[k].get(key):
                mine.append(f"{k[0]} seed {k[1]}: {key} {ra[k].get(key)!r} != {rb[k].get(key)!r}")
        if truth:
            ta = _truth_path(da.flight_folder(*k))
            tb = _truth_path(db.flight_folder(*k))
            if ta != tb:
                mine.append(f"{k[0]} seed {k[1]}: truth.jsonl paths differ" +
                            ("" if ta is not None and tb is not None else " (missing)"))
        if mine:
            why = [f"{x} ({r['lockstep_republished']} states republished)" for x, r in (("A", ra[k]), ("B", rb[k]))
                   if r.get("lockstep_republished")]
            if why:
                mine = [m + f" [lock-step disturbed in {', '.join(why)}]" for m in mine]
        diffs += mine
    sa, sb = da.summary["scenarios"], db.summary["scenarios"]
    for scen in sorted(set(sa) | set(sb)):
        for key in SUMMARY_KEYS:
            va, vb = (s.get(scen, {}).get(key) for s in (sa, sb))
            if va != vb:
                diffs.append(f"summary {scen}: {key} {va!r} != {vb!r}")
    return diffs
