"""Missions planned in a ground station (docs/missions.md): a ground station uploads a mission
to the simulated autopilot as QGroundControl does (pymavlink's mavwp and the upload handshake,
straight to the autopilot through the UDP tap), the bridge reads it over its own link
(`mission download`), and `mppid-mission from-autopilot` refuses it or flies it, mppid stood in
for by a controller that follows the reference (linktools.TrackingController)."""
import json
import math
import os
import subprocess
import time

import pytest

os.environ.setdefault("MAVLINK20", "1")
from pymavlink import mavutil, mavwp  # noqa: E402

from mavtest import PYTHON, ROOT, wait_for  # noqa: E402
from linktools import ARDUPILOT, StandInController, TrackingController  # noqa: E402
from mavchain import tapped_chain  # noqa: E402
from mavlink_vehicle.missions import HOME  # noqa: E402
from mppi_mission import autopilot_plan  # noqa: E402
from sitl_harness import bad_missions  # noqa: E402
from sitl_harness.bad_missions import BAD, FENCE  # noqa: E402

pytestmark = pytest.mark.timeout(120)
M = mavutil.mavlink
TAP_PORT = 14566


def mission(dialect, *rows):
    """Items numbered from the dialect's first (ArduPilot: home first, as item 0), as the
    harness's ground station writes them (sitl_harness.bad_missions)."""
    return bad_missions.mission(dialect, HOME, *rows)


class Gcs:
    """A ground station on the autopilot's link (system 255): uploads through the tap and reads
    the autopilot's answers from what the tap carried."""

    def __init__(self, tap):
        self.tap, self.seen = tap, 0
        self.mav = M.MAVLink(None, srcSystem=255, srcComponent=190)
        self.parser = M.MAVLink(None)
        self.parser.robust_parsing = True

    def send(self, msg):
        self.tap.a.sendto(msg.pack(self.mav), self.tap.vehicle)

    def _new(self):
        log, out = self.tap.log, []
        for _, d, data in log[self.seen:]:
            if d == "up":
                out += [m for m in self.parser.parse_buffer(data) or [] if getattr(m, "target_system", 0) == 255]
        self.seen = len(log)
        return out

    def upload(self, items, timeout=10.0) -> int:
        wp = mavwp.MAVWPLoader(target_system=1, target_component=1)
        for m in items:
            wp.add(m)
        self._new()
        self.send(M.MAVLink_mission_count_message(1, 1, wp.count(), M.MAV_MISSION_TYPE_MISSION))
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            for m in self._new():
                if m.get_type() in ("MISSION_REQUEST_INT", "MISSION_REQUEST"):
                    self.send(wp.wp(m.seq))
                elif m.get_type() == "MISSION_ACK":
                    return m.type
            time.sleep(0.01)
        raise AssertionError("the upload was never acknowledged")

    def clear(self):
        self.send(M.MAVLink_mission_clear_all_message(1, 1, M.MAV_MISSION_TYPE_MISSION))

    def param(self, name, value):
        self.send(M.MAVLink_param_set_message(1, 1, name.encode(), value, M.MAV_PARAM_TYPE_REAL32))


def _chain(procs, tmp_path, dialect, bridge_sets=(), vehicle_params=()):
    kw = dict(ARDUPILOT) if dialect == "ardupilot" else {"autopilot": "px4", "vehicle_params": []}
    kw["vehicle_params"] = kw["vehicle_params"] + list(vehicle_params)
    return tapped_chain(procs, tmp_path, TAP_PORT, bridge_sets, **kw)


def tool(c, out, wait=True, extra=()):
    cmd = [PYTHON, "-m", "mppi_mission", "from-autopilot", "--bridge", c.sock, "--lcm-url",
           "udpm://239.255.76.67:7667?ttl=0", "--out", str(out), *extra]
    p = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True, cwd=ROOT)
    if not wait:
        return p
    text = p.communicate(timeout=90)[0]
    print(text[-3000:])
    return p.returncode, text


def texts(c, since=0.0):
    """The bridge's STATUSTEXTs as the autopilot passed them on (component 191), after `since` (s)."""
    return [e["text"] for e in c.events("statustext") if e.get("src") == 191 and e["t"] >= since]


def seqs(c, event):
    return [e["seq"] for e in c.events(event) if e.get("src", 191) == 191]


