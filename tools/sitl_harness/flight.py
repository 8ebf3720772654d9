"""One flight: simulator, controller and lcm-logger inside a private network namespace,
flown to the end, then stopped cleanly whatever happens.

Isolation: `unshare -n` makes a namespace holding only a loopback interface, with the
multicast range routed to it, and a tiny `sleep` holding it open; every process of the
flight joins it with `nsenter -n`, so parallel flights each have their own LCM bus and no
datagram can leave the machine. Every process of the flight is in one process group (the
holder's), so a single killpg reaches all of them: SIGTERM first, SIGKILL after a grace
period. Children also get PR_SET_PDEATHSIG, so even a SIGKILLed harness leaves no orphan.
"""
from __future__ import annotations

import ctypes
import json
import os
import signal
import subprocess
import sys
import threading
import time
from dataclasses import dataclass, field
from pathlib import Path

import yaml

from . import paths

LCM_URL = "udpm://239.255.76.67:7667?ttl=0"
# A lock-step flight bursts thousands of datagrams a second; the logger must not drop any
# while the CPU is busy (the kernel caps this at net.core.rmem_max).
LOGGER_RECV_BUF = 4 * 1024 * 1024
SIM_FIFO_PRIORITY = 90
LOGGER_FIFO_PRIORITY = 79
VIEW_READY_TIMEOUT_S = 60.0    # the view imports rerun and starts its servers (seconds under load)
VIEW_GRPC_OFFSET = 786         # 9090 -> 9876, rerun's default pair
VIEW_ROLLOUTS = ["daemon.rollouts.hz=5", "daemon.rollouts.top=16", "daemon.rollouts.random=16"]
INJECT_READY_TIMEOUT_S = 30.0  # the injector imports lcm and subscribes (seconds under load)
_NETNS_SETUP = "ip link set lo up && ip route add 224.0.0.0/4 dev lo && echo ready && exec sleep 86400"


class FlightError(RuntimeError):
    pass


def _pdeathsig():
    # Dies with the harness (SIGKILL included). Only safe when the spawning thread lives
    # as long as the flight: flights are spawned from their process's main thread.
    try:
        libc = ctypes.CDLL("libc.so.6", use_errno=True)
        libc.prctl(1, signal.SIGTERM)  # PR_SET_PDEATHSIG
    except OSError:
        pass


@dataclass
class FlightSpec:
    scenario: str
    seed: int = 1
    out: Path = Path("results/run")
    backend: str = "cpu"
    realtime: bool = False
    ideal: bool = False              # lock-step without charging the controller's latency
    latency: float | None = None     # lock-step: charge this fixed latency [s] (and tell mppid)
    controller: str = "mppid"        # mppid | ddp (mppid --controller ddp: the MPC-DDP baseline) | standin
    wall_timeout: float = 0.0        # 0: from the scenario's duration
    sets: list[str] = field(default_factory=list)  # extra --set key=value for mppid
    kill_controller_after: float = 0.0  # tests: SIGKILL the controller after this many seconds
    lcm_url: str = LCM_URL           # the flight's bus (inside its own network namespace)
    plots: bool = True               # path.png, traces.png, timing.png (tuning skips them)
    params: list[str] = field(default_factory=list)  # "T:KEY=VALUE": parameter updates in flight (inject.py)
    autopilot: str = "sim"           # sim: mppid-sim; ardupilot: ArduCopter SITL and the bridge (ardupilot.py)
    ardupilot_bin: str | None = None  # the SITL binary (else $MPPID_ARDUPILOT_BIN)
    view: bool = False               # the live 3D view (tools/view) of the flight, rollouts on; flight.rrd
    view_hold: float = 0.0           # ... kept serving this long after the flight [s]
    view_wait: float = 0.0           # ... up this long before the flight starts (open the page) [s]
    view_port: int = 9090            # ... its web viewer's port; its gRPC server's is this + VIEW_GRPC_OFFSET
    rrd: bool = False                # flight.rrd: the LCM log converted for rerun's viewer


