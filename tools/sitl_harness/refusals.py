"""`tools/sitl refusals --autopilot ardupilot|px4 [--out DIR]`: the missions mppid must refuse
(bad_missions.py) uploaded to a real autopilot's SITL, each read by `mppid-mission
from-autopilot` as a flight reads the survey, and what the autopilot itself says to its ground
station judged: the refusal's STATUSTEXT (the item's number and the reason), HEARTBEAT (never
armed, the mode unchanged), and the tool's exit status (1). Not a flight: nothing takes off.

The processes are a survey flight's through that autopilot (flights/ardupilot.py, flights/px4.py,
`--controller mppid`, config/missions/survey_forest_sensed.yaml), in a private network
namespace (sandbox.py): the SITL, mppid (the real daemon, CPU backend, answering on the bus as
in a flight, though the tool refuses before it needs it) and the bridge, with a 25 m geofence
(bad_missions.FENCE) for the mission that leaves it; not its logger, referee, sensors and mapper
(no trees, nothing flies). The flight's ground station is replaced by
this module's (`python -m sitl_harness.refusals OUT/plan.json`, in the namespace): on the
autopilot's ground-station link (ArduCopter's serial 2 on tcp 5763, PX4's udp 14550), for each
mission in turn, the upload (ap_gcs.upload; the empty one: MISSION_CLEAR_ALL), then the tool
(the flight's command line, its own --out), the autopilot's STATUSTEXT and HEARTBEAT read until
it has exited and a heartbeat after it has come; answers.json.

The harness then judges each (verdict), prints a markdown table and writes refusals.json; exit
0 only if every mission was refused as it should be. Not shown here: a mission changed while
it is read (the CI test's; docs/missions.md says why)."""
from __future__ import annotations

import json
import re
import subprocess
import sys
import time
from pathlib import Path

from .bad_missions import BAD, FENCE, BadMission

SCENARIO = "survey_forest_sensed"     # the flight whose processes these are
TOOL_TIMEOUT_S = 180.0                # the tool's: the SITL's estimator first (~30 s), then the download
AFTER_S = 2.0                         # read on this long after the tool's exit (the STATUSTEXT's chunks)
HEARTBEAT_WAIT_S = 5.0                # ... and until a heartbeat after it
GCS_TIMEOUT_S = 240.0 + len(BAD) * (TOOL_TIMEOUT_S + 15.0)


# ---- the plan of processes (the harness) ------------------------------------------------------
def plan(autopilot: str, out: Path, binary: str | None = None) -> dict:
    """The survey flight's processes for mppid through `autopilot` (its SITL, mppid, the bridge
    with the geofence), this module's ground station in place of the flight's, the tool's command
    line, the ground station's link and home (ArduPilot: the SITL's; PX4: its estimator's origin,
    found at run time)."""
    from .flights import flight_class
    from .flights.base import FlightSpec
    spec = FlightSpec(scenario=SCENARIO, out=out, realtime=True, autopilot=autopilot, controller="mppid",
                      ardupilot_bin=binary if autopilot == "ardupilot" else None,
                      px4_bin=binary if autopilot == "px4" else None)
    flight = flight_class(autopilot).create(spec)
    flight.out.mkdir(parents=True, exist_ok=True)
    cmds = flight.plan().commands
    gcs = cmds["gcs"]
    home = next((c.split("=", 1)[1] for c in gcs if c.startswith("--home=")), None)
    procs = {k: list(cmds[k]) for k in ("sim", "controller", "bridge")}
    procs["bridge"] += [a for kv in FENCE for a in ("--set", kv)]
    procs["gcs"] = [sys.executable, "-m", "sitl_harness.refusals", str(flight.out / "plan.json")]
    return {"autopilot": autopilot, "binary": str(flight.binary), "dialect": gcs[gcs.index("--dialect") + 1],
            "url": gcs[gcs.index("--url") + 1], "home": [float(v) for v in home.split(",")[:3]] if home else None,
            "tool": cmds["mission"], "commands": procs}


def tool_command(tool: list[str], out: Path) -> list[str]:
    """The flight's `mppid-mission from-autopilot` command line with its record in `out`."""
    cmd = list(tool)
    cmd[cmd.index("--out") + 1] = str(out)
    return cmd


# ---- the verdict (the harness) ----------------------------------------------------------------
def refusal_text(answer: dict) -> str:
    """The refusal the ground station was told (the longest STATUSTEXT saying so), else ''."""
    said = [t["text"] for t in answer.get("statustexts", []) if "refuses the mission" in t["text"]]
    return max(said, key=len, default="")