# ---- download -------------------------------------------------------------------------------
@pytest.mark.parametrize("dialect", ["px4", "ardupilot"])
def test_the_bridge_reads_the_mission_the_ground_station_uploaded(netns, procs, tmp_path, tap, dialect):
    """Items and frames come back as uploaded; the answer for item 2, lost once, is asked for
    again; home and origin come with them, so the waypoints land where they were planned."""
    c = _chain(procs, tmp_path, dialect, vehicle_params=["SIM_MIS_DROP=2"])
    items = mission(dialect, (M.MAV_CMD_NAV_TAKEOFF, 0, 0, 2.5), (M.MAV_CMD_NAV_WAYPOINT, 6.0, 0.0, 3.0, (1, 2, 0, 0)),
                    (M.MAV_CMD_NAV_WAYPOINT, 6.0, -4.0, HOME[2] + 4.0, {"frame": M.MAV_FRAME_GLOBAL_INT}),
                    (M.MAV_CMD_DO_CHANGE_SPEED, 0, 0, 0, (1, 3, -1, 0), {"frame": M.MAV_FRAME_MISSION}),
                    (M.MAV_CMD_NAV_LAND,))
    assert Gcs(tap).upload(items) == M.MAV_MISSION_ACCEPTED
    r = c.ctl("mission download")
    assert r["ok"], r
    got = r["mission"]["items"]
    assert len(got) == len(items)
    for sent, read in zip(items, got):
        for k in ("seq", "frame", "command", "x", "y", "param1", "param2", "param3", "param4"):
            assert read[k] == pytest.approx(getattr(sent, k)), (k, sent, read)
        assert read["z"] == pytest.approx(sent.z)
    asked = [m.seq for _, m in tap.decoded("down") if m.get_type() == "MISSION_REQUEST_INT"]
    assert asked.count(2) >= 2 and sorted(set(asked)) == list(range(len(items))), asked
    assert c.events("mission_item_dropped")
    assert any(m.get_type() == "MISSION_ACK" for _, m in tap.decoded("down"))
    conv = autopilot_plan.convert(r["mission"], here=[0.0, 0.0, 0.0])
    lines = [leg["line"]["to"] for leg in conv.mission.legs if "line" in leg]
    assert lines[0] == pytest.approx([6.0, 0.0, 3.0], abs=0.02)
    assert lines[1] == pytest.approx([6.0, -4.0, 4.0], abs=0.02)
    assert conv.mission.takeoff == pytest.approx(2.5)


# ---- refusals -------------------------------------------------------------------------------
# The missions refused (sitl_harness/bad_missions.py): the same as `tools/sitl refusals` uploads to
# the real autopilots' SITL (bench/results/issue38_refusals).


def _assert_refused(c, tap, rc, out, words, number, t0):
    assert rc == 1, out
    words = (words,) if isinstance(words, str) else words     # any one of them
    said = [t for t in texts(c, t0) if "refuses the mission" in t]
    assert said and any(w in said[-1] for w in words), (said, texts(c))
    if number is not None:
        assert f"item {number}: " in said[-1], said[-1]
    assert any(w in c.procs.log("bridge") for w in words)            # the bridge's log line
    # Nothing asked of the autopilot but the messages it streams, home and origin: no arming,
    # no take-off, no mode; no setpoint on the wire (PX4: pre-streamed, as always before
    # `offboard`, and never flown: the vehicle never left its mode).
    asked = [r["command"] for r in c.wire() if r["type"] == "COMMAND_LONG"]
    assert set(asked) <= {M.MAV_CMD_SET_MESSAGE_INTERVAL, M.MAV_CMD_REQUEST_MESSAGE}, asked
    assert not c.events("armed") and not c.events("mode") and c.status()["engagement"] != "engaged"
    if c.autopilot == "ardupilot":
        assert tap.setpoints() == [], "a refused mission was flown"


