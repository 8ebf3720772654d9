"""Where a campaign's flights run: `local` (separate `sitl run` processes on this machine,
`jobs` at a time) or `ray` (one Ray task per flight, on a local Ray cluster or an existing
one). Both run the very same `sitl run` command per flight, so a flight's result folder
and score do not depend on the engine; run_flights() does the rest the same way for both:
the order, the retries and the progress bar.

A flight whose task failed (the harness process died or was killed, no score.json, a
harness error, a Ray worker or node lost) is flown once more; if that fails too, the run
is reported as a failure with both reasons. Every run's score says how many attempts it
took (`attempts`) and why earlier ones failed (`retried`); nothing is dropped.
"""
from __future__ import annotations

import json
import os
import queue
import shutil
import signal
import subprocess
import sys
import threading
import time
from collections import deque
from concurrent.futures import FIRST_COMPLETED, ThreadPoolExecutor
from concurrent.futures import wait as futures_wait
from dataclasses import dataclass, field
from pathlib import Path

from . import paths, turns

MAX_ATTEMPTS = 2   # a failed or lost task is flown once more
BASE_LCM_PORT = 7700


@dataclass
class FlightJob:
    index: int                      # position in the campaign (order of results, LCM port)
    scenario: str                   # a scenario name or a YAML file
    label: str                      # the scenario's name: result folder and summary key
    seed: int
    out: Path
    backend: str = "cpu"
    controller: str = "mppid"
    realtime: bool = False
    ideal: bool = False              # lock-step without the controller's latency charged
    latency: float | None = None     # lock-step: a fixed latency charged [s]
    sets: list[str] = field(default_factory=list)
    plots: bool = True
    timeout: float = 0.0
    autopilot: str = "sim"
    ardupilot_bin: str | None = None
    px4_bin: str | None = None

    @property
    def lcm_port(self) -> int:
        return BASE_LCM_PORT + self.index % 50000

    def run_args(self) -> list[str]:
        """Arguments of `sitl run` for this flight (without the Python and module)."""
        a = ["--scenario", self.scenario, "--seed", str(self.seed), "--out", str(self.out), "--backend", self.backend,
             "--controller", self.controller, "--lcm-port", str(self.lcm_port), "--quiet"]
        if self.realtime:
            a.append("--realtime")
        elif self.ideal:
            a.append("--ideal")
        elif self.latency is not None:
            a += ["--latency", repr(float(self.latency))]
        if not self.plots:
            a.append("--no-plots")
        if self.autopilot != "sim":
            a += ["--autopilot", self.autopilot] + (["--ardupilot-bin", self.ardupilot_bin] if self.ardupilot_bin else [])
            a += ["--px4-bin", self.px4_bin] if self.px4_bin else []
        if self.timeout:
            a += ["--timeout", str(self.timeout)]
        for kv in self.sets:
            a += ["--set", kv]
        return a


def task_failure(outcome: dict) -> str | None:
    """Why a flight's task failed (None: it flew, whatever the flight's own outcome)."""
    if outcome.get("lost"):
        return "lost: " + outcome["lost"]
    score, rc = outcome.get("score"), outcome.get("rc")
    if score is None:
        return f"no score.json (sitl run exit code {rc})"
    if score.get("harness_outcome") in ("error", "logger_died"):
        return f"harness: {score.get('reason')}"
    if rc not in (0, 1):
        return f"sitl run exit code {rc}"
    return None


class Progress:
    """One line on stderr: flights done, successes, retries, elapsed and time left."""

    def __init__(self, total: int, stream=None):
        self.total, self.done, self.ok, self.retries, self.t0 = total, 0, 0, 0, time.monotonic()
        self.lock = threading.Lock()
        self.stream = stream or sys.stderr
        self.tty = self.stream.isatty()

    def _line(self, label):
        w = 30
        fill = int(w * self.done / max(1, self.total))
        el = time.monotonic() - self.t0
        eta = el / self.done * (self.total - self.done) if self.done else float("nan")
        left = f"~{eta:.0f}s left" if self.done else "time left: after the first flight"
        line = (f"[{'#' * fill}{'.' * (w - fill)}] {self.done}/{self.total} ok {self.ok} "
                f"fail {self.done - self.ok}" + (f" retried {self.retries}" if self.retries else "") +
                f"  {el:.0f}s elapsed, {left}  {label}")
        self.stream.write(("\r" + line.ljust(120)) if self.tty else line + "\n")
        if self.tty and self.done == self.total:
            self.stream.write("\n")
        self.stream.flush()

    def update(self, success: bool, label: str):
        with self.lock:
            self.done += 1
            self.ok += int(success)
            self._line(label)

    def retry(self, label: str, why: str):
        with self.lock:
            self.retries += 1
            if self.tty:
                self.stream.write("\n")
            self.stream.write(f"sitl: {label} failed ({why}); flying it again\n")
            self._line(label)