def verdict(bad: BadMission, answer: dict | None) -> dict:
    """One mission's row: what was said and seen, and whether it was refused as it should be:
    uploaded (MISSION_ACK accepted), the tool's exit 1, a refusal naming the item and a reason
    of `bad`'s, never armed, the mode after as before."""
    if answer is None:
        return {"mission": bad.name, "what": bad.what, "pass": False, "why": "not tried"}
    text = refusal_text(answer)
    found = re.search(r"item (\d+): ", text)
    item = int(found.group(1)) if found else None
    reason = next((r for r in bad.reason if r in text), "")
    armed = any(h["armed"] for h in answer.get("heartbeats", []))
    modes = [h["mode"] for h in answer.get("heartbeats", [])]
    before, after = answer.get("before", {}).get("mode"), modes[-1] if modes else None
    why = [w for w, bad_ in (
        (f"upload answered {answer.get('ack')}", answer.get("ack") != 0),
        (f"exit {answer.get('exit')}", answer.get("exit") != 1),
        ("no refusal on the ground station", not text),
        (f"item {item}, not {bad.number}", text and item != bad.number),
        ("not the reason expected", text and not reason),
        ("armed", armed),
        (f"mode {before} -> {sorted(set(modes))}", before is None or any(m != before for m in modes)),
        ("no heartbeat after the tool", after is None)) if bad_]
    return {"mission": bad.name, "what": bad.what, "item": item, "reason": reason, "said": text,
            "exit": answer.get("exit"), "armed": armed, "mode_before": before, "mode_after": after,
            "pass": not why, "why": "; ".join(why)}


def table(rows: list[dict]) -> str:
    """The verdicts as a markdown table."""
    lines = ["| mission | item | reason said | exit | armed? | mode before / after | pass |",
             "|---|---|---|---|---|---|---|"]
    for r in rows:
        said = r.get("reason") or (r.get("said") or "-")
        lines.append(f"| {r['mission']}: {r['what']} | {r.get('item') or '-'} | {said} | {r.get('exit', '-')} | "
                     f"{'yes' if r.get('armed') else 'no'} | {r.get('mode_before') or '-'} / "
                     f"{r.get('mode_after') or '-'} | {'yes' if r['pass'] else 'NO: ' + r['why']} |")
    return "\n".join(lines)


def commit(folder: Path) -> str | None:
    """The git commit checked out in `folder` (short), None when it is not a checkout."""
    r = subprocess.run(["git", "-C", str(folder), "rev-parse", "--short=10", "HEAD"], capture_output=True, text=True)
    return r.stdout.strip() if r.returncode == 0 else None


def provenance(autopilot: str, binary: str) -> dict:
    """What was run: the autopilot, its binary within its checkout (<checkout>/build/...) and
    the checkout's commit, and mppid's commit."""
    from . import paths
    checkout = Path(binary).parents[3]
    return {"autopilot": autopilot, "binary": str(Path(binary).relative_to(checkout)),
            "autopilot_commit": commit(checkout), "mppid_commit": commit(paths.ROOT)}


def report(p: dict, answers: dict, out: Path) -> tuple[list[dict], bool]:
    """The verdicts of `answers` (by mission name); refusals.json written."""
    rows = [verdict(b, answers.get(b.name)) for b in BAD]
    ok = all(r["pass"] for r in rows)
    doc = {**provenance(p["autopilot"], p["binary"]),
           "date_utc": time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime()),
           "all_refused": ok, "missions": rows, "answers": answers}
    (out / "refusals.json").write_text(json.dumps(doc, indent=1))
    return rows, ok


# ---- the run (the harness) --------------------------------------------------------------------
def run(autopilot: str, out: Path, binary: str | None = None, say=print) -> int:
    """Starts the processes, lets the ground station try every mission, judges; the exit status."""
    from .sandbox import Sandbox, SandboxError
    out = Path(out).resolve()
    p = plan(autopilot, out, binary)
    (out / "plan.json").write_text(json.dumps(p, indent=1))
    (out / "answers.json").unlink(missing_ok=True)
    sb = Sandbox(out)
    try:
        sb.start_namespace()
        for name in ("sim", "controller", "bridge", "gcs"):
            sb.spawn(name, p["commands"][name])
        died = _watch(sb)
    except SandboxError as e:
        died = str(e)
    finally:
        sb.stop()
    answers = json.loads((out / "answers.json").read_text()) if (out / "answers.json").is_file() else {}
    rows, ok = report(p, answers, out)
    say("{autopilot}: {binary} at {autopilot_commit}, mppid at {mppid_commit}".format(
        **json.loads((out / "refusals.json").read_text())))
    say(table(rows))
    if died:
        say(f"refusals: {died} (see {out}/*.log)")
    say(f"{'all refused' if ok and not died else 'NOT all refused'}: {out / 'refusals.json'}")
    return 0 if ok and not died else 1


def _watch(sb) -> str:
    """Until the ground station is done ('') or a process it needs died (which, said)."""
    t0 = time.monotonic()
    while sb.returncode("gcs") is None:
        for name in ("sim", "controller", "bridge"):
            if sb.returncode(name) is not None:
                return f"{name} exited rc={sb.returncode(name)}"
        if time.monotonic() - t0 > GCS_TIMEOUT_S:
            return f"the ground station not done in {GCS_TIMEOUT_S:g} s"
        time.sleep(0.2)
    rc = sb.returncode("gcs")
    return "" if rc == 0 else f"the ground station exited rc={rc}"


