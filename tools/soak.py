"""tools/soak: a long real-time flight of mppid and mppid-sim while a schedule injects faults.

    tools/soak [--minutes N] [--scenario soak_circle] [--every S] [--seed S] [--out DIR]
               [--set key=value ...] [--no-realtime]

It drives the existing binaries, as in service: mppid --realtime (SCHED_FIFO when the OS
allows it) and mppid-sim --realtime flying the scenario (config/scenarios/soak_circle.yaml:
the circle, again and again, with the simulator's stand-in for the autopilot's
offboard-loss failsafe) for N minutes, in a private network namespace (nothing leaves the machine). Between them the
soak relays the state stream (the simulator's MPPI_STATE to mppid's SOAK_STATE), so it can
disturb it, and it is mppid's supervisor, the stand-in of the systemd unit (Restart=on-failure,
RestartSec=1s). After a warm-up, every --every seconds the next fault of the schedule:

  dropout      no state reaches mppid for 0.1-2 s
  nan          one state with a NaN in it
  out_of_order a state 5 sequence numbers old, again
  duplicates   the latest state 20 times over
  cpu_hog      two busy processes (one per core) for 3 s
  sim_stop     SIGSTOP to the simulator for 0.1-2 s, then SIGCONT
  daemon_kill  SIGKILL to mppid; the supervisor restarts it 1 s later

Per fault it reports when mppid's commands showed it (a command that is not MODE_NORMAL, a
deadline miss, or the counter of the rejected input in controller_status_t), when they
recovered (the first MODE_NORMAL command after the fault), and the commands sent meanwhile
by mode; overall, every command checked (finite, inside the task's limits), mppid's
resident memory after its warm-up (sampled once a second from /proc), deadline misses, and
the simulator's outcome. DIR/soak.json holds it all; exit 1 when any check fails: a NaN or
out-of-limit command, RSS growth above 1 MB after warm-up, a fault not recovered within
5 s, a collision, or a process that died unasked.
"""
from __future__ import annotations

import argparse
import json
import math
import os
import random
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path

from mppi_mavlink.layout import QuadrotorRate as Q
from sitl_harness import paths
from sitl_harness.sandbox import Sandbox, deathsig_setter, enter_private_network

LCM_URL = "udpm://239.255.76.67:7667?ttl=0"
RESTART_SEC = 1.0           # drivers/systemd/mppid.service: RestartSec=1s
WARMUP_S = 20.0             # before the first fault, and mppid's memory baseline
RSS_WARMUP_S = 30.0         # an incarnation's RSS baseline is taken this long after its start
RSS_LIMIT_KB = 1024
RECOVER_LIMIT_S = 5.0
FAULTS = ["dropout", "nan", "out_of_order", "duplicates", "cpu_hog", "sim_stop", "daemon_kill"]
MODE = {0: "normal", 1: "hold_plan", 2: "failsafe"}


def mono() -> float:
    return time.monotonic()


def rss_kb(pid: int) -> int | None:
    try:
        for line in Path(f"/proc/{pid}/status").read_text().splitlines():
            if line.startswith("VmRSS:"):
                return int(line.split()[1])
    except OSError:
        return None
    return None