@pytest.mark.parametrize("dialect", ["px4", "ardupilot"])
def test_a_mission_mppid_cannot_fly_is_refused_before_anything_flies(netns, procs, tmp_path, tap, dialect):
    """Each refused before arming, the item's number and the reason on the ground station
    (STATUSTEXT) and in the bridge's log; no setpoint on the wire."""
    ctl = StandInController()
    c = _chain(procs, tmp_path, dialect, bridge_sets=FENCE)
    gcs = Gcs(tap)
    try:
        for bad in BAD:
            if bad.rows is None:
                gcs.clear()
                wait_for(lambda: c.events("mission_cleared"), 5, "the mission cleared")
            else:
                assert gcs.upload(mission(dialect, *bad.rows)) == M.MAV_MISSION_ACCEPTED
            t0 = c.events()[-1]["t"] if c.events() else 0.0
            rc, out = tool(c, tmp_path / bad.name)
            _assert_refused(c, tap, rc, out, bad.reason, bad.number, t0)
    finally:
        ctl.close()


def test_a_mission_changed_while_it_is_read_is_refused(netns, procs, tmp_path, tap):
    """The ground station uploads another mission while the bridge waits for a lost item: the
    new total in MISSION_CURRENT ends the download, and nothing is flown."""
    ctl = StandInController()
    c = _chain(procs, tmp_path, "ardupilot", vehicle_params=["SIM_MIS_DROP=2", "SIM_MIS_DROP_N=4"])
    gcs = Gcs(tap)
    try:
        rows = [(M.MAV_CMD_NAV_TAKEOFF, 0, 0, 2.0), (M.MAV_CMD_NAV_WAYPOINT, 4.0, 0.0, 2.0),
                (M.MAV_CMD_NAV_WAYPOINT, 4.0, 4.0, 2.0)]
        assert gcs.upload(mission("ardupilot", *rows)) == M.MAV_MISSION_ACCEPTED
        p = tool(c, tmp_path / "changed", wait=False)
        wait_for(lambda: c.events("mission_item_dropped"), 20, "the bridge to ask for the item lost")
        assert gcs.upload(mission("ardupilot", *rows[:2])) == M.MAV_MISSION_ACCEPTED
        out = p.communicate(timeout=60)[0]
        _assert_refused(c, tap, p.returncode, out, "changed while it was read", None, 0.0)
    finally:
        ctl.close()


# ---- flights --------------------------------------------------------------------------------
def _summary(out):
    return json.loads((out / "mission_summary.json").read_text())


def test_a_downloaded_mission_is_flown_to_its_end(netns, procs, tmp_path, tap, dialect="px4"):
    """PX4 (OFFBOARD): take-off, two waypoints (a speed change between them, a hold at the
    second), return to launch: the autopilot's current item follows (MISSION_SET_CURRENT), each
    item is reached (MISSION_ITEM_REACHED) and told (STATUSTEXT); at the NAV_RETURN_TO_LAUNCH
    the vehicle is handed back to PX4's own AUTO.RTL, which lands it at home. ArduPilot
    (GUIDED) flies its missions to their end, landing, in the tests below."""
    ctl = TrackingController()
    c = _chain(procs, tmp_path, dialect)
    first = 0
    try:
        items = mission(dialect, (M.MAV_CMD_NAV_TAKEOFF, 0, 0, 2.0), (M.MAV_CMD_NAV_WAYPOINT, 4.0, 0.0, 2.0),
                        (M.MAV_CMD_DO_CHANGE_SPEED, 0, 0, 0, (1, 3, -1, 0), {"frame": M.MAV_FRAME_MISSION}),
                        (M.MAV_CMD_NAV_WAYPOINT, 4.0, 4.0, 2.5, (1, 0.5, 0, 0)),
                        (M.MAV_CMD_NAV_RETURN_TO_LAUNCH, {"frame": M.MAV_FRAME_MISSION}))
        assert Gcs(tap).upload(items) == M.MAV_MISSION_ACCEPTED
        rc, out = tool(c, tmp_path / "fly")
        assert rc == 0 and _summary(tmp_path / "fly")["outcome"] == "done", out
        assert seqs(c, "mission_item_reached") == [first, first + 1, first + 3]
        assert seqs(c, "mission_set_current") == [first + 1, first + 3]
        said = texts(c)
        assert any(f"item 2 NAV_WAYPOINT" in t for t in said) and any("item 4 NAV_WAYPOINT" in t for t in said)
        assert any("item 5 NAV_RETURN_TO_LAUNCH: the autopilot's own" in t for t in said), said
        c.wait_event("landed", 20)
        assert [e["mode"] for e in c.events("mode")][-2:] == ["OFFBOARD", "AUTO.RTL"]
        x = c.stop_vehicle()["final_state"]
        assert abs(x[0]) < 0.6 and abs(x[1]) < 0.6, x[:3]                   # PX4's own return: home
    finally:
        ctl.close()