# ---- the ground station (in the namespace) ----------------------------------------------------
class Chunks:
    """STATUSTEXTs joined: MAVLink 2's pieces of one text (the same id, chunk_seq 0, 1, ...),
    the last shorter than 50 bytes; id 0 a whole text."""

    def __init__(self):
        self.parts = {}

    def add(self, source, text_id: int, chunk_seq: int, text: str) -> str | None:
        """The whole text once its last piece came; None before."""
        if text_id == 0:
            return text
        parts = self.parts.setdefault((source, text_id), {})
        parts[chunk_seq] = text
        if len(text.encode()) == 50:
            return None
        del self.parts[(source, text_id)]
        return "".join(parts[i] for i in sorted(parts))


class Gcs:
    """A ground station on the autopilot's link: its heartbeat once a second, the autopilot's
    HEARTBEAT (armed, mode) and every STATUSTEXT, chunks joined."""

    def __init__(self, url: str, timeout: float = 120.0):
        from pymavlink import mavutil
        self.mavutil = mavutil
        self.conn = mavutil.mavlink_connection(url, source_system=255, source_component=190, autoreconnect=True,
                                               retries=int(timeout))
        self.conn.wait_heartbeat(timeout=timeout)
        self.chunks, self.sent = Chunks(), 0.0
        self.last = None

    def _beat(self):
        if time.monotonic() - self.sent >= 1.0:
            M = self.mavutil.mavlink
            self.conn.mav.heartbeat_send(M.MAV_TYPE_GCS, M.MAV_AUTOPILOT_INVALID, 0, 0, 0)
            self.sent = time.monotonic()

    def read(self, until, timeout: float) -> dict:
        """Heartbeats and texts until `until()` or `timeout` s."""
        got = {"heartbeats": [], "statustexts": []}
        deadline = time.monotonic() + timeout
        while not until(got) and time.monotonic() < deadline:
            self._beat()
            m = self.conn.recv_match(type=["HEARTBEAT", "STATUSTEXT"], blocking=True, timeout=0.2)
            if m is None:
                continue
            if m.get_type() == "HEARTBEAT" and (m.get_srcSystem(), m.get_srcComponent()) == (1, 1):
                M = self.mavutil.mavlink
                self.last = {"armed": bool(m.base_mode & M.MAV_MODE_FLAG_SAFETY_ARMED),
                             "mode": self.mavutil.mode_string_v10(m), "wall": time.time()}
                got["heartbeats"].append(self.last)
            elif m.get_type() == "STATUSTEXT":
                text = self.chunks.add((m.get_srcSystem(), m.get_srcComponent()), getattr(m, "id", 0),
                                       getattr(m, "chunk_seq", 0), m.text)
                if text is not None:
                    got["statustexts"].append({"src": m.get_srcComponent(), "severity": m.severity, "text": text,
                                               "wall": time.time()})
        return got


def try_mission(gcs: Gcs, p: dict, bad: BadMission, home, out: Path) -> dict:
    """Uploads `bad` (or clears the mission), runs the tool, reads the autopilot until the tool
    has exited and a heartbeat after it came: the answer."""
    from .ap_gcs import clear, upload_when_ready
    from .bad_missions import mission
    gcs.read(lambda got: got["heartbeats"], 5.0)
    before = gcs.last
    ack = clear(gcs.conn) if bad.rows is None else upload_when_ready(gcs.conn, mission(p["dialect"], home, *bad.rows))
    folder = out / bad.name
    folder.mkdir(exist_ok=True)
    with open(folder / "tool.log", "w") as log:
        proc = subprocess.Popen(tool_command(p["tool"], folder), stdout=log, stderr=subprocess.STDOUT,
                                stdin=subprocess.DEVNULL)
        got = gcs.read(lambda _: proc.poll() is not None, TOOL_TIMEOUT_S)
        if proc.poll() is None:
            proc.terminate()
            proc.wait(timeout=10)
    t_exit = time.time()
    after = gcs.read(lambda g: any(h["wall"] > t_exit + AFTER_S for h in g["heartbeats"]), AFTER_S + HEARTBEAT_WAIT_S)
    tail = (folder / "tool.log").read_text(errors="replace").strip().splitlines()[-3:]
    return {"ack": ack, "exit": proc.returncode, "before": before, "tool_said": tail,
            "heartbeats": got["heartbeats"] + after["heartbeats"],
            "statustexts": got["statustexts"] + after["statustexts"]}


def ground_station(plan_path: Path) -> int:
    """Every mission of BAD in turn on the autopilot's link; answers.json after each."""
    from .ap_gcs import origin_of
    plan_path = Path(plan_path)
    p, out = json.loads(plan_path.read_text()), plan_path.parent
    gcs = Gcs(p["url"])
    origin = origin_of(gcs.conn)            # the estimator has its origin: the bridge's states flow
    home = p["home"] or origin               # PX4: positions about the origin, as ap_gcs.py places them
    print(f"[gcs] {p['autopilot']} up, origin {origin}", flush=True)
    answers = {}
    for bad in BAD:
        answers[bad.name] = try_mission(gcs, p, bad, home, out)
        print(f"[gcs] {bad.name}: exit {answers[bad.name]['exit']}", flush=True)
        (out / "answers.json").write_text(json.dumps(answers, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(ground_station(Path(sys.argv[1])))
