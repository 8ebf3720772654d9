"""ArduCopter SITL in place of the stand-in, for package_flight.py (flights `NAME:arducopter`):
the real autopilot, built from ArduPilot's source outside this repository, copied into the
clean root as a fixture by `tools/package-test.sh --ardupilot-bin` (tools/ardupilot/
package-flights.sh; never in CI: CI has no ArduCopter build). What is under test is still only
the installed package: the operator's profile /usr/share/mppid/bridge/ardupilot_udp.yaml, which
the SITL's serial 0 reaches as a flight controller on Ethernet would (udpclient to 14550), and
the installed copter_mppid.parm loaded onto the autopilot.

Fixture folder /opt/ardupilot: `arducopter`, `copter.parm` (ArduPilot's SITL defaults of the
checkout it was built in), `guided_baseline.parm` (the README table's vehicle: loaded for mppid
too, so these flights are the table's), `vehicle.yaml` (config/vehicles/arducopter_sitl.yaml:
the operator's /etc/mppid/vehicle.yaml for this airframe) and `ap_truth.py` (the harness's
referee on serial 1: the SITL's truth, for tools/ardupilot/score_package_flights.py).

The kill flight (`circle_3ms:arducopter:kill`): mppid SIGKILLed in mid-circle and started again
1 s later (mppid.service's Restart=on-failure, RestartSec=1s); passes when the bridge
disengages, ArduCopter is put in BRAKE and holds its position and altitude, nothing of the new mppid is forwarded while
the mission tool keeps sending its circle, and only a new `offboard` (`mppid-mission hold`)
flies again.
"""
from __future__ import annotations

import json
import math
import signal
import subprocess
import time
from pathlib import Path

FIXTURE = Path("/opt/ardupilot")
# ArduPilot's SITL home (the autotest default, as tools/sitl_harness/flights/ardupilot.py).
HOME = "-35.363261,149.165230,584,353"
KILL_AFTER_S = 6.0      # into the circle leg
RESTART_S = 1.0         # mppid.service's RestartSec
WATCH_S = 12.0          # from the kill: the circle goes on in the mission tool meanwhile
HOLD_SPREAD_M = 0.5     # the position over the window's last 5 s: the vehicle holds
MIN_ALTITUDE_M = 1.0    # ... in the air (the circle flies at 2 m)


def start(st, out: Path):
    """The SITL (serial 0 to the bridge's UDP port, serial 1 to the referee) and the referee."""
    ap_dir = out / "ardupilot"
    ap_dir.mkdir(parents=True, exist_ok=True)
    defaults = ",".join(str(p) for p in (FIXTURE / "copter.parm",
                                         Path("/usr/share/mppid/autopilot/ardupilot/copter_mppid.parm"),
                                         FIXTURE / "guided_baseline.parm"))
    st.start("standin", ["sh", "-c", f'cd "{ap_dir}" && exec "$0" "$@"', str(FIXTURE / "arducopter"),
                         "--model", "quad", "--speedup", "1", "--home", HOME, "--defaults", defaults, "-I0",
                         "--wipe", "--serial0", "udpclient:127.0.0.1:14550"])
    st.start("referee", ["python3", str(FIXTURE / "ap_truth.py"), "--url", "tcp:127.0.0.1:5762",
                         f"--home={HOME}", "--out", str(out)],
             env={"PYTHONPATH": "/usr/lib/mppid/python", "MAVLINK20": "1"})


def _bridge(sock: str, *args) -> dict:
    r = subprocess.run(["mppid-mavlink-bridge", *args, "--socket", sock], capture_output=True, text=True, timeout=30)
    try:
        return json.loads(r.stdout)
    except ValueError:
        return {"rc": r.returncode, "text": (r.stdout + r.stderr).strip()}


def _leg_started(mission_log: Path, leg: int) -> bool:
    if not mission_log.exists():
        return False
    recs = (json.loads(line) for line in mission_log.read_text().splitlines() if line.strip())
    return any(r.get("event") == "step" and r.get("leg") == leg for r in recs)


