"""Runs inside a clean Debian 12 root that holds the installed mppid package and nothing of a
build tree (tools/package-test.sh starts it there, in a private network namespace, with
Debian's python3): the flight stack from the installed files alone, and two missions flown
against the stand-in autopilot (sim/mavlink_vehicle, copied in as a test fixture).

What an operator does, in that order: the units' own command lines (ExecStart= of
/usr/lib/systemd/system/mppid*.service: the LCM route, the recorder, mppid, the bridge; no
systemd in a chroot, so this starts them as it would, as root, the bridge at SCHED_FIFO 85 as
its unit asks), and for each flight the autopilot's link profile copied to
/etc/mppid/mavlink-bridge.yaml and the bridge restarted (docs/first-flight.md), then
`mppid-mission fly /usr/share/mppid/missions/NAME.yaml`: hover against a PX4 stand-in on UDP
(px4_udp.yaml), the 3 m/s circle against an ArduPilot stand-in (ardupilot_udp.yaml), mppid
and the recorder running on through the bridge's restart. Passes when both missions end
`done` within the bars below, mppid, the bridge and the recorder ran throughout, and the
recorder's log holds the flights. Writes results.json beside itself.
"""
from __future__ import annotations

import json
import os
import shlex
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

UNITS = Path("/usr/lib/systemd/system")
OUT = Path(sys.argv[1] if len(sys.argv) > 1 else "/tmp/package-flight")
STANDIN = Path("/opt/standin")
SOCK = "/run/mppid-mavlink/control.sock"
# The stand-in's bars (test/mavlink/test_flight.py: circle RMSE < 0.3 m after the ramp).
MAX_RMSE = {"hover": 0.2, "circle_3ms": 0.3}
MISSION_TIMEOUT_S = {"hover": 120, "circle_3ms": 150}
# Each flight's autopilot: the stand-in's flavour, the port its profile listens on, its parameters.
FLIGHTS = (("hover", "px4", 14540, ()),
           ("circle_3ms", "ardupilot", 14550, ("GUID_OPTIONS=8", "MOT_THST_HOVER=0.4")))


def exec_lines(unit: str) -> list[list[str]]:
    """The ExecStart= command lines of an installed unit ('-' prefix: failure ignored)."""
    out = []
    for line in (UNITS / unit).read_text().splitlines():
        if line.startswith("ExecStart="):
            out.append(shlex.split(line[len("ExecStart="):].lstrip("-")))
    assert out, f"{unit}: no ExecStart="
    return out


def unit_value(unit: str, key: str) -> str | None:
    for line in (UNITS / unit).read_text().splitlines():
        if line.startswith(key + "="):
            return line.split("=", 1)[1]
    return None


class Stack:
    def __init__(self):
        self.procs: dict[str, subprocess.Popen] = {}

    def start(self, name: str, cmd: list[str], env=None):
        log = open(OUT / f"{name}.log", "ab")
        self.procs[name] = subprocess.Popen(cmd, stdout=log, stderr=subprocess.STDOUT, stdin=subprocess.DEVNULL,
                                            env={**os.environ, **(env or {})})
        print(f"[package-flight] {name}: {' '.join(cmd)}", flush=True)

    def alive(self, name: str) -> bool:
        return self.procs[name].poll() is None

    def stop(self, name: str):
        p = self.procs.pop(name)
        if p.poll() is None:
            p.send_signal(signal.SIGTERM)
            try:
                p.wait(5)
            except subprocess.TimeoutExpired:
                p.kill()

    def stop_all(self):
        for name, p in reversed(list(self.procs.items())):
            if p.poll() is None:
                p.send_signal(signal.SIGTERM)
                try:
                    p.wait(5)
                except subprocess.TimeoutExpired:
                    p.kill()


def start_stack(st: Stack):
    """The units mppid.target starts, but the bridge (its link is each flight's)."""
    for cmd in exec_lines("mppid-lcm-route.service"):
        subprocess.run(cmd, check=True)
    for unit in ("mppid-recorder.service", "mppid-mavlink-bridge.service"):  # StateDirectory=, RuntimeDirectory=
        for key, base in (("StateDirectory", "/var/lib"), ("RuntimeDirectory", "/run")):
            if unit_value(unit, key):
                Path(base, unit_value(unit, key)).mkdir(parents=True, exist_ok=True)
    st.start("recorder", exec_lines("mppid-recorder.service")[0])
    st.start("mppid", exec_lines("mppid.service")[0])


