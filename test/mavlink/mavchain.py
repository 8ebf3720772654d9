"""One chain of processes: simulated autopilot <-> (MAVProxy) <-> bridge <-> LCM <-> mppid,
started inside the test's network namespace, with helpers to drive and watch it."""
from __future__ import annotations

import json
import os
import threading
import time
from pathlib import Path

import yaml

from mavtest import LCM_URL, PYTHON, ROOT, Procs, events, find_binary, read_jsonl, require_binary, wait_for
from mppi_mavlink import control, lcm_types

VEHICLE_PORT = 14540      # the bridge listens here (PX4's offboard port)
ROUTER_IN = 14550         # MAVProxy's master (the vehicle sends here)
# Real time on a shared 2-core machine: 512 samples keep mppid inside its 20 ms (a miss makes
# its status unhealthy, and the bridge rightly pauses the stream).
MPPID_SETS = ("mppi.rollouts=512",)
# As in service: mppid --realtime (SCHED_FIFO 80, drivers/systemd/mppid.service) and the link's
# processes (simulated autopilot, router, bridge) above it, SCHED_FIFO 85: they are short I/O
# work. Without this, other builds on the machine make mppid miss its deadlines.
# MAVLINK_TEST_RT=0 turns it off.
RT = os.environ.get("MAVLINK_TEST_RT", "1") != "0" and os.geteuid() == 0
# The link's Python processes: `python -m MODULE`, at SCHED_FIFO 85 once imported.
IO_LAUNCH = [PYTHON, Path(__file__).resolve().parent / "fifo_after_imports.py", "85"] if RT else [PYTHON, "-m"]
# The bridge as its unit runs it: its latency path's threads at SCHED_FIFO 85 once started.
BRIDGE_RT = ["--realtime", "85"] if RT else []