class Flight:
    def __init__(self, spec: FlightSpec):
        self.spec = spec
        self.out = Path(spec.out).resolve()
        self.procs: dict[str, subprocess.Popen] = {}
        self.holder: subprocess.Popen | None = None
        self.events: list[str] = []
        self.logs = {}

    # ---- processes ---------------------------------------------------------------------
    def _start_namespace(self):
        if os.geteuid() != 0:
            # Unprivileged: a user namespace grants the capabilities to set up lo.
            cmd = ["unshare", "-r", "-n", "--", "sh", "-c", _NETNS_SETUP]
        else:
            cmd = ["unshare", "-n", "--", "sh", "-c", _NETNS_SETUP]
        main = threading.current_thread() is threading.main_thread()
        self.holder = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, process_group=0,
                                       preexec_fn=_pdeathsig if main else None)
        line = self.holder.stdout.readline().decode().strip()
        if line != "ready":
            try:  # its shell exits right after the failing command: say what it said
                self.holder.wait(timeout=2.0)
            except subprocess.TimeoutExpired:
                pass
            err = self.holder.stderr.read().decode() if self.holder.poll() is not None else ""
            raise FlightError(f"network namespace set-up failed: {line} {err}".strip())
        self.pgid = self.holder.pid

    def _spawn(self, name: str, cmd: list[str]):
        log = open(self.out / f"{name}.log", "wb")
        self.logs[name] = log
        ns = ["nsenter", "-t", str(self.holder.pid), "-n"]
        if os.geteuid() != 0:
            ns = ["nsenter", "-t", str(self.holder.pid), "-U", "-n", "--preserve-credentials"]
        main = threading.current_thread() is threading.main_thread()
        env = dict(os.environ)
        env["PYTHONPATH"] = os.pathsep.join(str(d) for d in (paths.ROOT / "tools", paths.lcm_python_dir()) if d)
        p = subprocess.Popen(ns + ["--"] + cmd, stdout=log, stderr=subprocess.STDOUT, stdin=subprocess.DEVNULL,
                             process_group=self.pgid, cwd=paths.ROOT, env=env,
                             preexec_fn=_pdeathsig if main else None)
        self.procs[name] = p
        return p

    def _start_view(self):
        """tools/view live in this (the host's) network namespace, so the browser reaches its
        servers, reading the flight's LCM bus from inside the flight's namespace (--netns-pid).
        Its own process group: the flight's killpg must not end it before view_hold."""
        spec = self.spec
        # The logger's receive buffer: a lock-step flight bursts faster than a normal-policy
        # reader drains. What the view still drops shows live only: flight.rrd is converted
        # from the complete log after the flight (fly()).
        cmd = [sys.executable, "-m", "mppid_view", "live", "--lcm-url",
               f"{spec.lcm_url}&recv_buf_size={LOGGER_RECV_BUF}", "--netns-pid", str(self.holder.pid),
               "--web-port", str(spec.view_port), "--grpc-port", str(spec.view_port + VIEW_GRPC_OFFSET)]
        log = open(self.out / "view.log", "wb")
        self.logs["view"] = log
        env = dict(os.environ)
        env["PYTHONPATH"] = os.pathsep.join(str(d) for d in (paths.ROOT / "tools", paths.lcm_python_dir()) if d)
        main = threading.current_thread() is threading.main_thread()
        self.view = subprocess.Popen(cmd, stdout=log, stderr=subprocess.STDOUT, stdin=subprocess.DEVNULL, cwd=paths.ROOT,
                                     env=env, process_group=0, preexec_fn=_pdeathsig if main else None)
        deadline = time.monotonic() + VIEW_READY_TIMEOUT_S
        path = self.out / "view.log"
        while "view: http" not in path.read_text(errors="replace"):
            if self.view.poll() is not None:
                raise FlightError(f"view exited at start (rc={self.view.returncode}); see view.log")
            if time.monotonic() > deadline:
                raise FlightError(f"view not serving after {VIEW_READY_TIMEOUT_S:g} s; see view.log")
            time.sleep(0.05)
        url = next(l for l in path.read_text(errors="replace").splitlines() if l.startswith("view: http"))
        print(url, flush=True)
        if spec.view_wait > 0:
            print(f"view: the flight starts in {spec.view_wait:g} s (time to open the page)", flush=True)
            time.sleep(spec.view_wait)

    def _stop_view(self):
        view = getattr(self, "view", None)
        if view is None or view.poll() is not None:
            return
        if self.spec.view_hold > 0:
            print(f"view: serving {self.spec.view_hold:g} s more (Ctrl-C to stop)", flush=True)
            try:
                view.wait(timeout=self.spec.view_hold)
            except (subprocess.TimeoutExpired, KeyboardInterrupt):
                pass
        try:
            view.send_signal(signal.SIGTERM)
            view.wait(timeout=10)
        except subprocess.TimeoutExpired:
            view.kill()
            view.wait(timeout=5)

    def _wait_ready(self, name: str, timeout: float):
        """Waits for `{"event": "ready"}` on a helper's log (it has subscribed), or fails."""
        deadline = time.monotonic() + timeout
        path = self.out / f"{name}.log"
        while '"event": "ready"' not in path.read_text(errors="replace"):
            if self.procs[name].poll() is not None:
                raise FlightError(f"{name} exited at start (rc={self.procs[name].returncode}); see {name}.log")
            if time.monotonic() > deadline:
                raise FlightError(f"{name} not subscribed after {timeout:g} s; see {name}.log")
            time.sleep(0.02)

    def _terminate(self, name: str, grace: float):
        p = self.procs.get(name)
        if p is None or p.poll() is not None:
            return
        try:
            p.send_signal(signal.SIGTERM)
            p.wait(timeout=grace)
        except subprocess.TimeoutExpired:
            p.kill()
            p.wait(timeout=5)
        except ProcessLookupError:
            pass

    def cleanup(self):
        """Stops everything: the controller and the simulator, then the logger (so it has
        recorded their last messages), then the holder; then SIGKILL to whatever is left of
        the process group. Safe to call twice. Further SIGINT/SIGTERM are ignored meanwhile,
        so a second Ctrl-C cannot cut the clean-up short."""
        main = threading.current_thread() is threading.main_thread()
        saved = {}
        if main:
            for sig in (signal.SIGINT, signal.SIGTERM):
                saved[sig] = signal.signal(sig, signal.SIG_IGN)
        try:
            self._cleanup()
        finally:
            for sig, h in saved.items():
                signal.signal(sig, h)
        self._stop_view()  # after: its hold ends on Ctrl-C / SIGTERM

    def _signal_group(self, sig, wait_s: float) -> bool:
        """sig to the flight's process group, then up to wait_s for it to be gone; True if gone
        (or never started: the namespace's set-up failed before the group existed)."""
        if getattr(self, "pgid", None) is None:
            return True
        try:
            os.killpg(self.pgid, sig)
        except ProcessLookupError:
            pass
        deadline = time.monotonic() + wait_s
        while time.monotonic() < deadline and _group_alive(self.pgid):
            time.sleep(0.05)
        return not _group_alive(self.pgid)

    def _cleanup(self):
        for name in [n for n in self.procs if n != "logger"]:
            self._terminate(name, 3.0)
        if "logger" in self.procs and self.procs["logger"].poll() is None:
            time.sleep(0.3)  # the logger drains what is still in its socket
        self._terminate("logger", 3.0)
        if self.holder is not None:
            if not self._signal_group(signal.SIGTERM, 2.0):
                self._signal_group(signal.SIGKILL, 5.0)
            for p in list(self.procs.values()) + [self.holder]:
                try:
                    p.wait(timeout=5)
                except subprocess.TimeoutExpired:
                    pass
        for f in self.logs.values():
            f.close()
        self.logs = {}

    # ---- the flight ----------------------------------------------------------------------
    def run(self) -> dict:
        spec = self.spec
        self.out.mkdir(parents=True, exist_ok=True)
        scen_path = paths.scenario_path(spec.scenario)
        scen = yaml.safe_load(scen_path.read_text())
        task = scen["task"]
        sim_bin = paths.find_binary("mppid-sim")
        if sim_bin is None:
            raise FlightError("mppid-sim not built (searched %s)" % ", ".join(map(str, paths.build_dirs())))
        duration = float(scen.get("timing", {}).get("duration", 30.0))
        wall_timeout = spec.wall_timeout or (duration * 4 + 60 if not spec.realtime else duration + 30)
        lockstep = not spec.realtime

        if spec.controller in ("mppid", "ddp"):
            mppid = paths.find_binary("mppid")
            if mppid is None:
                raise FlightError("mppid not built (searched %s)" % ", ".join(map(str, paths.build_dirs())))
            # The scenario names its controller config (config/tasks/<task>.yaml), optionally
            # another file (mppid.config) and overrides (mppid.set: ["mppi.lambda=10", ...]).
            mp = scen.get("mppid") or {}
            cfg = paths.ROOT / mp["config"] if mp.get("config") else paths.TASKS / f"{task}.yaml"
            if not cfg.is_file():
                raise FlightError(f"scenario {spec.scenario} names controller config {cfg}, which does not exist")
            ctrl_cmd = [str(mppid), "--config", str(cfg), "--lcm-url", spec.lcm_url]
            # As the systemd unit runs it (SCHED_FIFO, locked memory; it runs on with a
            # warning where the OS refuses), in lock-step too: there its measured latency is
            # what the simulator charges, and it must be the service's, not a busy machine's.
            if _fifo_allowed():
                ctrl_cmd.append("--realtime")
            if lockstep:
                ctrl_cmd.append("--lockstep")
                if spec.latency is not None:
                    # The controller is told the fixed latency charged: the run repeats exactly.
                    ms = f"{1e3 * spec.latency:g}"
                    ctrl_cmd += ["--set", f"daemon.latency.floor_ms={ms}", "--set", f"daemon.latency.ceiling_ms={ms}"]
            ctrl_cmd += ["--backend", spec.backend]
            if spec.controller == "ddp":
                ctrl_cmd += ["--controller", "ddp"]
            # The flight's seed also seeds the controller's sampling (a campaign over seeds
            # varies both the world and the noise); --set can still override it.
            ctrl_cmd += ["--set", f"mppi.seed={spec.seed}"]
            # The live view's rollout fan, unless the flight sets its own daemon.rollouts.
            view_sets = VIEW_ROLLOUTS if spec.view and not any("daemon.rollouts." in str(s) for s in spec.sets) else []
            for kv in list(mp.get("set", [])) + view_sets + list(spec.sets):
                ctrl_cmd += ["--set", str(kv)]
        else:
            ctrl_cmd = [sys.executable, "-m", "sitl_harness.standin", "--scenario", str(scen_path), "--lcm-url",
                        spec.lcm_url]
        sim_cmd = [str(sim_bin), "--scenario", str(scen_path), "--seed", str(spec.seed), "--lcm-url", spec.lcm_url,
                   "--out", str(self.out), "--lockstep" if lockstep else "--realtime"]
        if lockstep and spec.ideal:
            sim_cmd.append("--ideal")
        elif lockstep and spec.latency is not None:
            sim_cmd += ["--latency", f"{spec.latency:g}"]
        inject_cmd = [sys.executable, "-m", "sitl_harness.inject", "--lcm-url", spec.lcm_url]
        for u in spec.params:
            inject_cmd += ["--at", str(u)]
        logger_cmd = [str(_lcm_logger()), "-q", "-f", f"--lcm-url={spec.lcm_url}&recv_buf_size={LOGGER_RECV_BUF}",
                      str(self.out / "flight.lcmlog")]
        if _fifo_allowed():
            # The simulator stands in for the physical world: the controller's CPU load must
            # not slow its physics down, nor other load its clock and the latency it measures
            # (the daemon runs SCHED_FIFO 80, the simulator above).
            sim_cmd = ["chrt", "-f", str(SIM_FIFO_PRIORITY)] + sim_cmd
            # The logger too, just below the daemon: a lock-step flight runs many times faster
            # than real time and a logger starved meanwhile loses datagrams.
            logger_cmd = ["chrt", "-f", str(LOGGER_FIFO_PRIORITY)] + logger_cmd
            # The parameter injector as the logger: at the normal policy a lock-step flight
            # (SCHED_FIFO, both cores) would starve it of every state until the flight ends.
            inject_cmd = ["chrt", "-f", str(LOGGER_FIFO_PRIORITY)] + inject_cmd

        t0 = time.monotonic()
        outcome = None
        cfg = locals().get("cfg")
        try:
            self._start_namespace()
            if spec.view:
                self._start_view()
            self._spawn("logger", logger_cmd)
            self._spawn("controller", ctrl_cmd)
            time.sleep(0.5)  # let both subscribe before the first state
            for name in ("logger", "controller"):
                if self.procs[name].poll() is not None:
                    raise FlightError(f"{name} exited at start (rc={self.procs[name].returncode}); see {name}.log")
            if spec.params:
                # Parameter updates at set state times, their answers logged (inject.log).
                self._spawn("inject", inject_cmd)
                self._wait_ready("inject", INJECT_READY_TIMEOUT_S)
            self._spawn("sim", sim_cmd)
            if scen.get("mission"):
                # The operator's side: the mission tool gives mppid its references (the
                # scenario's own reference is `none`), as on a real vehicle.
                self._spawn("mission", [str(paths.ROOT / "drivers" / "mission" / "mppid-mission"), "fly",
                                        str(paths.ROOT / scen["mission"]), "--seed", str(spec.seed), "--out",
                                        str(self.out), "--lcm-url", spec.lcm_url])
            (self.out / "pids.json").write_text(json.dumps(
                {"pgid": self.pgid, "holder": self.holder.pid, **{k: p.pid for k, p in self.procs.items()}}))
            killed = False
            while True:
                time.sleep(0.05)
                now = time.monotonic() - t0
                if self.procs["sim"].poll() is not None:
                    break
                if spec.kill_controller_after and not killed and now > spec.kill_controller_after:
                    self.procs["controller"].kill()
                    killed = True
                    self.events.append(f"controller killed by the harness at {now:.2f} s (test)")
                if self.procs["controller"].poll() is not None:
                    outcome = "controller_died"
                    self.events.append(f"controller exited rc={self.procs['controller'].returncode} at {now:.2f} s")
                    break
                if self.procs["logger"].poll() is not None:
                    outcome = "logger_died"
                    break
                if now > wall_timeout:
                    outcome = "wall_timeout"
                    break
        except KeyboardInterrupt:
            outcome = "interrupted"
            self.events.append("interrupted (Ctrl-C / SIGTERM)")
            raise
        finally:
            self.cleanup()
            info = self._record(t0, outcome, {
                "commands": {"sim": sim_cmd, "controller": ctrl_cmd, "logger": logger_cmd,
                             **({"inject": inject_cmd} if spec.params else {})},
                "controller_config": str(cfg) if spec.controller in ("mppid", "ddp") else None,
                "spec": {"scenario": spec.scenario, "seed": spec.seed, "backend": spec.backend,
                         "realtime": spec.realtime, "ideal": spec.ideal, "latency": spec.latency,
                         "controller": spec.controller, "lcm_url": spec.lcm_url, "params": spec.params}})
        return info

    def _record(self, t0: float, outcome, extra: dict) -> dict:
        """harness.json: how the flight ended, its processes' exit codes and events, and `extra`."""
        info = {"harness_outcome": outcome, "wall_s": time.monotonic() - t0,
                "niceness": os.getpriority(os.PRIO_PROCESS, 0),
                "returncodes": {k: p.returncode for k, p in self.procs.items()}, "events": self.events, **extra}
        (self.out / "harness.json").write_text(json.dumps(info, indent=2, default=str))
        return info


