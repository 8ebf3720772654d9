"""Runs inside a clean Debian 12 root that holds the installed mppid package and nothing of a
build tree (tools/package-test.sh starts it there, in a private network namespace, with
Debian's python3): the flight stack from the installed files alone, and two missions flown
against the stand-in autopilot (sim/mavlink_vehicle, copied in as a test fixture).

What an operator does, in that order: the units' own command lines (ExecStart= of
/usr/lib/systemd/system/mppid*.service: the LCM route, the recorder, mppid, the bridge; no
systemd in a chroot, so this starts them as it would, as root: the bridge's `--realtime 85`
as its unit gives it), and for each flight the autopilot's link profile copied to
/etc/mppid/mavlink-bridge.yaml and the bridge restarted (docs/first-flight.md), then
`mppid-mission fly /usr/share/mppid/missions/NAME.yaml`: hover against a PX4 stand-in on UDP
(px4_udp.yaml), the 3 m/s circle against an ArduPilot stand-in (ardupilot_udp.yaml), mppid
and the recorder running on through the bridge's restart. Passes when both missions end
`done` within the bars below, mppid, the bridge and the recorder ran throughout, and the
recorder's log holds the flights. Around them, the installed docs/first-flight.md's command
blocks run as they are: those marked `sh no-vehicle` after the install (they put the Pi 5 task
in /etc/mppid, so that is what flies), `sh stand-in` with the first stand-in on the link,
`sh after-flight` at the end. Before the flights, the mapper from its unit's command line and
/etc/mppid/mapper.yaml (as `systemctl enable --now mppid-mapper.service` starts it): a depth
frame of a wall published on the bus it names turns into a local_map_t with the wall in it
(check_mapper). Writes results.json into --out.
"""
from __future__ import annotations

import argparse
import json
import os
import shlex
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import package_sitl

UNITS = Path("/usr/lib/systemd/system")
OUT = Path("/tmp/package-flight")
STANDIN = Path("/opt/standin")
STANDIN_PRIORITY = "85"   # the stand-in autopilot, a flight controller of its own: SCHED_FIFO
DOC = Path("/usr/share/doc/mppid/first-flight.md")
SOCK = "/run/mppid-mavlink/control.sock"
# The stand-in's bars (test/mavlink/test_flight.py: circle RMSE < 0.3 m after the ramp).
MAX_RMSE = {"hover": 0.2, "circle_3ms": 0.3}
MISSION_TIMEOUT_S = {"hover": 120, "circle_3ms": 150}
SERVICES = ("mppid-lcm-route.service", "mppid-recorder.service", "mppid.service", "mppid-mavlink-bridge.service")
# Each autopilot's stand-in: the port its profile (NAME_udp.yaml) listens on, its parameters.
AUTOPILOTS = {"px4": (14540, ()), "ardupilot": (14550, ("GUID_OPTIONS=8", "MOT_THST_HOVER=0.4"))}
# `arducopter`: ArduCopter SITL in place of the stand-in (package_sitl.py), on the ArduPilot profile.
PROFILE = {"px4": "px4", "ardupilot": "ardupilot", "arducopter": "ardupilot"}


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
    """The processes of the flight stack, each logging to OUT/NAME.log; mppid, the bridge and
    the recorder on one CPU when `cpu` is given, the stand-in autopilot (a flight controller of
    its own on a vehicle) on `standin_cpu` (the latency budget: docs/first-flight.md)."""

    def __init__(self, cpu: int | None, standin_cpu: int | None):
        self.procs: dict[str, subprocess.Popen] = {}
        self.mppid_cmd: list[str] = []
        self.pin = ["taskset", "-c", str(cpu)] if cpu is not None else []
        self.standin_pin = ["taskset", "-c", str(standin_cpu)] if standin_cpu is not None else []

    def start(self, name: str, cmd: list[str], env=None):
        cmd = (self.standin_pin if name == "standin" else self.pin) + cmd
        log = open(OUT / f"{name}.log", "ab")
        self.procs[name] = subprocess.Popen(cmd, stdout=log, stderr=subprocess.STDOUT, stdin=subprocess.DEVNULL,
                                            env={**os.environ, **(env or {})})
        print(f"[package-flight] {name}: {' '.join(cmd)}", flush=True)

    def alive(self, name: str) -> bool:
        return self.procs[name].poll() is None

    def cpu_share(self, name: str) -> float | None:
        """CPU time over wall time since it started (1.0: one core busy), children included
        for the ones started through chrt or taskset (those exec, so the pid is the program)."""
        try:
            fields = Path(f"/proc/{self.procs[name].pid}/stat").read_text().rsplit(")", 1)[1].split()
            uptime = float(Path("/proc/uptime").read_text().split()[0])
        except (OSError, KeyError):
            return None
        tck = os.sysconf("SC_CLK_TCK")
        cpu = (int(fields[11]) + int(fields[12])) / tck
        wall = uptime - int(fields[19]) / tck
        return round(cpu / wall, 3) if wall > 0 else None

    @staticmethod
    def _terminate(p: subprocess.Popen):
        """SIGTERM, then SIGKILL after 5 s."""
        if p.poll() is None:
            p.send_signal(signal.SIGTERM)
            try:
                p.wait(5)
            except subprocess.TimeoutExpired:
                p.kill()

    def stop(self, name: str):
        self._terminate(self.procs.pop(name))

    def stop_all(self):
        for p in reversed(list(self.procs.values())):
            self._terminate(p)


