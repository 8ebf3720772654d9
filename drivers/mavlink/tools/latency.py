#!/usr/bin/env python3
"""State on the MAVLink wire -> setpoint on the wire, through bridge and mppid, on this
machine: p50, p99 (and more) as one JSON document.

    .venv/bin/python drivers/mavlink/tools/latency.py [--seconds 20] [--rollouts 512] [--no-rt] [--out DIR]

Runs, in a private network namespace (unshare -n; root), the simulated autopilot, the
bridge and mppid (--realtime, as in service), flies a hover (offboard, arm, hold), and
pairs each setpoint with the state it answers: the bridge's trace names, per setpoint, the
autopilot time stamp (ODOMETRY time_usec) of the state it answers and when it sent it
(monotonic, just after sendto); the simulated autopilot logs when it sent each ODOMETRY
(monotonic, just before sendto). Loopback UDP has no wire time of its own, so these are the
times on the wire. The figure includes the bridge's NED->ENU state path, LCM both ways,
mppid's cycle (wait for the next 50 Hz tick + MPPI iteration) and the bridge's command path.
"""
from __future__ import annotations

import argparse
import ctypes
import json
import os
import platform
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from mppi_mavlink.control import request

ROOT = Path(__file__).resolve().parents[3]
PY = sys.executable  # has the bridge and the simulated autopilot (tools/setup.sh installs them into .venv)
LCM_URL = "udpm://239.255.76.67:7667?ttl=0"


def percentile(v, p):
    v = sorted(v)
    if not v:
        return None
    k = (len(v) - 1) * p / 100.0
    i = int(k)
    return v[i] + (v[min(i + 1, len(v) - 1)] - v[i]) * (k - i)


def find_mppid():
    for d in ([os.environ["MPPID_BUILD_DIR"]] if os.environ.get("MPPID_BUILD_DIR") else []) + \
            ["build", "build-mavlink", "build-sim", "build-daemon"]:
        p = ROOT / d / "bin" / "mppid"
        if p.is_file():
            return p
    sys.exit("latency: mppid not built (tools/setup.sh)")


def ctl(sock, line):
    return request(sock, line, 30)


def private_network():
    """This process into a network namespace of its own, with the loopback multicast route."""
    libc = ctypes.CDLL("libc.so.6", use_errno=True)
    if libc.unshare(0x40000000) != 0:
        sys.exit("latency: unshare(CLONE_NEWNET) failed: run as root")
    subprocess.run(["ip", "link", "set", "lo", "up"], check=True)
    subprocess.run(["ip", "route", "add", "224.0.0.0/4", "dev", "lo"], check=True)


def wait_until_streaming(sock: str, seconds: float = 20.0):
    """Until the bridge has the link, no refusal, mppid's stream and 75 states published."""
    deadline = time.monotonic() + seconds
    while time.monotonic() < deadline:
        try:
            st = ctl(sock, "status")["status"]
            if st["link_up"] and not st["refusal"] and st["streaming"] and st["states_published"] > 75:
                return
        except (OSError, ValueError, KeyError):
            pass
        time.sleep(0.2)


def fly(a, out: Path) -> tuple[int, int]:
    """The chain (bridge, mppid, the simulated autopilot) engaged for a.seconds: its window [us]."""
    env = dict(os.environ, PYTHONUNBUFFERED="1")
    rt = [] if a.no_rt else ["chrt", "-f", "85"]
    sock = str(out / "bridge.sock")
    procs = []

    def start(name, cmd):
        f = open(out / f"{name}.log", "wb")
        procs.append(subprocess.Popen([str(c) for c in cmd], stdout=f, stderr=subprocess.STDOUT, cwd=ROOT, env=env))

    try:
        start("bridge", [PY, "-m", "mppi_mavlink", "run", "--config", ROOT / "config/bridge/px4_sitl.yaml",
                         *([] if a.no_rt else ["--realtime", "85"]),
                              "--set", f"control.socket={sock}", "--set", f"trace.file={out / 'bridge_trace.jsonl'}"])
        start("mppid", [find_mppid(), "--config", ROOT / f"config/tasks/{a.task}.yaml", "--lcm-url", LCM_URL,
                        "--backend", "cpu", "--set", f"mppi.rollouts={a.rollouts}"] + ([] if a.no_rt else ["--realtime"]))
        start("vehicle", rt + [PY, "-m", "mavlink_vehicle", "--url", "udpout:127.0.0.1:14540", "--out", out,
                               "--start", "0,0,0"])
        wait_until_streaming(sock)
        for line in ("offboard", "arm"):
            r = ctl(sock, line)
            if not r["ok"]:
                sys.exit(f"latency: {line}: {r['message']}")
        t0 = time.monotonic_ns() // 1000
        time.sleep(a.seconds)  # the measured window
        t1 = time.monotonic_ns() // 1000
        ctl(sock, "land")
        return t0, t1
    finally:
        for p in procs[::-1]:
            p.send_signal(signal.SIGTERM)
        for p in procs:
            try:
                p.wait(5)
            except subprocess.TimeoutExpired:
                p.kill()


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--seconds", type=float, default=20.0)
    ap.add_argument("--rollouts", type=int, default=512)
    ap.add_argument("--task", default="quadrotor_rate_track")
    ap.add_argument("--no-rt", action="store_true", help="no SCHED_FIFO (mppid without --realtime)")
    ap.add_argument("--out", help="keep the logs here (default: a temporary folder)")
    a = ap.parse_args()
    out = Path(a.out or tempfile.mkdtemp(prefix="mavlink-latency-"))
    out.mkdir(parents=True, exist_ok=True)
    private_network()
    t0, t1 = fly(a, out)
    res = measure(out, t0, t1)
    res.update({"seconds": a.seconds, "rollouts": a.rollouts, "task": a.task, "realtime": not a.no_rt,
                "machine": {"cpus": os.cpu_count(), "cpu": _cpu_model(), "kernel": platform.release(),
                            "load_avg": os.getloadavg()},
                "logs": str(out)})
    print(json.dumps(res, indent=2))


def measure(out, t0, t1):
    """Each state the autopilot sent (wire.jsonl) matched with the bridge's answer to it
    (bridge_trace.jsonl), between t0 and t1 (monotonic us)."""
    sent = {}
    for line in open(out / "wire.jsonl"):
        r = json.loads(line)
        if r["type"] == "ODOMETRY":
            sent[r["time_usec"]] = r["mono_us"]
    lat, lost = [], 0
    for line in open(out / "bridge_trace.jsonl"):
        r = json.loads(line)
        if not t0 <= r["mono_us"] <= t1:
            continue
        s = sent.get(r["state_time_usec"])
        if s is None:
            lost += 1
            continue
        lat.append((r["mono_us"] - s) / 1000.0)
    states = sum(1 for t in sent.values() if t0 <= t <= t1)
    return {
        "what": "ODOMETRY sent by the autopilot -> SET_ATTITUDE_TARGET answering it sent by the bridge [ms]",
        "samples": len(lat), "states_on_wire": states, "unmatched": lost,
        "p50_ms": percentile(lat, 50), "p90_ms": percentile(lat, 90), "p99_ms": percentile(lat, 99),
        "max_ms": max(lat) if lat else None, "min_ms": min(lat) if lat else None,
    }


def _cpu_model():
    try:
        for line in open("/proc/cpuinfo"):
            if line.startswith("model name"):
                return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor()


if __name__ == "__main__":
    main()