def _fifo_allowed() -> bool:
    """Whether this process may start SCHED_FIFO children (root, or CAP_SYS_NICE), and is
    to: MPPID_NO_FIFO=1 keeps every process of the flight in the normal scheduler, for work
    beside a real-time measurement (a soak, a benchmark) that must not be preempted."""
    if os.environ.get("MPPID_NO_FIFO"):
        return False
    try:
        return subprocess.run(["chrt", "-f", "1", "true"], stdout=subprocess.DEVNULL,
                              stderr=subprocess.DEVNULL).returncode == 0
    except OSError:
        return False


def _lcm_logger() -> Path:
    """The lcm-logger binary itself: the venv's entry point is a Python wrapper that would
    run it as a grandchild (and leave it behind on SIGTERM)."""
    try:
        import lcm
        p = Path(lcm.LCM_BIN_DIR) / "lcm-logger"
        if p.is_file():
            return p
    except (ImportError, AttributeError):
        pass
    return paths.VENV_BIN / "lcm-logger"


def _group_alive(pgid: int) -> bool:
    try:
        os.killpg(pgid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True
    # Zombies count as alive for killpg; reap check through /proc.
    for d in os.listdir("/proc"):
        if not d.isdigit():
            continue
        try:
            with open(f"/proc/{d}/stat") as f:
                parts = f.read().rsplit(")", 1)[1].split()
            if int(parts[2]) == pgid and parts[0] != "Z":
                return True
        except (OSError, IndexError, ValueError):
            continue
    return False


def _flight_for(spec: FlightSpec):
    """The flight and its scorer: mppid-sim's (score.py, plots.py), or ArduCopter SITL's
    (ardupilot.py, ap_score.py, ap_plots.py). Raises FlightError (no SITL binary, say)."""
    if spec.autopilot == "ardupilot":
        from . import ap_plots, ap_score, ardupilot
        return ardupilot.ArduPilotFlight(spec, ardupilot.ardupilot_binary(spec.ardupilot_bin)), ap_score, ap_plots
    from . import plots, score
    return Flight(spec), score, plots


def fly(spec: FlightSpec) -> dict:
    """Runs one flight, scores it and plots it; returns the score (also in score.json)."""
    interrupt_on_stop_signals()
    out = Path(spec.out).resolve()
    out.mkdir(parents=True, exist_ok=True)
    try:
        flight, scorer, plotter = _flight_for(spec)
    except FlightError as e:
        result = {"success": False, "reason": str(e), "harness_outcome": "error"}
        (out / "score.json").write_text(json.dumps(result, indent=2))
        return result
    info = {}
    try:
        info = flight.run()
    except FlightError as e:
        info = {"harness_outcome": "error", "error": str(e)}
        (out / "harness.json").write_text(json.dumps(info, indent=2))
    if spec.rrd or spec.view:
        try:
            from mppid_view.convert import convert
            paths.add_lcm_types_to_path()
            convert(out / "flight.lcmlog", out / "flight.rrd")
        except Exception as e:  # the rrd must never turn a flight into a crash
            info.setdefault("events", []).append(f"flight.rrd failed: {e!r}")
    result = scorer.score_flight(out, spec, info)
    (out / "score.json").write_text(json.dumps(result, indent=2))
    if spec.plots:
        try:
            plotter.plot_flight(out)
        except Exception as e:  # plots must never turn a flight into a crash
            result.setdefault("warnings", []).append(f"plots failed: {e!r}")
            (out / "score.json").write_text(json.dumps(result, indent=2))
    return result


def _interrupt(*_):
    raise KeyboardInterrupt


def interrupt_on_stop_signals() -> None:
    """SIGINT and SIGTERM raise KeyboardInterrupt in the main thread: a flight (a campaign, a
    study) stops, cleans up and leaves. SIGINT needs this too: Python installs its Ctrl-C
    handler only where SIGINT was not ignored at start, and a background job of a
    non-interactive shell (`tools/test.sh &`, a CI step, `nohup`) starts with it ignored. A
    campaign so started ignored an explicit SIGINT and flew on to its last flight (the cause
    of test_campaign_ctrl_c's 40 s time-outs "under load": the suite ran as a background job)."""
    if threading.current_thread() is threading.main_thread():
        for sig in (signal.SIGINT, signal.SIGTERM):
            signal.signal(sig, _interrupt)


def lcm_url_for_port(port: int) -> str:
    """The flight bus on another UDP port (each campaign flight gets its own)."""
    if not 1024 <= int(port) <= 65535:
        raise ValueError(f"LCM port {port} outside 1024-65535")
    return f"udpm://239.255.76.67:{int(port)}?ttl=0"


def watch_parent(parent_pid: int, interval: float = 0.2) -> None:
    """Ends this process like a SIGTERM (the flight is cleaned up) once the process that
    started it is gone: a campaign worker (a Ray worker, say) that dies mid-flight leaves no
    simulator or daemon behind. Watches the parent process itself (its pid changes to a
    reaper's when it dies), not the thread that started us, which PR_SET_PDEATHSIG would."""
    if os.getppid() != parent_pid:
        os.kill(os.getpid(), signal.SIGTERM)
        return

    def loop():
        while True:
            time.sleep(interval)
            if os.getppid() != parent_pid:
                os.kill(os.getpid(), signal.SIGTERM)
                return

    threading.Thread(target=loop, name="parent-watch", daemon=True).start()