def start_link(st: Stack, autopilot: str, port: int, params):
    """The operator's edit for this autopilot, the bridge (re)started, the stand-in booted."""
    shutil.copy(f"/usr/share/mppid/bridge/{autopilot}_udp.yaml", "/etc/mppid/mavlink-bridge.yaml")
    prio = unit_value("mppid-mavlink-bridge.service", "CPUSchedulingPriority")
    st.start("bridge", ["chrt", "-f", prio] + exec_lines("mppid-mavlink-bridge.service")[0])
    cmd = ["chrt", "-f", prio, "python3", "-m", "mavlink_vehicle", "--url", f"udpout:127.0.0.1:{port}",
           "--autopilot", autopilot, "--out", str(OUT / f"standin-{autopilot}")]
    for p in params:
        cmd += ["--param", p]
    st.start("standin", cmd, env={"PYTHONPATH": f"{STANDIN}:/usr/lib/mppid/python",
                                  "MPPI_LCM_PYTHON": "/usr/lib/mppid/python"})


def bridge_ready(timeout=40.0) -> dict:
    """The bridge's `status` until the link is up, its checks passed and 1.2 s of states went
    to mppid (as test/mavlink/mavchain.py waits)."""
    deadline = time.monotonic() + timeout
    last = {}
    while time.monotonic() < deadline:
        r = subprocess.run(["mppid-mavlink-bridge", "status", "--socket", SOCK], capture_output=True, text=True)
        if r.returncode == 0:
            last = json.loads(r.stdout).get("status", {})
            if last.get("link_up") and not last.get("refusal") and last.get("states_published", 0) >= 60:
                return last
        time.sleep(0.5)
    raise SystemExit(f"package-flight: the bridge did not get ready in {timeout} s: {last}\n"
                     + (OUT / "bridge.log").read_text(errors="replace")[-3000:])


def fly(name: str) -> dict:
    out = OUT / name
    t0 = time.monotonic()
    r = subprocess.run(["mppid-mission", "fly", f"/usr/share/mppid/missions/{name}.yaml", "--bridge", SOCK,
                        "--out", str(out)], capture_output=True, text=True, timeout=MISSION_TIMEOUT_S[name])
    (OUT / f"mission-{name}.log").write_text(r.stdout + r.stderr)
    summary = json.loads((out / "mission_summary.json").read_text())
    rmse = max((leg["rmse"] for leg in summary["legs"] if "rmse" in leg), default=float("inf"))
    res = {"rc": r.returncode, "outcome": summary["outcome"], "worst_leg_rmse_m": round(rmse, 4),
           "wall_s": round(time.monotonic() - t0, 1)}
    print(f"[package-flight] {name}: {res}", flush=True)
    return res


def main() -> int:
    OUT.mkdir(parents=True, exist_ok=True)
    st = Stack()
    results: dict = {}
    try:
        start_stack(st)
        alive = {}
        for name, autopilot, port, params in FLIGHTS:
            start_link(st, autopilot, port, params)
            bridge_ready()
            results[name] = fly(name)
            alive.update({f"{n} ({name})": st.alive(n) for n in ("recorder", "mppid", "bridge")})
            st.stop("standin")
            st.stop("bridge")
        results["alive"] = alive
    finally:
        st.stop_all()
    logs = sorted(Path("/var/lib/mppid-recorder").glob("mppid.lcmlog*"))
    results["recorder_files"] = {p.name: p.stat().st_size for p in logs}
    (OUT / "results.json").write_text(json.dumps(results, indent=1))
    failures = [f"{n}: {results[n]}" for n in MAX_RMSE
                if results[n]["rc"] != 0 or results[n]["outcome"] != "done" or results[n]["worst_leg_rmse_m"] > MAX_RMSE[n]]
    failures += [f"{n} exited during the flights" for n, ok in results["alive"].items() if not ok]
    if not logs or sum(results["recorder_files"].values()) < 100_000:
        failures.append(f"the recorder wrote too little: {results['recorder_files']}")
    for f in failures:
        print(f"[package-flight] FAILED {f}", flush=True)
    return 1 if failures else 0


if __name__ == "__main__":
    sys.exit(main())
