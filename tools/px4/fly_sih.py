#!/usr/bin/env python3
"""One flight of mppid through PX4 SITL with SIH (Simulation-In-Hardware), in a private
network namespace, recorded and scored from SIH's truth.

    tools/px4/fly_sih.py --px4 PX4_BUILD_DIR --out DIR [--bridge-root REPO] [--mppid BIN]
        [--set key=value ...] -- MISSION ARGS (as mppid-mission takes them: fly FILE | circle ...)

PX4_BUILD_DIR is a `px4_sitl_sih` build (its bin/px4 and rootfs/; docs/px4.md says which PX4
was flown). The script re-runs itself under `unshare -n` (root), brings `lo` up and routes
224.0.0.0/4 to it (the LCM bus), as tools/sitl_harness does for ArduCopter; then starts, in
order: the recorders (threads of this process), lcm-logger (flight.lcmlog: states,
commands, status), PX4 (`PX4_SIM_MODEL=sihsim_quadx PX4_SIMULATOR=sihsim ../bin/px4 -d` in
rootfs/), mppid (quadrotor_rate_track, CPU, --realtime), the bridge
(config/bridge/px4_sitl.yaml) and mppid-mission with `--bridge SOCK`, and waits for the
mission tool to exit.

`--bridge-root` flies another checkout's bridge and mission tool (the one before a fix,
say): they run as `python -m mppi_mavlink` / `-m mppi_mission` from its drivers/, with this
checkout's venv and LCM types. As in the bridge's tests (test/mavlink/mavchain.py), PX4 and
the bridge run at SCHED_FIFO 85, above mppid's 80 (`--no-rt`: at normal priority, as a new
user would start them).

Truth: PX4 sends SIH's ground truth to the SIH display port as HIL_STATE_QUATERNION (25 Hz:
the groundtruth topics' attitude, rates, geodetic position and NED velocity) and the
estimate as LOCAL_POSITION_NED to the GCS port (14550). Both are recorded with their
receive times (truth.jsonl, estimate.jsonl), which also measure PX4's clock against ours.
The score (score.json) is score_sih.py's.
"""
from __future__ import annotations

import argparse
import json
import os
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
LCM_URL = "udpm://239.255.76.67:7667?ttl=0"
TRUTH_PORT = 19410      # px4-rc.mavlink: the SIH display link sends here (HIL_STATE_QUATERNION)
GCS_PORT = 14550        # the GCS link (LOCAL_POSITION_NED at 50 Hz, as px4-rc.mavlink asks)
INNER = "MPPID_PX4_NETNS"
LCM_LOGGER = ROOT / ".venv" / "bin" / "lcm-logger"


def parse(argv):
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--px4", type=Path, required=True, help="the px4_sitl_sih build folder")
    ap.add_argument("--out", type=Path, required=True)
    ap.add_argument("--bridge-root", type=Path, default=ROOT, help="checkout whose bridge and mission tool fly")
    ap.add_argument("--mppid", type=Path, default=ROOT / "build" / "bin" / "mppid")
    ap.add_argument("--task", default="quadrotor_rate_track")
    ap.add_argument("--set", dest="sets", action="append", default=[], help="mppid --set key=value")
    ap.add_argument("--bridge-set", action="append", default=[], help="bridge --set key=value")
    ap.add_argument("--timeout", type=float, default=180.0, help="the mission tool's wall-clock limit [s]")
    ap.add_argument("--no-rt", action="store_true", help="PX4 and the bridge without SCHED_FIFO 85")
    ap.add_argument("mission", nargs=argparse.REMAINDER, help="-- then mppid-mission's arguments")
    a = ap.parse_args(argv)
    a.mission = [m for m in a.mission if m != "--"] if a.mission[:1] == ["--"] else a.mission
    if not a.mission:
        ap.error("no mission: add -- circle --center=-5,0,2 --radius 5 --speed 3 --takeoff 2 (say)")
    return a


class Procs:
    """The flight's processes, each logging to OUT/NAME.log, stopped in reverse order."""

    def __init__(self, out: Path):
        self.out, self.p = out, {}

    def start(self, name, cmd, cwd=None, env=None):
        log = open(self.out / f"{name}.log", "wb")
        self.p[name] = subprocess.Popen([str(c) for c in cmd], stdout=log, stderr=subprocess.STDOUT,
                                        stdin=subprocess.DEVNULL, cwd=cwd, env={**os.environ, **(env or {})},
                                        start_new_session=True)
        return self.p[name]

    def stop_all(self, grace=5.0):
        for name in reversed(list(self.p)):
            p = self.p[name]
            if p.poll() is None:
                os.killpg(p.pid, signal.SIGTERM)
                try:
                    p.wait(grace)
                except subprocess.TimeoutExpired:
                    os.killpg(p.pid, signal.SIGKILL)
                    p.wait()