class Soak:
    def __init__(self, a):
        self.a = a
        self.out = Path(a.out).resolve()
        self.out.mkdir(parents=True, exist_ok=True)
        import lcm
        import mppi_lcm
        import yaml
        self.m = mppi_lcm
        self.scen_path = paths.scenario_path(a.scenario)
        scen = yaml.safe_load(self.scen_path.read_text())
        self.task = scen["task"]
        cfg = yaml.safe_load((paths.TASKS / f"{self.task}.yaml").read_text())
        self.u_min, self.u_max = cfg["mppi"]["u_min"], cfg["mppi"]["u_max"]
        self.mppid_bin, self.sim_bin = paths.find_binary("mppid"), paths.find_binary("mppid-sim")
        if self.mppid_bin is None or self.sim_bin is None:
            raise SystemExit("tools/soak: mppid and mppid-sim must be built (tools/setup.sh)")
        self.rng = random.Random(a.seed)
        self.lc = lcm.LCM(LCM_URL)
        self.lock = threading.Lock()
        self.stop = threading.Event()
        # Relay state.
        self.dropping = False
        self.history: list[bytes] = []      # raw states from the simulator, newest last
        self.relayed = 0
        # What mppid said.
        self.commands: list[tuple[float, int, int]] = []   # (t, seq, mode)
        self.bad_commands: list[dict] = []
        self.statuses: list[tuple[float, object]] = []
        # Processes: in the soak's own network namespace (enter_private_network), SIGKILLed
        # with it; the supervisor thread restarts mppid, so its children get that too.
        self.sandbox = Sandbox(self.out, deathsig=signal.SIGKILL, any_thread=True)
        self.procs = self.sandbox.procs
        self.incarnations: list[dict] = []   # mppid: start, pid, rss samples
        self.expected_exit = False
        self.proc_lock = threading.Lock()   # mppid's process: the fault and the supervisor
        self.unasked_exits: list[str] = []
        self.events: list[dict] = []
        self.t0 = mono()

    # ---- processes ------------------------------------------------------------------------
    def start_mppid(self):
        cmd = [self.mppid_bin, "--config", paths.TASKS / f"{self.task}.yaml", "--lcm-url", LCM_URL, "--backend",
               "cpu", "--set", "daemon.channels.state=SOAK_STATE", "--stats"]
        if self.a.realtime:
            cmd.append("--realtime")
        for kv in self.a.set:
            cmd += ["--set", kv]
        p = self.sandbox.spawn("mppid", cmd)
        self.incarnations.append({"start": mono() - self.t0, "pid": p.pid, "rss": []})
        return p

    def rt(self) -> bool:
        return self.a.realtime and os.geteuid() == 0

    def start_sim(self, seconds):
        # As the link's processes in service (drivers/mavlink: SCHED_FIFO 85, above mppid's
        # 80): the state source is short I/O work and must not be starved by the CPU hog or
        # by whatever else runs on the machine.
        prio = ["chrt", "-f", "85"] if self.rt() else []
        return self.sandbox.spawn("sim", prio + [self.sim_bin, "--scenario", self.scen_path, "--seed", self.a.seed, "--realtime",
                                  "--lcm-url", LCM_URL, "--out", self.out, "--duration", seconds, "--quiet"])

    # ---- LCM: relay and watch --------------------------------------------------------------
    def on_sim_state(self, ch, data):
        with self.lock:
            self.history.append(data)
            del self.history[:-16]
            drop = self.dropping
        if not drop:
            self.lc.publish("SOAK_STATE", data)
            self.relayed += 1

    def on_command(self, ch, data):
        t = mono() - self.t0
        c = self.m.command_t.decode(data)
        ok = c.n == len(self.u_min) == len(c.u) and all(
            math.isfinite(v) and lo <= v <= hi for v, lo, hi in zip(c.u, self.u_min, self.u_max))
        with self.lock:
            self.commands.append((t, c.seq, c.mode))
            if not ok:
                self.bad_commands.append({"t": round(t, 3), "seq": c.seq, "mode": c.mode, "u": list(c.u)})

    def on_status(self, ch, data):
        with self.lock:
            self.statuses.append((mono() - self.t0, self.m.controller_status_t.decode(data)))

    def lcm_loop(self):
        if self.rt():  # this thread only: the relay and the monitor, as the link's processes
            try:
                os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(85))
            except OSError:
                pass
        while not self.stop.is_set():
            self.lc.handle_timeout(20)

    def inject_state(self, mutate, copies=1):
        with self.lock:
            if not self.history:
                return 0
            raw = self.history[mutate[1]] if isinstance(mutate, tuple) else self.history[-1]
        s = self.m.vehicle_state_t.decode(raw)
        if mutate == "nan":
            s.seq += 1
            s.x = list(s.x)
            s.x[Q.PX] = float("nan")
        data = s.encode()
        for _ in range(copies):
            self.lc.publish("SOAK_STATE", data)
        return copies

    # ---- faults ----------------------------------------------------------------------------
    def fault(self, kind):
        t_start = mono() - self.t0
        ev = {"fault": kind, "t": round(t_start, 3)}
        if kind == "dropout":
            d = round(self.rng.uniform(0.1, 2.0), 2)
            with self.lock:
                self.dropping = True
            time.sleep(d)
            with self.lock:
                self.dropping = False
            ev["seconds"] = d
        elif kind == "nan":
            ev["injected"] = self.inject_state("nan")
        elif kind == "out_of_order":
            ev["injected"] = self.inject_state(("old", -6))
        elif kind == "duplicates":
            ev["injected"] = self.inject_state("latest", copies=20)
        elif kind == "cpu_hog":
            hogs = [subprocess.Popen([sys.executable, "-c", "while True: pass"],
                                     preexec_fn=deathsig_setter(signal.SIGKILL))
                    for _ in range(os.cpu_count() or 2)]
            time.sleep(3.0)
            for h in hogs:
                h.kill()
                h.wait()
            ev["seconds"], ev["processes"] = 3.0, len(hogs)
        elif kind == "sim_stop":
            d = round(self.rng.uniform(0.1, 2.0), 2)
            self.procs["sim"].send_signal(signal.SIGSTOP)
            time.sleep(d)
            self.procs["sim"].send_signal(signal.SIGCONT)
            ev["seconds"] = d
        elif kind == "daemon_kill":
            with self.proc_lock:
                self.expected_exit = True
                self.procs["mppid"].kill()
                self.procs["mppid"].wait()
            ev["detected_after_s"] = round(mono() - self.t0 - t_start, 4)  # the supervisor's wait() returned
            time.sleep(RESTART_SEC)
            with self.proc_lock:
                self.start_mppid()
                self.expected_exit = False
            ev["restarted_at"] = round(mono() - self.t0, 3)
        ev["end"] = round(mono() - self.t0, 3)
        self.events.append(ev)
        return ev

    # ---- the run ---------------------------------------------------------------------------
    def supervise(self):
        """Samples mppid's RSS once a second; notes any process that exits unasked."""
        while not self.stop.is_set():
            with self.proc_lock:
                p = self.procs.get("mppid")
                alive = p is not None and p.poll() is None
                unasked = p is not None and not alive and not self.expected_exit
            if alive:
                r = rss_kb(p.pid)
                if r is not None:
                    self.incarnations[-1]["rss"].append((round(mono() - self.t0, 1), r))
            elif unasked and not self.stop.is_set():
                self.unasked_exits.append(f"mppid exited rc={p.returncode} at {mono() - self.t0:.1f} s")
                time.sleep(RESTART_SEC)
                with self.proc_lock:
                    if self.procs.get("mppid") is p:  # nobody restarted it meanwhile
                        self.start_mppid()
            self.stop.wait(1.0)

    def run(self):
        seconds = self.a.minutes * 60.0
        self.lc.subscribe("MPPI_STATE", self.on_sim_state)
        self.lc.subscribe("MPPI_COMMAND", self.on_command)
        self.lc.subscribe("MPPI_STATUS", self.on_status)
        threading.Thread(target=self.lcm_loop, daemon=True).start()
        self.start_mppid()
        time.sleep(1.0)
        self.start_sim(seconds + 2.0)
        threading.Thread(target=self.supervise, daemon=True).start()
        schedule = list(FAULTS)
        self.rng.shuffle(schedule)
        next_fault, i = WARMUP_S, 0
        end = self.t0 + seconds
        try:
            while mono() < end:
                if self.procs["sim"].poll() is not None:
                    self.unasked_exits.append(f"mppid-sim exited rc={self.procs['sim'].returncode} at "
                                              f"{mono() - self.t0:.1f} s (see sim_summary.json)")
                    break
                if mono() - self.t0 >= next_fault and mono() + 8.0 < end:
                    ev = self.fault(schedule[i % len(schedule)])
                    print(f"[soak] {ev['t']:7.1f} s  {ev['fault']}", flush=True)
                    i += 1
                    next_fault = mono() - self.t0 + self.a.every
                time.sleep(0.05)
        finally:
            self.stop.set()
            for name in ("sim", "mppid"):  # the world first: it must not see mppid go
                self.sandbox.terminate(name, 5.0)
            self.sandbox.stop()
        return self.report(seconds)

    # ---- report ----------------------------------------------------------------------------
    def running_totals(self, field):
        """(t, total since the soak began) of one of controller_status_t's cumulative
        counters, summed over mppid's incarnations (a restart starts them from 0)."""
        out, base, last_cycles, last = [], 0, -1, 0
        for t, st in self.statuses:
            if st.cycles < last_cycles:  # a new incarnation
                base += last
            last_cycles, last = st.cycles, getattr(st, field)
            out.append((t, base + last))
        return out

    def measure(self, ev):
        t0, t1 = ev["t"], ev["end"]
        cmds = self.commands
        during = [c for c in cmds if t0 <= c[0] <= t1 + 0.2]
        by_mode = {MODE.get(m, str(m)): sum(1 for c in during if c[2] == m) for m in sorted({c[2] for c in during})}
        first_off = next((c[0] for c in cmds if c[0] >= t0 and c[2] != 0), None)
        misses = self.running_totals("misses")
        misses0 = max((v for t, v in misses if t < t0), default=0)
        miss_t = next((t for t, v in misses if t >= t0 and v > misses0), None)
        r = {"commands_meanwhile": by_mode}
        kind = ev["fault"]
        counter = {"nan": "rejected_nan", "out_of_order": "rejected_out_of_order",
                   "duplicates": "rejected_out_of_order"}.get(kind)
        if counter:
            totals = self.running_totals(counter)
            before = max((v for t, v in totals if t < t0), default=0)
            seen = next((t for t, v in totals if t >= t0 and v > before), None)
            r["detected_s"] = None if seen is None else round(seen - t0, 3)
            r["counted"] = seen is not None
            # The input is refused: mppid flies on (its commands stay, or are again, normal).
            r["non_normal_commands"] = sum(1 for c in during if c[2] != 0)
            normal_after = next((c[0] for c in cmds if c[0] >= t1 and c[2] == 0), None)
            r["recovered_s"] = None if normal_after is None else round(max(0.0, normal_after - t1), 3)
            r["ok"] = r["counted"] and r["recovered_s"] is not None and r["recovered_s"] <= RECOVER_LIMIT_S
            return r
        cands = [x for x in (first_off, miss_t) if x is not None and x <= t1 + 1.0]
        if kind == "daemon_kill":
            r["detected_s"] = ev["detected_after_s"]
        else:
            r["detected_s"] = round(min(cands) - t0, 3) if cands else None
        normal_after = next((c[0] for c in cmds if c[0] >= t1 and c[2] == 0), None)
        r["recovered_s"] = None if normal_after is None else round(normal_after - t1, 3)
        if kind == "daemon_kill":
            r["recovered_s"] = None if normal_after is None else round(normal_after - t0, 3)
        r["ok"] = r["recovered_s"] is not None and r["recovered_s"] <= RECOVER_LIMIT_S
        if kind in ("dropout", "sim_stop") and ev["seconds"] > 0.15:
            r["ok"] = r["ok"] and r["detected_s"] is not None  # longer than the state timeout: held/failsafe
        return r

    def report(self, seconds):
        for ev in self.events:
            ev.update(self.measure(ev))
        rss = []
        for inc in self.incarnations:
            base = [r for t, r in inc["rss"] if t >= inc["start"] + RSS_WARMUP_S]
            if len(base) >= 2:
                rss.append({"pid": inc["pid"], "start_s": round(inc["start"], 1), "after_warmup_kb": base[0],
                            "max_kb": max(base), "growth_kb": max(base) - base[0], "samples": len(base)})
        summary_path = self.out / "sim_summary.json"
        sim = json.loads(summary_path.read_text()) if summary_path.exists() else {}
        misses = max((v for t, v in self.running_totals("misses")), default=0)
        cycles = max((v for t, v in self.running_totals("cycles")), default=0)
        collisions = sim.get("collisions") or []
        checks = {
            "no_bad_commands": not self.bad_commands,
            "rss_growth_le_1MB": bool(rss) and all(r["growth_kb"] <= RSS_LIMIT_KB for r in rss),
            "every_fault_recovered": all(ev["ok"] for ev in self.events),
            "no_collision": not collisions,
            "no_unasked_exit": not self.unasked_exits,
        }
        out = {"minutes": self.a.minutes, "scenario": self.a.scenario, "task": self.task, "seed": self.a.seed,
               "realtime": self.a.realtime, "machine": os.uname().nodename, "cpus": os.cpu_count(),
               "load_end": os.getloadavg(), "commands": len(self.commands),
               "commands_by_mode": {MODE.get(m, str(m)): sum(1 for c in self.commands if c[2] == m)
                                    for m in sorted({c[2] for c in self.commands})},
               "bad_commands": self.bad_commands[:20], "bad_command_count": len(self.bad_commands),
               "states_relayed": self.relayed, "status_cycles": cycles, "deadline_misses": misses,
               "rss": rss, "faults": self.events, "collisions": collisions,
               "sim_outcome": sim.get("outcome"), "sim_command_timeouts": sim.get("command_timeouts"),
               "unasked_exits": self.unasked_exits, "checks": checks,
               "ok": all(checks.values())}
        (self.out / "soak.json").write_text(json.dumps(out, indent=1, default=str))
        print(f"[soak] {self.a.minutes} min of {self.a.scenario}: {len(self.commands)} commands "
              f"({out['commands_by_mode']}), {len(self.bad_commands)} NaN or out of limits; "
              f"deadline misses {misses} of {cycles} cycles")
        for ev in self.events:
            print(f"[soak]   {ev['t']:7.1f} s {ev['fault']:<13} detected {ev.get('detected_s')} s, "
                  f"recovered {ev.get('recovered_s')} s, meanwhile {ev['commands_meanwhile']}"
                  f"{'' if ev['ok'] else '  <- FAILED'}")
        for r in rss:
            print(f"[soak]   mppid pid {r['pid']}: RSS {r['after_warmup_kb']} kB after warm-up, "
                  f"growth {r['growth_kb']} kB over {r['samples']} s")
        for k, v in checks.items():
            print(f"[soak]   {k}: {'yes' if v else 'NO'}")
        print(f"[soak] {'passed' if out['ok'] else 'FAILED'}; {self.out / 'soak.json'}")
        return 0 if out["ok"] else 1


def main() -> int:
    ap = argparse.ArgumentParser(prog="tools/soak", description=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--minutes", type=float, default=5.0)
    ap.add_argument("--scenario", default="soak_circle")
    ap.add_argument("--every", type=float, default=15.0, help="seconds between faults")
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--out", default="results/soak")
    ap.add_argument("--set", action="append", default=[], metavar="KEY=VALUE", help="mppid --set, repeatable")
    ap.add_argument("--no-realtime", dest="realtime", action="store_false")
    a = ap.parse_args()
    if a.minutes * 60 < WARMUP_S + 10:
        ap.error(f"--minutes must leave room for the {WARMUP_S:.0f} s warm-up and a fault")
    enter_private_network("MPPID_SOAK_NETNS")
    signal.signal(signal.SIGTERM, lambda *_: (_ for _ in ()).throw(KeyboardInterrupt()))
    return Soak(a).run()


if __name__ == "__main__":
    sys.exit(main())