def start_stack(st: Stack, mppid_sets: list[str]):
    """The units mppid.target starts, but the bridge (its link is each flight's)."""
    for cmd in exec_lines("mppid-lcm-route.service"):
        subprocess.run(cmd, check=True)
    for unit in ("mppid-recorder.service", "mppid-mavlink-bridge.service"):  # StateDirectory=, RuntimeDirectory=
        for key, base in (("StateDirectory", "/var/lib"), ("RuntimeDirectory", "/run")):
            if unit_value(unit, key):
                Path(base, unit_value(unit, key)).mkdir(parents=True, exist_ok=True)
    st.start("recorder", exec_lines("mppid-recorder.service")[0])
    extra = ["--stats"] + [w for kv in mppid_sets for w in ("--set", kv)]
    st.mppid_cmd = exec_lines("mppid.service")[0] + extra
    st.start("mppid", st.mppid_cmd)


def start_link(st: Stack, flight: str, autopilot: str):
    """The operator's edit for this autopilot, the bridge (re)started, the stand-in booted."""
    (OUT / flight).mkdir(parents=True, exist_ok=True)
    shutil.copy(f"/usr/share/mppid/bridge/{PROFILE[autopilot]}_udp.yaml", "/etc/mppid/mavlink-bridge.yaml")
    st.start("bridge", exec_lines("mppid-mavlink-bridge.service")[0]
             + ["--set", f"trace.file={OUT / flight / 'bridge_trace.jsonl'}"])
    if autopilot == "arducopter":
        package_sitl.start(st, OUT / flight)
        return
    port, params = AUTOPILOTS[autopilot]
    cmd = ["chrt", "-f", STANDIN_PRIORITY, "python3", "-m", "mavlink_vehicle", "--url", f"udpout:127.0.0.1:{port}",
           "--autopilot", autopilot, "--out", str(OUT / flight / "standin")]
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


def wall_frame(seq: int, point_cloud_t):
    """A depth frame from (0, 0, 2) looking along +x (identity orientation) at a wall 3 m ahead:
    21 x 11 returns over y in [-1, 1], z in [-0.5, 0.5] (sensor frame)."""
    m = point_cloud_t()
    m.utime, m.seq, m.sensor = int(time.time() * 1e6), seq, point_cloud_t.SENSOR_DEPTH_CAMERA
    m.position, m.orientation = [0.0, 0.0, 2.0], [1.0, 0.0, 0.0, 0.0]
    m.min_range, m.max_range = 0.2, 10.0
    pts = [(3.0, -1.0 + 0.1 * i, -0.5 + 0.1 * k) for i in range(21) for k in range(11)]
    m.n = len(pts)
    m.x, m.y, m.z = ([p[d] for p in pts] for d in range(3))
    m.hit = [1] * m.n
    return m