def record(port: int, types: set[str], path: Path, stop: threading.Event):
    """Every message of `types` arriving on UDP `port`, with its receive time (wall, us)."""
    os.environ.setdefault("MAVLINK20", "1")
    from pymavlink import mavutil
    conn = mavutil.mavlink_connection(f"udpin:127.0.0.1:{port}", source_system=254)
    with open(path, "w", buffering=1) as f:
        while not stop.is_set():
            m = conn.recv_match(type=list(types), blocking=True, timeout=0.2)
            if m is None:
                continue
            d = m.to_dict()
            d["wall_us"] = time.time_ns() // 1000
            f.write(json.dumps(d) + "\n")
    conn.close()


def wait_line(path: Path, text: str, timeout: float) -> bool:
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        if path.is_file() and text in path.read_text(errors="replace"):
            return True
        time.sleep(0.2)
    return False


def fly(a) -> int:
    out = a.out.resolve()
    out.mkdir(parents=True, exist_ok=True)
    subprocess.run(["ip", "link", "set", "lo", "up"], check=True)
    subprocess.run(["ip", "route", "add", "224.0.0.0/4", "dev", "lo"], check=True)
    procs, stop = Procs(out), threading.Event()
    recorders = [threading.Thread(target=record, args=(port, types, out / name, stop)) for port, types, name in (
        (TRUTH_PORT, {"HIL_STATE_QUATERNION"}, "truth.jsonl"),
        (GCS_PORT, {"LOCAL_POSITION_NED", "HEARTBEAT", "STATUSTEXT"}, "estimate.jsonl"))]
    rc, info = 1, {"started_wall_us": time.time_ns() // 1000, "mission_args": a.mission}
    try:
        for r in recorders:
            r.start()
        procs.start("logger", [LCM_LOGGER, "-q", "-f", "-c", "MPPI_(STATE|STATUS|COMMAND|MAVLINK_LINK)",
                               f"--lcm-url={LCM_URL}", out / "flight.lcmlog"])
        px4 = a.px4.resolve()
        io_prio = [] if a.no_rt else ["chrt", "-f", "85"]
        procs.start("px4", io_prio + [px4 / "bin" / "px4", "-d"], cwd=px4 / "rootfs",
                    env={"PX4_SIM_MODEL": "sihsim_quadx", "PX4_SIMULATOR": "sihsim"})
        if not wait_line(out / "px4.log", "Ready for takeoff", 60):
            info["error"] = "PX4 did not report 'Ready for takeoff' in 60 s"
            return 1
        sock = out / "bridge.sock"
        br = a.bridge_root.resolve()
        procs.start("mppid", [a.mppid, "--config", ROOT / "config" / "tasks" / f"{a.task}.yaml", "--lcm-url", LCM_URL,
                              "--backend", "cpu", "--realtime"] + sum((["--set", s] for s in a.sets), []))
        py = [ROOT / ".venv" / "bin" / "python", "-m"]
        env = {"PYTHONPATH": os.pathsep.join([str(br / "drivers" / "mavlink"), str(br / "drivers" / "mission")]),
               "MPPI_LCM_PYTHON": str(ROOT / "build" / "python"), "PYTHONUNBUFFERED": "1"}
        procs.start("bridge", io_prio + py + ["mppi_mavlink", "run", "--config",
                               ROOT / "config" / "bridge" / "px4_sitl.yaml", "--lcm-url", LCM_URL,
                               "--set", f"control.socket={sock}", "--set", f"trace.file={out / 'bridge_trace.jsonl'}"]
                    + sum((["--set", s] for s in a.bridge_set), []), env=env)
        mission = procs.start("mission", py + ["mppi_mission"] + a.mission
                              + ["--bridge", sock, "--lcm-url", LCM_URL, "--out", out], env=env)
        try:
            rc = mission.wait(a.timeout)
        except subprocess.TimeoutExpired:
            info["error"] = f"mission tool still running after {a.timeout:g} s"
        info["mission_rc"] = rc
        return rc
    finally:
        info["ended_wall_us"] = time.time_ns() // 1000
        procs.stop_all()
        stop.set()
        for r in recorders:
            r.join(2.0)
        (out / "flight.json").write_text(json.dumps(info, indent=1))


def main(argv=None) -> int:
    a = parse(sys.argv[1:] if argv is None else argv)
    if os.environ.get(INNER) != "1":
        if os.geteuid() != 0:
            print("fly_sih: needs root (unshare -n, --realtime)", file=sys.stderr)
            return 2
        env = {**os.environ, INNER: "1"}
        return subprocess.call(["unshare", "-n", "--", sys.executable, __file__] + sys.argv[1:], env=env)
    rc = fly(a)
    from score_sih import score  # beside this file: a script's folder is on its import path
    s = score(a.out)
    (a.out / "score.json").write_text(json.dumps(s, indent=1))
    print(json.dumps(s, indent=1))
    return rc


if __name__ == "__main__":
    sys.exit(main())