class Chain:
    def __init__(self, procs: Procs, out: Path, world=None, autopilot="px4", vehicle_params=(), router=False,
                 bridge_sets=(), mppid=True, task="quadrotor_rate_track", mppid_sets=MPPID_SETS, bridge_config=None,
                 vehicle_args=()):
        self.procs, self.out = procs, out
        self.world, self.autopilot, self.router = world, autopilot, router
        self.sock = str(out / "bridge.sock")
        self.link_msgs = []
        self._lcm_stop = threading.Event()
        self.vehicle_params, self.bridge_sets = list(vehicle_params), list(bridge_sets)
        self.vehicle_args = list(vehicle_args)
        self.mppid, self.task, self.mppid_sets = mppid, task, list(mppid_sets)
        self.bridge_config = bridge_config or str(ROOT / "config" / "bridge" /
                                                  ("px4_sitl.yaml" if autopilot == "px4" else "ardupilot_sitl.yaml"))

    # ---- processes ----------------------------------------------------------------------
    def _take_turn(self):
        """The link's processes at SCHED_FIFO 85, the test's stand-in controller answering each
        state, a real-time mppid: one such test at a time on the machine's cores, never beside a
        real-time SITL flight (turns.py), whose SCHED_FIFO simulator and daemon held the
        stand-in's answers off for 200 ms and more."""
        if RT:
            self.procs.turn.acquire()

    def start_vehicle(self, url=None):
        self._take_turn()
        url = url or f"udpout:127.0.0.1:{ROUTER_IN if self.router else VEHICLE_PORT}"
        cmd = IO_LAUNCH + ["mavlink_vehicle", "--url", url, "--autopilot", self.autopilot, "--out", self.out,
               "--lcm-url", LCM_URL]
        if self.world:
            cmd += ["--world", ROOT / "sim" / "mavlink_vehicle" / "worlds" / f"{self.world}.yaml"]
        for kv in self.vehicle_params:
            cmd += ["--param", kv]
        return self.procs.start("vehicle", cmd + self.vehicle_args)

    def start_router(self, extra_outs=()):
        self._take_turn()
        cmd = IO_LAUNCH + ["MAVProxy.mavproxy", f"--master=udpin:127.0.0.1:{ROUTER_IN}",
               f"--out=udpout:127.0.0.1:{VEHICLE_PORT}", "--daemon", "--non-interactive", "--nowait",
               f"--state-basedir={self.out}", "--default-modules=", "--streamrate=-1"]
        for o in extra_outs:
            cmd.append(f"--out={o}")
        return self.procs.start("mavproxy", cmd)

    def start_bridge(self, url=None):
        self._take_turn()
        # The simulated autopilot sends to the bridge's UDP port whatever the config names.
        url = url or f"udpin:127.0.0.1:{VEHICLE_PORT}"
        cmd = [PYTHON, "-m", "mppi_mavlink", "run", *BRIDGE_RT, "--config", self.bridge_config, "--lcm-url", LCM_URL,
               "--set", f"control.socket={self.sock}", "--set", f"trace.file={self.out / 'bridge_trace.jsonl'}",
               "--url", url]
        for kv in self.bridge_sets:
            cmd += ["--set", kv]
        return self.procs.start("bridge", cmd)

    def start_mppid(self):
        mppid = require_binary("mppid")
        cmd = [mppid, "--config", ROOT / "config" / "tasks" / f"{self.task}.yaml", "--lcm-url", LCM_URL,
               "--backend", "cpu"] + (["--realtime"] if RT else [])
        for kv in self.mppid_sets:
            cmd += ["--set", kv]
        self._take_turn()
        return self.procs.start("mppid", cmd)

    def start(self):
        self.listen_lcm()
        if self.router:
            self.start_router()
        self.start_bridge()
        if self.mppid:
            self.start_mppid()
        self.start_vehicle()
        wait_for(lambda: self.status().get("link_up") and not self.status().get("refusal"), 20,
                 "the bridge to find the autopilot and pass its checks")
        # The simulated autopilot's estimator is ready 1 s after boot (an arming check).
        wait_for(lambda: self.status().get("states_published", 0) >= 60, 10, "1.2 s of state")
        return self

    # ---- LCM ----------------------------------------------------------------------------
    def listen_lcm(self):
        import lcm
        link_t = lcm_types.import_link_type()
        lc = lcm.LCM(LCM_URL)
        lc.subscribe("MPPI_MAVLINK_LINK", lambda ch, data: self.link_msgs.append((time.monotonic(),
                                                                                 link_t.decode(data))))
        self.lc = lc

        def loop():
            while not self._lcm_stop.is_set():
                lc.handle_timeout(50)
        self._lcm_thread = threading.Thread(target=loop, daemon=True)
        self._lcm_thread.start()
        self.procs_cleanup = self._lcm_stop

    # ---- driving ------------------------------------------------------------------------
    def ctl(self, line, timeout=30.0) -> dict:
        return control.request(self.sock, line, timeout)

    def ok(self, line):
        r = self.ctl(line)
        assert r["ok"], f"bridge `{line}` failed: {r['message']}\n--- bridge log\n{self.procs.log('bridge')[-3000:]}"
        return r["message"]

    def status(self) -> dict:
        try:
            return self.ctl("status", 5.0)["status"]
        except (OSError, ValueError, KeyError):
            return {}

    def events(self, name=None):
        return events(self.out, name)

    def wait_event(self, name, timeout):
        return wait_for(lambda: self.events(name), timeout, f"vehicle event {name!r}\n"
                        f"events so far: {self.events()}\n--- bridge log tail\n{self.procs.log('bridge')[-2000:]}")

    def wire(self):
        return read_jsonl(self.out / "wire.jsonl")

    def setpoints(self):
        return [r for r in self.wire() if r["type"] == "SET_ATTITUDE_TARGET"]

    def stop_vehicle(self):
        self.procs.stop("vehicle")
        self._lcm_stop.set()
        return json.loads((self.out / "vehicle_summary.json").read_text())

    def land_and_finish(self, timeout=20):
        self.ok("land")
        self.wait_event("landed", timeout)
        return self.stop_vehicle()


def world_yaml(name):
    return yaml.safe_load((ROOT / "sim" / "mavlink_vehicle" / "worlds" / f"{name}.yaml").read_text())


def tapped_chain(procs, tmp_path, port, bridge_sets=(), **kw) -> Chain:
    """A chain whose vehicle sends to `port` (a linktools.UdpTap in front of the bridge),
    its bridge's telemetry grace 1 s, started and checked: link up, checks passed, states."""
    c = Chain(procs, tmp_path, bridge_sets=["telemetry.grace_s=1.0", *bridge_sets], **kw)
    c.listen_lcm()
    c.start_bridge()
    c.start_vehicle(url=f"udpout:127.0.0.1:{port}")
    wait_for(lambda: c.status().get("link_up") and not c.status().get("refusal")
             and c.status().get("states_published", 0) >= 60, 15, "link up, checks passed, states")
    return c