# ---- local ---------------------------------------------------------------------------------
class LocalEngine:
    name = "local"

    def __init__(self, jobs: int = 2, pin: bool = False):
        self.capacity = max(1, int(jobs))
        self.pool = ThreadPoolExecutor(max_workers=self.capacity)
        self.tasks: dict = {}  # future -> its task: {"cancel": bool, "proc": Popen | None}
        self.lock = threading.Lock()
        # Pinned: each flight runs on its own share of the CPUs (taskset), so real-time
        # flights side by side (on a many-core machine) do not take each other's cores.
        self.pins: queue.Queue | None = None
        if pin and self.capacity > 1:
            self.pins = queue.Queue()
            for cs in core_sets(self.capacity):
                self.pins.put(cs)

    def describe(self) -> dict:
        return {"engine": "local", "jobs": self.capacity, "pinned": self.pins is not None}

    def _run(self, job: FlightJob, task: dict) -> dict:
        out = Path(job.out)
        out.mkdir(parents=True, exist_ok=True)
        for stale in ("score.json", "pids.json", "harness.json"):
            (out / stale).unlink(missing_ok=True)
        cmd = [sys.executable, "-m", "sitl_harness", "run", *job.run_args(), "--parent-pid", str(os.getpid())]
        cores = self.pins.get() if self.pins is not None else None
        try:
            if cores is not None:
                # The daemon's loop thread goes on the share's last core, its workers fill it.
                cmd = (["taskset", "-c", ",".join(map(str, cores))] + cmd +
                       ["--set", f"daemon.realtime.cpu={cores[-1]}", "--set", f"mppi.threads={len(cores)}"])
            env = dict(os.environ)
            if cores is not None:
                env.pop(turns.ENV, None)  # cores of its own: it need not take turns (turns.py)
            with self.lock:
                if task["cancel"]:
                    return {"cancelled": True}
                with open(out / "harness.stderr", "wb") as err:
                    task["proc"] = subprocess.Popen(cmd, cwd=paths.ROOT, start_new_session=True, env=env,
                                                    stdin=subprocess.DEVNULL, stdout=subprocess.DEVNULL, stderr=err)
            rc = task["proc"].wait()
        finally:
            if cores is not None:
                self.pins.put(cores)
        if task["cancel"]:
            return {"cancelled": True}
        try:
            score = json.loads((out / "score.json").read_text())
        except (OSError, ValueError):
            score = None
        return {"rc": rc, "score": score}

    def submit(self, job: FlightJob, attempt: int):
        task = {"cancel": False, "proc": None}
        f = self.pool.submit(self._run, job, task)
        with self.lock:
            self.tasks[f] = task
        return f

    def wait_any(self, handles, timeout=None):
        done, _ = futures_wait(list(handles), timeout=timeout, return_when=FIRST_COMPLETED)
        out = []
        for f in done:
            with self.lock:
                self.tasks.pop(f, None)
            try:
                out.append((f, f.result()))
            except Exception as e:  # noqa: BLE001 - a thread that failed is a lost task
                out.append((f, {"lost": repr(e)}))
        return out

    def cancel(self, jobs_and_handles):
        """Stops these flights (SIGTERM: each cleans up its own flight), waits for them."""
        running = []
        with self.lock:
            for _, f in jobs_and_handles:
                task = self.tasks.pop(f, None)
                f.cancel()  # not started yet: never starts
                if task is not None:
                    task["cancel"] = True
                    if task["proc"] is not None:
                        running.append(task["proc"])
        for p in running:
            try:
                p.send_signal(signal.SIGTERM)
            except ProcessLookupError:
                pass
        for p in running:
            try:
                p.wait(timeout=30)
            except subprocess.TimeoutExpired:
                os.killpg(p.pid, signal.SIGKILL)
                p.wait()

    def close(self):
        self.pool.shutdown(wait=True, cancel_futures=True)