def distance_at(m, p) -> float:
    """The map's distance [m] at the cell holding world point p."""
    i = [int((p[d] - m.origin[d]) // m.resolution) for d in range(3)]
    return m.distance_mm[i[0] + m.nx * (i[1] + m.ny * i[2])] / 1000.0


def check_mapper(st: Stack) -> dict:
    """mppid-mapper from its unit and /etc/mppid/mapper.yaml (a small window: --set map.size),
    a wall's frames on the bus the settings name, and the first map that holds the wall: the
    distance on the wall under 0.3 m, at the sensor over 2 m."""
    sys.path.insert(0, "/usr/lib/mppid/python")
    import lcm  # noqa: PLC0415 (the package's Python, as the bridge's)
    import yaml  # noqa: PLC0415
    from mppi_lcm import local_map_t, point_cloud_t  # noqa: PLC0415
    url = yaml.safe_load(Path("/etc/mppid/mapper.yaml").read_text())["lcm_url"]
    st.start("mapper", exec_lines("mppid-mapper.service")[0] + ["--set", "map.size=[8,8,4]"])
    bus, maps = lcm.LCM(url), []
    bus.subscribe("MPPI_LOCAL_MAP", lambda _ch, data: maps.append(local_map_t.decode(data)))
    res: dict = {"url": url}
    deadline = time.monotonic() + 20.0
    for seq in range(1, 1000):
        bus.publish("MPPI_DEPTH", wall_frame(seq, point_cloud_t).encode())
        bus.handle_timeout(100)
        with_wall = [m for m in maps if distance_at(m, (3.0, 0.0, 2.0)) < 0.3]
        if with_wall or time.monotonic() > deadline:
            break
    res["maps"] = len(maps)
    if with_wall:
        m = with_wall[0]
        res.update(cells=[m.nx, m.ny, m.nz], wall_m=distance_at(m, (3.0, 0.0, 2.0)),
                   sensor_m=distance_at(m, (0.0, 0.0, 2.0)))
    res["alive"] = st.alive("mapper")
    st.stop("mapper")
    res["ok"] = bool(with_wall) and res["sensor_m"] > 2.0 and res["alive"]
    print(f"[package-flight] mapper: {res}", flush=True)
    return res


def fly(name: str, key: str) -> dict:
    out = OUT / key
    t0 = time.monotonic()
    r = subprocess.run(["mppid-mission", "fly", f"/usr/share/mppid/missions/{name}.yaml", "--bridge", SOCK,
                        "--out", str(out)], capture_output=True, text=True, timeout=MISSION_TIMEOUT_S.get(name, 180))
    (OUT / f"mission-{name}.log").write_text(r.stdout + r.stderr)
    summary = json.loads((out / "mission_summary.json").read_text())
    rmse = max((leg["rmse"] for leg in summary["legs"] if "rmse" in leg), default=float("inf"))
    res = {"rc": r.returncode, "outcome": summary["outcome"], "worst_leg_rmse_m": round(rmse, 4),
           "wall_s": round(time.monotonic() - t0, 1)}
    res.update(wire_latency(out))
    print(f"[package-flight] {name}: {res}", flush=True)
    return res


def doc_blocks(tag: str) -> list[str]:
    """The installed first-flight.md's command blocks marked ```sh TAG."""
    blocks, cur = [], None
    for line in DOC.read_text().splitlines():
        if cur is None and line.strip() == f"```sh {tag}":
            cur = []
        elif cur is not None and line.strip() == "```":
            blocks.append("\n".join(cur))
            cur = None
        elif cur is not None:
            cur.append(line)
    return blocks


def run_doc(tag: str) -> int:
    """Runs the guide's blocks of one tag as an operator would (root here: `sudo` runs the
    command as it is); the number run. A block that fails ends the test."""
    shim = OUT / "shim"
    shim.mkdir(exist_ok=True)
    (shim / "sudo").write_text('#!/bin/sh\n[ "$1" = -E ] && shift\nexec "$@"\n')
    (shim / "sudo").chmod(0o755)
    env = {**os.environ, "PATH": f"{shim}:{os.environ.get('PATH', '/usr/sbin:/usr/bin:/sbin:/bin')}",
           "HOME": "/root", "USER": "root"}
    blocks = doc_blocks(tag)
    for i, b in enumerate(blocks):
        r = subprocess.run(["sh", "-ec", b], cwd="/tmp", env=env, capture_output=True, text=True, timeout=120)
        (OUT / f"doc-{tag}-{i}.log").write_text(f"$ {b}\n{r.stdout}{r.stderr}")
        print(f"[package-flight] first-flight.md `{tag}` block {i + 1}/{len(blocks)}: rc {r.returncode}", flush=True)
        if r.returncode != 0:
            raise SystemExit(f"package-flight: first-flight.md's `sh {tag}` block failed:\n{b}\n{r.stdout}{r.stderr}")
    return len(blocks)


def percentile(v: list[float], p: float) -> float | None:
    v = sorted(v)
    return round(v[min(len(v) - 1, int(round((len(v) - 1) * p / 100.0)))], 2) if v else None


def wire_latency(out: Path) -> dict:
    """State on the wire -> the setpoint answering it on the wire (as drivers/mavlink/tools/
    latency.py pairs them: the stand-in's ODOMETRY send time, the bridge's trace), PX4 only
    (ArduPilot's states are two messages)."""
    wire, trace = out / "standin" / "wire.jsonl", out / "bridge_trace.jsonl"
    if not wire.exists() or not trace.exists():
        return {}
    sent = {}
    for line in wire.read_text().splitlines():
        r = json.loads(line)
        if r.get("type") == "ODOMETRY":
            sent[r["time_usec"]] = r["mono_us"]
    lat = []
    for line in trace.read_text().splitlines():
        r = json.loads(line)
        if r.get("state_time_usec") in sent:
            lat.append((r["mono_us"] - sent[r["state_time_usec"]]) / 1000.0)
    if not lat:
        return {}
    return {"state_to_setpoint_ms": {"n": len(lat), "p50": percentile(lat, 50), "p99": percentile(lat, 99),
                                     "max": round(max(lat), 2)}}


def mppid_stats() -> dict:
    """mppid's own --stats line (compute, state sampled -> command out, misses), at its exit."""
    for line in (OUT / "mppid.log").read_text(errors="replace").splitlines():
        if line.startswith("mppid-stats "):
            d = json.loads(line.split(" ", 1)[1])
            return {k: d[k] for k in ("backend", "rollouts", "cycles", "misses", "compute", "latency", "partial_updates")}
    return {}


def fly_one(st: Stack, token: str, doc_first: bool, results: dict, alive: dict) -> str:
    """One flight of --flights (NAME:AUTOPILOT[:kill]) on a fresh link (the bridge restarted,
    mppid and the recorder running on); its results key."""
    name, autopilot, *variant = token.split(":")
    base = key = name + ("_kill" if variant == ["kill"] else "")
    n = 1
    while key in results:        # the same flight again (a longer measurement): circle_3ms_2, ...
        n += 1
        key = f"{base}_{n}"
    start_link(st, key, autopilot)
    bridge_ready(90.0 if autopilot == "arducopter" else 40.0)
    if doc_first:
        results["doc_blocks"]["stand-in"] = run_doc("stand-in")
    if variant == ["kill"]:
        results[key] = package_sitl.fly_kill(st, name, OUT / key, SOCK, st.mppid_cmd)
    else:
        results[key] = fly(name, key)
    results[key]["cpu_share"] = {n: st.cpu_share(n) for n in ("mppid", "bridge", "recorder", "standin")}
    alive.update({f"{n} ({key})": st.alive(n) for n in ("recorder", "mppid", "bridge")})
    for n in ("referee", "standin", "bridge"):
        if n in st.procs:
            st.stop(n)
    return key


def operator_edits(flights: list[str], sets: list[str]) -> list[str]:
    """For ArduCopter SITL: its airframe's vehicle file in /etc/mppid (package_sitl.py) and
    mppid's cycle on each state (config/ardupilot/mppid_overlay.yaml's one line)."""
    if not any(":arducopter" in f for f in flights):
        return sets
    shutil.copy(package_sitl.FIXTURE / "vehicle.yaml", "/etc/mppid/vehicle.yaml")
    return ["daemon.trigger=state"] + sets


def failures_of(results: dict, keys: list[str], doc: bool) -> list[str]:
    failures = []
    for k in keys:
        r = results[k]
        if "ok" in r:
            bad = not r["ok"]
        else:
            bad = r["rc"] != 0 or r["outcome"] != "done" or r["worst_leg_rmse_m"] > MAX_RMSE.get(k, 0.3)
        if bad:
            failures.append(f"{k}: {r}")
    failures += [f"{n} exited during the flights" for n, ok in results["alive"].items() if not ok]
    if not results.get("mapper", {}).get("ok"):
        failures.append(f"mppid-mapper made no map of the wall: {results.get('mapper')}")
    if doc and results["enabled"] != sorted(SERVICES):
        failures.append(f"`systemctl enable mppid.target` enabled {results['enabled']}, not {sorted(SERVICES)}")
    if not results["recorder_files"] or sum(results["recorder_files"].values()) < 100_000:
        failures.append(f"the recorder wrote too little: {results['recorder_files']}")
    return failures


def main() -> int:
    global OUT
    ap = argparse.ArgumentParser(description="the flight stack from the installed package, and missions")
    ap.add_argument("--out", type=Path, default=OUT)
    ap.add_argument("--flights", default="hover:px4,circle_3ms:ardupilot",
                    help="MISSION:AUTOPILOT[:kill],... (AUTOPILOT: px4, ardupilot (stand-ins), arducopter (SITL))")
    ap.add_argument("--cpu", type=int, help="mppid, the bridge and the recorder on this one CPU (taskset)")
    ap.add_argument("--standin-cpu", type=int, help="the stand-in autopilot on this CPU")
    ap.add_argument("--set", action="append", default=[], metavar="KEY=VALUE", help="mppid --set")
    ap.add_argument("--no-doc", dest="doc", action="store_false",
                    help="without first-flight.md's commands (a measurement)")
    a = ap.parse_args()
    OUT = a.out
    OUT.mkdir(parents=True, exist_ok=True)
    st = Stack(a.cpu, a.standin_cpu)
    flights = a.flights.split(",")
    results: dict = {"cpu": a.cpu, "mppid_sets": a.set, "doc_blocks": {}}
    keys, alive = [], {}
    try:
        if a.doc:
            results["doc_blocks"]["no-vehicle"] = run_doc("no-vehicle")
            results["enabled"] = sorted(p.name for p in Path("/etc/systemd/system/mppid.target.wants").iterdir())
        start_stack(st, operator_edits(flights, a.set))
        results["mapper"] = check_mapper(st)
        for i, token in enumerate(flights):
            keys.append(fly_one(st, token, a.doc and i == 0, results, alive))
    finally:
        st.stop_all()
    results["alive"] = alive
    if a.doc:
        results["doc_blocks"]["after-flight"] = run_doc("after-flight")
    results["mppid"] = mppid_stats()
    logs = sorted(Path("/var/lib/mppid-recorder").glob("mppid.lcmlog*"))
    results["recorder_files"] = {p.name: p.stat().st_size for p in logs}
    (OUT / "results.json").write_text(json.dumps(results, indent=1))
    failures = failures_of(results, keys, a.doc)
    for f in failures:
        print(f"[package-flight] FAILED {f}", flush=True)
    return 1 if failures else 0


if __name__ == "__main__":
    sys.exit(main())
