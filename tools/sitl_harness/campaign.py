"""Campaigns: N seeds x scenarios, flown as separate `sitl run` processes, several at a
time (lock-step flights are independent: each has its own network namespace). Real-time
flights compete for the CPU and run one at a time, unless realtime_jobs > 1 asks for that
many at once, each pinned (taskset) to its own share of the cores."""
from __future__ import annotations

import json
import math
import os
import queue
import signal
import subprocess
import sys
import threading
import time
from concurrent.futures import ThreadPoolExecutor, as_completed
from pathlib import Path

import numpy as np

from . import paths


def wilson(k: int, n: int, z: float = 1.96):
    """Wilson score interval of a success rate (95 % by default)."""
    if n == 0:
        return (0.0, 1.0)
    p = k / n
    d = 1 + z * z / n
    c = (p + z * z / (2 * n)) / d
    h = z * math.sqrt(p * (1 - p) / n + z * z / (4 * n * n)) / d
    return (max(0.0, c - h), min(1.0, c + h))


class Progress:
    def __init__(self, total: int):
        self.total, self.done, self.ok, self.t0 = total, 0, 0, time.monotonic()
        self.lock = threading.Lock()
        self.tty = sys.stderr.isatty()

    def update(self, success: bool, label: str):
        with self.lock:
            self.done += 1
            self.ok += int(success)
            w = 30
            fill = int(w * self.done / max(1, self.total))
            el = time.monotonic() - self.t0
            eta = el / self.done * (self.total - self.done)
            line = (f"[{'#' * fill}{'.' * (w - fill)}] {self.done}/{self.total} ok {self.ok} "
                    f"fail {self.done - self.ok}  {el:.0f}s elapsed, ~{eta:.0f}s left  {label}")
            sys.stderr.write(("\r" + line.ljust(120)) if self.tty else line + "\n")
            if self.tty and self.done == self.total:
                sys.stderr.write("\n")
            sys.stderr.flush()


def core_sets(n: int, cpus=None) -> list[list[int]]:
    """n disjoint, equal shares of the CPUs this process may use (the rest left over)."""
    cpus = sorted(cpus if cpus is not None else os.sched_getaffinity(0))
    per = len(cpus) // n
    if per < 1:
        raise ValueError(f"{n} pinned real-time flights need at least {n} CPUs; {len(cpus)} available")
    return [cpus[i * per:(i + 1) * per] for i in range(n)]


def run_campaign(scenarios, seeds, out: Path, jobs: int = 2, backend: str = "cpu", first_seed: int = 1,
                 controller: str = "mppid", realtime: bool = False, sets=(), realtime_jobs: int = 1) -> dict:
    out = Path(out).resolve()
    out.mkdir(parents=True, exist_ok=True)
    runs = [(s, first_seed + k) for s in scenarios for k in range(seeds)]
    pins: queue.Queue | None = None
    if realtime:
        # Real-time flights compete for the CPU: one at a time, or realtime_jobs at once,
        # each on its own cores.
        jobs = max(1, realtime_jobs)
        if jobs > 1:
            pins = queue.Queue()
            for cs in core_sets(jobs):
                pins.put(cs)
    prog = Progress(len(runs))
    children: set[subprocess.Popen] = set()
    lock = threading.Lock()
    stopping = threading.Event()

    def one(scen, seed):
        d = out / scen / f"seed_{seed:04d}"
        cmd = [sys.executable, "-m", "sitl_harness", "run", "--scenario", scen, "--seed", str(seed), "--out", str(d),
               "--backend", backend, "--controller", controller, "--quiet"] + (["--realtime"] if realtime else [])
        for kv in sets:
            cmd += ["--set", kv]
        env = dict(os.environ, PYTHONPATH=str(paths.ROOT / "tools"))
        if stopping.is_set():
            return scen, seed, None
        d.mkdir(parents=True, exist_ok=True)
        cores = pins.get() if pins is not None else None
        try:
            if cores is not None:
                cmd = ["taskset", "-c", ",".join(map(str, cores))] + cmd
            with open(d / "harness.stderr", "wb") as err:
                p = subprocess.Popen(cmd, env=env, cwd=paths.ROOT, start_new_session=True, stdout=subprocess.DEVNULL,
                                     stderr=err)
            with lock:
                children.add(p)
            p.wait()
            with lock:
                children.discard(p)
        finally:
            if cores is not None:
                pins.put(cores)
        try:
            score = json.loads((d / "score.json").read_text())
        except (OSError, json.JSONDecodeError):
            score = {"scenario": scen, "seed": seed, "success": False, "reason": f"no score (rc={p.returncode})"}
        prog.update(bool(score.get("success")), f"{scen}#{seed}")
        return scen, seed, score

    results = []
    ex = ThreadPoolExecutor(max_workers=max(1, jobs))
    try:
        futs = [ex.submit(one, s, k) for s, k in runs]
        for f in as_completed(futs):
            scen, seed, score = f.result()
            if score is not None:
                results.append(score)
    except KeyboardInterrupt:
        # Not `with ThreadPoolExecutor`: its exit would wait for every running flight.
        stopping.set()
        ex.shutdown(wait=False, cancel_futures=True)
        with lock:
            running = list(children)
        for p in running:
            try:
                p.send_signal(signal.SIGTERM)  # each run cleans up its own flight
            except ProcessLookupError:
                pass
        for p in running:
            try:
                p.wait(timeout=20)
            except subprocess.TimeoutExpired:
                os.killpg(p.pid, signal.SIGKILL)
        raise
    ex.shutdown(wait=True)
    summary = summarize(results)
    summary["command"] = " ".join(sys.argv)
    summary["jobs"] = jobs
    summary["realtime_pinned"] = pins is not None
    summary["sets"] = list(sets)
    (out / "summary.json").write_text(json.dumps({"summary": summary, "runs": sorted(results, key=lambda r: (r.get("scenario", ""), r.get("seed", 0)))}, indent=2))
    (out / "summary.md").write_text(markdown(summary))
    try:
        sys.path.insert(0, str(paths.ROOT / "tools" / "plots"))
        from sitl_campaign import plot_campaign
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
            "min_clearance": _stat([r.get("min_clearance") for r in rs]),
            "mean_speed": _stat([r.get("mean_speed") for r in ok]),
            "compute_ms_p99": _stat([r.get("compute_ms_p99") for r in rs]),
            "deadline_misses": _stat([r.get("deadline_misses") for r in rs]),
            "failures": reasons,
        }
    return {"scenarios": rows}


def markdown(summary) -> str:
    def f(s, key="mean", fmt="{:.2f}"):
        return fmt.format(s[key]) if s else "-"
    lines = ["| scenario | runs | success | 95 % CI (Wilson) | time to goal [s] | RMSE | min clearance [m] | mean speed [m/s] | compute p99 [ms] | failures |",
             "|---|---:|---:|---|---:|---:|---:|---:|---:|---|"]
    for scen, r in summary["scenarios"].items():
        lo, hi = r["wilson95"]
        fails = "; ".join(f"{k} x{v}" for k, v in r["failures"].items()) or "-"
        lines.append(f"| {scen} | {r['runs']} | {r['successes']}/{r['runs']} ({100 * r['success_rate']:.0f} %) | "
                     f"{100 * lo:.0f}-{100 * hi:.0f} % | {f(r['time_to_goal'])} | {f(r['tracking_rmse'], fmt='{:.3f}')} | "
                     f"{f(r['min_clearance'], 'min')} | {f(r['mean_speed'])} | {f(r['compute_ms_p99'], 'max')} | {fails} |")
    return "\n".join(lines) + "\n"