def _fly_until(procs, tmp_path, tap, seq, what, *extra_waypoints):
    """ArduPilot: take-off, waypoints (3, 0) and (6, 0), `extra_waypoints`, land uploaded by a
    ground station; the tool flying it until the autopilot's current item is `seq`."""
    c = _chain(procs, tmp_path, "ardupilot")
    gcs = Gcs(tap)
    assert gcs.upload(mission("ardupilot", (M.MAV_CMD_NAV_TAKEOFF, 0, 0, 2.0),
                              (M.MAV_CMD_NAV_WAYPOINT, 3.0, 0.0, 2.0), (M.MAV_CMD_NAV_WAYPOINT, 6.0, 0.0, 2.0),
                              *extra_waypoints, (M.MAV_CMD_NAV_LAND,))) == 0
    p = tool(c, tmp_path / "fly", wait=False)
    wait_for(lambda: seq in seqs(c, "mission_set_current"), 60, what)
    return c, gcs, p


def test_a_mission_changed_in_flight_is_read_again_and_flown(netns, procs, tmp_path, tap):
    """ArduPilot: while the second waypoint is flown the ground station uploads a shorter
    mission: at the end of that leg it is read again and flown from the autopilot's current
    item (the first after an upload), the take-off skipped in the air, to its return to launch,
    which is ArduPilot's own: AUTO from that item (MISSION_SET_CURRENT, then the mode) flies
    home and lands."""
    ctl = TrackingController()
    try:
        c, gcs, p = _fly_until(procs, tmp_path, tap, 3, "the second waypoint flown",
                               (M.MAV_CMD_NAV_WAYPOINT, 6.0, 3.0, 2.0))
        assert gcs.upload(mission("ardupilot", (M.MAV_CMD_NAV_TAKEOFF, 0, 0, 2.0),
                                  (M.MAV_CMD_NAV_WAYPOINT, 0.0, 3.0, 2.0),
                                  (M.MAV_CMD_NAV_RETURN_TO_LAUNCH, {"frame": M.MAV_FRAME_MISSION}))) == 0
        out = p.communicate(timeout=90)[0]
        s = _summary(tmp_path / "fly")
        assert p.returncode == 0 and s["outcome"] == "done" and s["reloads"] == 1, out
        assert seqs(c, "mission_item_reached")[-1] == 2           # the new mission's waypoint
        assert 4 not in seqs(c, "mission_set_current")            # the old mission's third waypoint never flown
        assert seqs(c, "mission_set_current")[-1] == 3            # the hand-back: AUTO from the RTL item
        c.wait_event("landed", 20)
        assert [e["seq"] for e in c.events("mission_item_reached") if e["src"] == 1] == [3]   # AUTO's own RTL
        assert [e["mode"] for e in c.events("mode")] == ["GUIDED", "AUTO"]
        x = c.stop_vehicle()["final_state"]
        assert abs(x[0]) < 0.6 and abs(x[1]) < 0.6, x[:3]                   # home
    finally:
        ctl.close()


def test_a_mission_changed_in_flight_to_one_refused_holds(netns, procs, tmp_path, tap):
    """The new mission has an item mppid cannot fly: refused (named on the ground station),
    mppid holds where the vehicle is, nothing lands, the vehicle stays with mppid."""
    ctl = TrackingController()
    try:
        c, gcs, p = _fly_until(procs, tmp_path, tap, 2, "the first waypoint flown")
        assert gcs.upload(mission("ardupilot", (M.MAV_CMD_NAV_TAKEOFF, 0, 0, 2.0),
                                  (M.MAV_CMD_NAV_SPLINE_WAYPOINT, 0.0, 3.0, 2.0))) == 0
        out = p.communicate(timeout=60)[0]
        s = _summary(tmp_path / "fly")
        assert p.returncode == 1 and "item 2: NAV_SPLINE_WAYPOINT" in s["refused"], out
        assert any("item 2: NAV_SPLINE_WAYPOINT" in t and "holding" in t for t in texts(c))
        st = c.status()
        assert st["armed"] and st["engaged"] and st["mode"] == "GUIDED" and not c.events("landed")
        ref, _ = ctl.ref
        # Where it was: at the first waypoint, within the acceptance radius that ended the leg.
        assert ref["kind"] == "hold" and 1.5 < ref["center"][0] < 3.5 and abs(ref["center"][1]) < 0.3, ref
        # Held in the air: the vehicle, brought to rest from the leg's speed, stays at the hold.
        wait_for(lambda: math.hypot(*ctl.last_x[3:6]) < 0.1 and math.dist(ctl.last_x[:3], ref["center"]) < 0.2,
                 15, "the vehicle at rest at the hold")
        for _ in range(10):
            assert math.dist(ctl.last_x[:3], ref["center"]) < 0.3 and ctl.last_x[2] > 1.5, (ctl.last_x[:3], ref)
            time.sleep(0.1)
        assert c.status()["mode"] == "GUIDED" and not c.events("landed")
    finally:
        ctl.close()