# ---- ray -----------------------------------------------------------------------------------
class RayEngine:
    """Flights as Ray tasks. No address: a local Ray cluster with `jobs` CPUs, stopped at
    close(). An address ("auto", "HOST:6379", "ray://HOST:10001"): that cluster, which every
    node must see the repository on at the same path (built), and the result folder's path
    writable; a flight flown on another node sends its result folder back."""
    name = "ray"

    def __init__(self, address: str | None = None, jobs: int | None = None, cpus_per_flight: float = 1.0):
        os.environ.setdefault("RAY_USAGE_STATS_ENABLED", "0")  # no usage reports from the machine
        try:
            import ray
        except ImportError as e:
            raise RuntimeError("--engine ray needs the `ray` package (requirements.txt; tools/setup.sh installs it)") from e
        from . import ray_task

        self.ray = ray
        self.address = address
        self.started = False
        if not ray.is_initialized():
            try:
                if address:
                    ray.init(address=address, log_to_driver=False, logging_level="WARNING")
                else:
                    ray.init(num_cpus=max(1, int(jobs or 2)), include_dashboard=False, log_to_driver=False,
                             logging_level="WARNING")
            except Exception as e:  # noqa: BLE001 - Ray raises many kinds; the message says which
                where = f"join the Ray cluster at {address}" if address else "start a local Ray cluster"
                raise RuntimeError(f"cannot {where}: {type(e).__name__}: {e}") from e
            self.started = True
        # Shipped by value: workers need only the standard library (and the repository).
        ray.cloudpickle.register_pickle_by_value(ray_task)
        self.task = ray.remote(num_cpus=cpus_per_flight, max_retries=0)(ray_task.run_flight_task)
        cpus = float(ray.cluster_resources().get("CPU", 1.0))
        self.capacity = max(1, int(jobs) if jobs else int(cpus // max(cpus_per_flight, 1e-9)))
        self.cpus_per_flight = cpus_per_flight
        self.driver_node = ray.get_runtime_context().get_node_id()

    def describe(self) -> dict:
        return {"engine": "ray", "address": self.address or "local cluster", "jobs": self.capacity,
                "cpus_per_flight": self.cpus_per_flight}

    def submit(self, job: FlightJob, attempt: int):
        # Ray starts its workers at niceness 15: the flight goes back to the campaign's own.
        args = job.run_args() + ["--niceness", str(os.getpriority(os.PRIO_PROCESS, 0))]
        payload = {"root": str(paths.ROOT), "out": str(job.out), "args": args, "attempt": attempt,
                   "driver_node_id": self.driver_node}
        p = Path(job.scenario)
        if p.suffix in (".yaml", ".yml") and p.is_file():
            payload["scenario_file"] = job.scenario
            payload["scenario_text"] = p.read_text()
        return self.task.remote(payload)

    def wait_any(self, handles, timeout=None):
        ready, _ = self.ray.wait(list(handles), num_returns=1, timeout=timeout)
        out = []
        for ref in ready:
            try:
                res = self.ray.get(ref)
            except self.ray.exceptions.TaskCancelledError:
                res = {"cancelled": True}
            except self.ray.exceptions.RayError as e:
                res = {"lost": f"{type(e).__name__}: {str(e).splitlines()[0] if str(e) else ''}"}
            out.append((ref, res))
        return out

    def fetch_files(self, job: FlightJob, res: dict):
        if res.get("files"):
            import io
            import tarfile

            out = Path(job.out)
            if out.exists():
                shutil.rmtree(out)
            out.mkdir(parents=True)
            with tarfile.open(fileobj=io.BytesIO(res["files"]), mode="r:gz") as tar:
                tar.extractall(out, filter="data")
            res["files"] = None

    def cancel(self, jobs_and_handles):
        refs = [h for _, h in jobs_and_handles]
        for r in refs:
            try:
                self.ray.cancel(r)  # KeyboardInterrupt in the task: it stops its flight
            except Exception:  # noqa: BLE001 - already finished
                pass
        if refs:
            self.ray.wait(refs, num_returns=len(refs), timeout=40)

    def close(self):
        if self.started:
            self.ray.shutdown()


def core_sets(n: int, cpus=None) -> list[list[int]]:
    """n disjoint, equal shares of the CPUs this process may use (the rest left over)."""
    cpus = sorted(cpus if cpus is not None else os.sched_getaffinity(0))
    per = len(cpus) // n
    if per < 1:
        raise ValueError(f"{n} pinned real-time flights need at least {n} CPUs; {len(cpus)} available")
    return [cpus[i * per:(i + 1) * per] for i in range(n)]


def make_engine(name: str, jobs: int | None = None, address: str | None = None, cpus_per_flight: float = 1.0,
                pin: bool = False):
    if name == "local":
        if address:
            raise ValueError("--address is for --engine ray")
        return LocalEngine(jobs or 2, pin=pin)
    if pin:
        raise ValueError("--realtime-jobs (pinned flights) is for --engine local")
    if name == "ray":
        return RayEngine(address=address, jobs=jobs, cpus_per_flight=cpus_per_flight)
    raise ValueError(f"unknown engine {name}")


# ---- the flights ---------------------------------------------------------------------------
def _final_score(job, res: dict, why: str | None, attempts: int, notes: list[str]) -> dict:
    """A job's score after its last attempt: the flight's, or a failure naming why the task
    failed (`why`); with the attempts, and the retries' notes (in the folder's score.json too)."""
    score = res.get("score")
    if why:
        score = {"scenario": job.label, "seed": job.seed, "success": False,
                 "reason": f"task failed {attempts} times: {why}",
                 **({"sim_outcome": score.get("sim_outcome")} if score else {})}
        score["task_failed"] = True
    score["attempts"] = attempts
    if notes:
        score["retried"] = list(notes)
        # The folder's score.json says it too.
        try:
            (Path(job.out) / "score.json").write_text(json.dumps(score, indent=2))
        except OSError:
            pass
    return score


def run_flights(engine, jobs, progress: Progress | None = None, on_result=None, poll: float = 0.5) -> list[dict]:
    """Flies `jobs` on `engine`; returns one score per job, in job order (a job stopped by
    on_result returning True, and the ones not started then, are left out). Retries a
    failed or lost task once; on KeyboardInterrupt stops the running flights and re-raises."""
    pending = deque(jobs)
    attempts = {j.index: 0 for j in jobs}
    notes: dict[int, list[str]] = {j.index: [] for j in jobs}
    running: dict = {}  # handle -> job
    results: dict[int, dict] = {}
    stop = False
    try:
        while (pending and not stop) or running:
            while pending and not stop and len(running) < engine.capacity:
                job = pending.popleft()
                attempts[job.index] += 1
                running[engine.submit(job, attempts[job.index])] = job
            for h, res in engine.wait_any(running, timeout=poll):
                job = running.pop(h)
                if res.get("cancelled"):
                    continue
                if hasattr(engine, "fetch_files"):
                    engine.fetch_files(job, res)
                why = task_failure(res)
                if why and attempts[job.index] < MAX_ATTEMPTS:
                    notes[job.index].append(f"attempt {attempts[job.index]}: {why}")
                    if progress:
                        progress.retry(f"{job.label}#{job.seed}", why)
                    pending.appendleft(job)
                    continue
                if why:
                    notes[job.index].append(f"attempt {attempts[job.index]}: {why}")
                score = results[job.index] = _final_score(job, res, why, attempts[job.index], notes[job.index])
                if progress:
                    progress.update(bool(score.get("success")), f"{job.label}#{job.seed}")
                if on_result is not None and on_result(job, score) and not stop:
                    stop = True
                    pending.clear()
                    engine.cancel([(j, hh) for hh, j in running.items()])
                    running.clear()
    except BaseException:
        engine.cancel([(j, hh) for hh, j in running.items()])
        raise
    return [results[j.index] for j in jobs if j.index in results]