def _truth_after(out: Path, t_wall: float) -> tuple[list, list]:
    """The referee's truth samples and mode events after wall time t_wall (s since the epoch)."""
    rows = [json.loads(line) for line in (out / "truth.jsonl").read_text().splitlines() if line.strip()]
    after = [r for r in rows if r.get("wall_us", 0) * 1e-6 >= t_wall]
    return [r for r in after if "x" in r], [r for r in after if r.get("event") == "mode"]


def fly_kill(st, name: str, out: Path, sock: str, mppid_cmd: list[str]) -> dict:
    """circle_3ms with mppid killed in mid-circle; what the bridge and ArduCopter did."""
    mission = subprocess.Popen(["mppid-mission", "fly", f"/usr/share/mppid/missions/{name}.yaml", "--bridge", sock,
                                "--out", str(out)], stdout=open(out.parent / f"mission-{name}-kill.log", "w"),
                               stderr=subprocess.STDOUT)
    deadline = time.monotonic() + 120
    while not _leg_started(out / "mission.jsonl", 1):
        if mission.poll() is not None or time.monotonic() > deadline:
            return {"ok": False, "why": f"the circle never started (mission rc {mission.poll()})"}
        time.sleep(0.2)
    time.sleep(KILL_AFTER_S)
    before = _bridge(sock, "status").get("status", {})
    t_kill = time.time()
    st.procs["mppid"].send_signal(signal.SIGKILL)
    st.procs["mppid"].wait()
    time.sleep(RESTART_S)
    st.start("mppid", mppid_cmd)
    time.sleep(WATCH_S - RESTART_S - 5.0)
    mid = _bridge(sock, "status").get("status", {})
    time.sleep(5.0)
    end = _bridge(sock, "status").get("status", {})
    mission.send_signal(signal.SIGINT)  # the operator stops the mission: it holds, never lands
    mission.wait(30)
    res = _kill_verdict(out, t_kill, before, mid, end)
    hold = subprocess.run(["mppid-mission", "hold", "--for", "5", "--bridge", sock, "--out", str(out / "after")],
                          capture_output=True, text=True, timeout=120)
    res["offboard_again"] = {"rc": hold.returncode, "engaged_after": _bridge(sock, "status").get("status", {}).get("engaged")}
    land = _bridge(sock, "land")
    res["land"] = land.get("text", land)
    res["ok"] = bool(res["ok"] and hold.returncode == 0)
    return res


def _kill_verdict(out: Path, t_kill: float, before: dict, mid: dict, end: dict) -> dict:
    truth, modes = _truth_after(out, t_kill)
    last = [r["x"] for r in truth if r["wall_us"] * 1e-6 >= t_kill + WATCH_S - 5.0]
    spread = max((math.dist(p, last[0]) for p in last), default=float("inf"))
    sent_before, sent_mid, sent_end = (s.get("setpoints_sent", 0) for s in (before, mid, end))
    res = {"engaged_before": before.get("engaged"), "engaged_after": end.get("engaged"),
           "disengaged_why": end.get("disengaged_why"), "mode_after": end.get("mode"),
           "modes_after_kill": [m.get("mode") for m in modes],
           "setpoints_sent": [sent_before, sent_mid, sent_end],
           "dropped_after_restart": {k: v for k, v in end.items() if k.startswith("dropped_") and v},
           "hold_spread_m": round(spread, 3)}
    res["lowest_m"] = round(min((r["x"][2] for r in truth), default=float("nan")), 3)
    res["ok"] = bool(before.get("engaged") and not end.get("engaged") and sent_mid == sent_end
                     and spread <= HOLD_SPREAD_M and res["lowest_m"] >= MIN_ALTITUDE_M and end.get("armed"))
    print(f"[package-flight] kill: {res}", flush=True)
    return res