def test_the_operator_starts_it_by_arming_and_takes_it_back_with_a_mode_switch(netns, procs, tmp_path, tap):
    """From the ground station alone: `from-autopilot --wait-armed` (as a unit would run it)
    does nothing until the operator arms; then it reads the mission and flies it. The
    operator's switch to LOITER in flight ends it at once: nothing landed, the mode kept."""
    ctl = TrackingController()
    c = _chain(procs, tmp_path, "ardupilot", vehicle_params=["SIM_RC_THROTTLE=0.5"])
    gcs = Gcs(tap)
    try:
        assert gcs.upload(mission("ardupilot", (M.MAV_CMD_NAV_TAKEOFF, 0, 0, 2.0),
                                  (M.MAV_CMD_NAV_WAYPOINT, 6.0, 0.0, 2.0), (M.MAV_CMD_NAV_WAYPOINT, 6.0, 6.0, 2.0),
                                  (M.MAV_CMD_NAV_LAND,))) == 0
        p = tool(c, tmp_path / "fly", wait=False, extra=["--wait-armed"])
        lines = []
        while not any("waiting for the vehicle to be armed" in x for x in lines):
            lines.append(p.stdout.readline())
            assert lines[-1], "".join(lines)
        assert not [r for r in c.wire() if r["type"] == "COMMAND_LONG"
                    and r["command"] != M.MAV_CMD_SET_MESSAGE_INTERVAL], "the tool asked before the arming"
        gcs.send(M.MAVLink_command_long_message(1, 1, M.MAV_CMD_COMPONENT_ARM_DISARM, 0, 1, 0, 0, 0, 0, 0, 0))
        wait_for(lambda: 2 in seqs(c, "mission_set_current"), 60, "the first waypoint flown")
        gcs.send(M.MAVLink_command_long_message(1, 1, M.MAV_CMD_DO_SET_MODE, 0,
                                                M.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED, 5, 0, 0, 0, 0, 0))   # LOITER
        out = "".join(lines) + p.communicate(timeout=30)[0]
        s = _summary(tmp_path / "fly")
        assert p.returncode == 1 and s["outcome"].startswith("stopped at item 2: mppid disengaged"), out
        assert [e["mode"] for e in c.events("mode")] == ["GUIDED", "LOITER"] and c.status()["mode"] == "LOITER"
        assert 3 not in seqs(c, "mission_set_current")
        assert any("mission stopped at item 2" in t for t in texts(c))
    finally:
        ctl.close()


# ---- ArduCopter's guided segments inside AUTO -----------------------------------------------
def _command(gcs, cmd, *params):
    gcs.send(M.MAVLink_command_long_message(1, 1, cmd, 0, *(list(params) + [0] * (7 - len(params)))))


def _set_mode(gcs, custom_mode):
    _command(gcs, M.MAV_CMD_DO_SET_MODE, M.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED, custom_mode)


def test_guided_segments_inside_auto_are_flown_by_mppid_and_auto_goes_on(netns, procs, tmp_path, tap):
    """ArduCopter: the operator flies the mission in AUTO. At the first NAV_GUIDED_ENABLE mppid
    engages without a mode change, flies the segment's waypoint and hands back (MISSION_SET_
    CURRENT to the NAV_GUIDED_ENABLE 0); AUTO flies the rest itself (its own MISSION_ITEM_
    REACHED). In the second segment mppid goes quiet: the bridge lets go (the vehicle stays in
    AUTO), GUID_TIMEOUT levels the vehicle, the guided limit's timeout ends the segment and AUTO
    flies on from the item after it, as ArduCopter does, to the landing."""
    ctl = TrackingController()
    c = _chain(procs, tmp_path, "ardupilot", vehicle_params=["GUID_TIMEOUT=1"])
    gcs = Gcs(tap)
    ge, mis = M.MAV_CMD_NAV_GUIDED_ENABLE, {"frame": M.MAV_FRAME_MISSION}
    wp = M.MAV_CMD_NAV_WAYPOINT
    try:
        assert gcs.upload(mission("ardupilot", (M.MAV_CMD_NAV_TAKEOFF, 0, 0, 2.0), (wp, 2.0, 0.0, 2.0),   # 1, 2
                                  (ge, 0, 0, 0, (1, 0, 0, 0), mis), (wp, 2.0, 2.0, 2.0),                  # 3, 4
                                  (ge, 0, 0, 0, (0, 0, 0, 0), mis), (wp, 0.0, 2.0, 2.0),                  # 5, 6
                                  (M.MAV_CMD_DO_GUIDED_LIMITS, 0, 0, 0, (4, 0, 0, 0), mis),               # 7
                                  (ge, 0, 0, 0, (1, 0, 0, 0), mis), (wp, 0.0, 5.0, 2.0),                  # 8, 9
                                  (ge, 0, 0, 0, (0, 0, 0, 0), mis), (M.MAV_CMD_NAV_LAND,))) == 0          # 10, 11
        p = tool(c, tmp_path / "fly", wait=False, extra=["--speed", "3"])
        _set_mode(gcs, 4)                                                   # the operator: GUIDED, arm, take off
        wait_for(lambda: c.status().get("mode") == "GUIDED", 5, "GUIDED")
        _command(gcs, M.MAV_CMD_COMPONENT_ARM_DISARM, 1)
        wait_for(lambda: c.status().get("armed"), 5, "armed")
        _command(gcs, M.MAV_CMD_NAV_TAKEOFF, 0, 0, 0, 0, 0, 0, 2.0)
        c.wait_event("takeoff_complete", 20)
        r = c.ctl("segment")                                                # only in AUTO at a NAV_GUIDED_ENABLE
        assert not r["ok"] and "the vehicle is in GUIDED, not AUTO" in r["message"], r
        _set_mode(gcs, 3)                                                   # then AUTO
        wait_for(lambda: len(c.events("guided_segment")) == 2 and c.status().get("engagement") == "engaged", 40,
                 "mppid engaged in the second segment")
        time.sleep(0.3)
        ctl.answer = False                                                  # mppid goes quiet
        out = p.communicate(timeout=60)[0]
        c.wait_event("landed", 30)
        s1 = _summary(tmp_path / "fly" / "segment_3")
        s2 = _summary(tmp_path / "fly" / "segment_8")
        assert p.returncode == 1 and s1["outcome"] == "done", out
        assert s2["outcome"].startswith("stopped at item 9: mppid disengaged"), s2
        own = [e["seq"] for e in c.events("mission_item_reached") if e["src"] == 1]
        assert own == [1, 2, 5, 6, 8, 9, 10, 11], own                       # AUTO's own (9: after the limit)
        assert seqs(c, "mission_item_reached") == [4]                       # mppid's: the segment's waypoint
        assert seqs(c, "mission_set_current") == [5]                        # mppid's hand-back
        assert [e["mode"] for e in c.events("mode")] == ["GUIDED", "AUTO"]  # no mode change by mppid
        (to,) = c.events("guided_timeout")
        (limit,) = c.events("guided_limit")
        g2 = c.events("guided_segment")[1]
        # Never early; late by at most a stalled step of the stand-in's clock on a busy machine.
        assert to["seq"] == 8 and 1.0 <= to["since_target_s"] < 1.5 and abs(to["z"] - 2.0) < 0.3, to
        assert limit["seq"] == 8 and 4.0 <= limit["t"] - g2["t"] < 4.5, (limit, g2)
        assert any("guided segment" in t or "item 4 NAV_WAYPOINT" in t for t in texts(c))
        x = c.stop_vehicle()["final_state"]
        assert math.hypot(x[0], x[1] - 5.0) < 1.1, x[:3]                    # AUTO flew item 9 (1 m radius), landed
    finally:
        ctl.close()
