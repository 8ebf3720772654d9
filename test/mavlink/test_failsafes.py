"""Failsafes as PX4 and ArduPilot users expect them (docs/failsafes.md), against the simulated
autopilot through a UDP tap that keeps every datagram; mppid stood in for by a controller
that answers each state (linktools.py).

The silent re-takeover: once engaged, mppid's setpoints stopping for any reason (mppid
killed or restarted, the link to the autopilot lost and back, the states stopping) ends the
engagement; nothing reaches the autopilot again until a new `offboard`, whatever comes back,
and the operator is told (the bridge's log, and a STATUSTEXT to the ground station)."""
import os
import threading
import time

import pytest

os.environ.setdefault("MAVLINK20", "1")
from pymavlink import mavutil  # noqa: E402

from mavtest import wait_for  # noqa: E402
from linktools import ARDUPILOT, StandInController  # noqa: E402
from mavchain import Chain, tapped_chain  # noqa: E402

pytestmark = pytest.mark.timeout(90)
mavlink = mavutil.mavlink
TAP_PORT = 14562


def _chain(procs, tmp_path, bridge_sets=(), **kw):
    return tapped_chain(procs, tmp_path, TAP_PORT, bridge_sets, **kw)


def _gcs(tap, command, *params):
    """A ground station's COMMAND_LONG, straight to the autopilot (not through the bridge)."""
    gcs = mavlink.MAVLink(None, srcSystem=255, srcComponent=190)
    p = list(params) + [0.0] * (7 - len(params))
    tap.a.sendto(gcs.command_long_encode(1, 1, command, 0, *p).pack(gcs), tap.vehicle)


def _statustexts(tap, since=0):
    """The bridge's STATUSTEXTs on the link (component 191), chunks joined."""
    out, parts = [], {}
    for t, m in tap.decoded("down"):
        if m.get_type() != "STATUSTEXT" or t < since or m.get_srcComponent() != 191:
            continue
        text = m.text if isinstance(m.text, str) else m.text.decode(errors="replace")
        text = text.rstrip("\x00")
        if getattr(m, "id", 0):
            parts.setdefault(m.id, []).append(text)
            if len(text) == 50:
                continue
            text = "".join(parts.pop(m.id))
        out.append((m.severity, text))
    return out


def _between(tap, t0, t1):
    return [t for t, _ in tap.setpoints() if t0 < t < t1]


def _engage(c, tap):
    msg = c.ok("offboard")
    n = len(tap.setpoints())
    wait_for(lambda: len(tap.setpoints()) > n + 25, 5, "setpoints after offboard")
    assert c.status()["engaged"]
    return msg


def _assert_not_reengaged(c, tap, t_back, what):
    """From t_back (what came back) on, nothing on the wire; disengaged, the operator told;
    a new `offboard` is what flies again."""
    time.sleep(2.0)
    st = c.status()
    late = _between(tap, t_back, time.monotonic_ns() // 1000)
    assert late == [], f"{len(late)} setpoints after {what} came back: a re-takeover without `offboard`"
    assert st["engaged"] is False, st
    assert "`offboard`" in c.procs.log("bridge")
    texts = [t for _, t in _statustexts(tap)]
    assert any("disengaged" in t for t in texts), texts
    t_offboard = time.monotonic_ns() // 1000
    _engage(c, tap)
    assert _between(tap, t_offboard, time.monotonic_ns() // 1000)


def test_mppid_restart_never_reengages(netns, procs, tmp_path, tap):
    """ArduPilot, engaged in GUIDED: mppid killed and back 1.5 s later (its seq from 1): the
    bridge disengaged when the stream stopped, hands the vehicle to BRAKE (GUIDED would only
    level and drift), and forwards nothing of the new mppid until `offboard`."""
    ctl = StandInController()
    c = _chain(procs, tmp_path, **ARDUPILOT)
    try:
        _engage(c, tap)
        ctl.close()                       # mppid dies
        wait_for(lambda: c.status().get("engaged") is False, 10, "the bridge to disengage")
        assert "stopped" in c.status()["disengaged_why"]
        wait_for(lambda: c.status().get("mode") == "BRAKE", 5, "the hand-back to BRAKE")
        time.sleep(1.0)
        ctl = StandInController()         # mppid restarted (systemd: Restart=on-failure)
        t_back = time.monotonic_ns() // 1000
        wait_for(lambda: ctl.seq > 50, 5, "the new mppid's commands")
        _assert_not_reengaged(c, tap, t_back, "mppid")
    finally:
        ctl.close()


def test_hand_back_holds_altitude_whatever_the_throttle_stick(netns, procs, tmp_path, tap):
    """ArduPilot, in the air and engaged, its throttle stick low (SIM_RC_THROTTLE 0: no RC, as
    ArduCopter SITL): mppid dies; the vehicle handed back must hold its altitude. LOITER reads
    the stick as a climb rate and sinks (ArduCopter SITL hit the ground 1.7 s after a LOITER
    hand-back at 2 m: docs/ardupilot.md); BRAKE holds whatever the sticks say."""
    ctl = StandInController()
    c = _chain(procs, tmp_path, **ARDUPILOT)
    try:
        c.ok("arm")
        c.ok("takeoff 2")
        _engage(c, tap)
        ctl.close()                       # mppid dies
        wait_for(lambda: c.status().get("engaged") is False, 10, "the bridge to disengage")
        wait_for(lambda: c.status().get("mode") not in ("GUIDED", None), 5, "the hand-back")
        watch = StandInController()
        watch.answer = False
        wait_for(lambda: watch.last_x is not None, 10, "states")
        z0, zs = watch.last_x[2], []
        for _ in range(30):               # 3 s in the hand-back's mode
            time.sleep(0.1)
            zs.append(watch.last_x[2])
        watch.close()
        assert z0 > 1.0, f"not in the air at the hand-back: z {z0:.2f} m"
        assert max(abs(z - z0) for z in zs) < 0.3, (
            f"{c.status().get('mode')}: altitude {z0:.2f} m -> {zs[-1]:.2f} m in 3 s after the hand-back")
    finally:
        ctl.close()


def test_link_back_never_reengages(netns, procs, tmp_path, tap):
    """ArduPilot, engaged: the link cut for 3 s and restored: no setpoint after it returns;
    the bridge disengaged and, the link back, hands the vehicle to BRAKE."""
    ctl = StandInController()
    c = _chain(procs, tmp_path, **ARDUPILOT)
    try:
        _engage(c, tap)
        tap.cut = True
        wait_for(lambda: c.status().get("link_up") is False, 5, "the link loss")
        assert c.status()["engaged"] is False
        time.sleep(1.0)
        tap.cut = False
        t_back = time.monotonic_ns() // 1000
        wait_for(lambda: c.status().get("link_up"), 5, "the link back")
        wait_for(lambda: c.status().get("mode") == "BRAKE", 5, "the hand-back to BRAKE")
        _assert_not_reengaged(c, tap, t_back, "the link")
    finally:
        ctl.close()


def test_states_that_stop_never_reengage(netns, procs, tmp_path, tap):
    """ArduPilot, engaged: a ground station stops ATTITUDE_QUATERNION for 1.5 s (no states, so
    no fresh commands), then restarts it: nothing is forwarded when the states return."""
    ctl = StandInController()
    c = _chain(procs, tmp_path, **ARDUPILOT)
    try:
        _engage(c, tap)
        _gcs(tap, mavlink.MAV_CMD_SET_MESSAGE_INTERVAL, mavlink.MAVLINK_MSG_ID_ATTITUDE_QUATERNION, -1)
        wait_for(lambda: c.status().get("engaged") is False, 10, "the bridge to disengage")
        time.sleep(1.0)
        _gcs(tap, mavlink.MAV_CMD_SET_MESSAGE_INTERVAL, mavlink.MAVLINK_MSG_ID_ATTITUDE_QUATERNION, 20000)
        t_back = time.monotonic_ns() // 1000
        wait_for(lambda: not c.status().get("refusal") and c.status().get("state_rate_hz", 0) > 40, 5, "states back")
        _assert_not_reengaged(c, tap, t_back, "the states")
    finally:
        ctl.close()


def test_px4_pause_in_offboard_never_reengages(netns, procs, tmp_path, tap):
    """PX4 with COM_OF_LOSS_T 5 s: mppid silent until the bridge disengages, then answering
    again while the vehicle is still in OFFBOARD (PX4's failsafe not yet due: 5 s leaves room
    for a busy machine's scheduling): when it answers again nothing goes out while the
    vehicle is in OFFBOARD, so PX4's own offboard-loss failsafe acts (COM_OBL_RC_ACT; the
    simulated one lands). Out of OFFBOARD nothing is pre-streamed either: PX4's offboard loss
    is a fallback, and setpoints arriving would take it back into OFFBOARD by itself; the
    vehicle never goes back to OFFBOARD, and `offboard` is what flies again."""
    ctl = StandInController()
    c = _chain(procs, tmp_path, vehicle_params=["COM_OF_LOSS_T=5.0"])
    try:
        assert "OFFBOARD" in _engage(c, tap)
        ctl.answer = False
        wait_for(lambda: c.status().get("engagement") == "disengaged", 3, "the bridge to disengage")
        assert c.status()["mode"] == "OFFBOARD"   # PX4 has not given up yet
        ctl.answer = True
        t_back = time.monotonic_ns() // 1000
        # mppid's commands flow again; the bridge takes them and drops them (disengaged, counted)
        # while the vehicle is in OFFBOARD.
        n = c.status()["dropped_disengaged"]
        wait_for(lambda: c.status()["dropped_disengaged"] > n + 10, 5, "mppid's commands again")
        assert c.status()["mode"] == "OFFBOARD" and c.status()["engagement"] == "disengaged"
        assert _between(tap, t_back, time.monotonic_ns() // 1000) == [], "forwarded while still in OFFBOARD"
        c.wait_event("failsafe", 10)
        t_fs = time.monotonic_ns() // 1000
        assert _between(tap, t_back, t_fs) == [], "forwarded while still in OFFBOARD"
        time.sleep(1.5)
        assert c.status()["engagement"] == "disengaged", "pre-streamed after PX4's offboard-loss fallback"
        assert _between(tap, t_fs, time.monotonic_ns() // 1000) == []
        modes = [e["mode"] for e in c.events("mode")]
        assert modes[-1] == "AUTO.LAND" and modes.count("OFFBOARD") == 1, modes
        assert not c.events("offboard_resumed")
        texts = [t for _, t in _statustexts(tap)]
        assert any("disengaged" in t and "stopped" in t for t in texts), texts
    finally:
        ctl.close()


def test_px4_link_back_never_resumes_offboard(netns, procs, tmp_path, tap):
    """PX4, engaged: the link cut until the bridge has declared it lost (its heartbeat timeout,
    2 s), then restored. PX4's offboard-loss failsafe holds (COM_OBL_RC_ACT 5) with OFFBOARD
    still its intended mode, so any setpoint after the link returns would take it back into
    OFFBOARD by itself (the real PX4 did: docs/px4.md). The bridge, disengaged by the loss,
    sends nothing when the link is back, the vehicle stays in Hold, and `offboard` is what flies
    again. The loss is waited for, not timed: the link goes down, then up, and both are seen."""
    ctl = StandInController()
    c = _chain(procs, tmp_path, vehicle_params=["COM_OBL_RC_ACT=5"])
    try:
        _engage_armed(c, tap, "px4")
        losses = c.status()["link_losses"]
        # Counted from the cut: on a busy machine a gap in the stand-in's answers before it may
        # already have tripped (and ended) one fallback, which is not what this test is about.
        failsafes, resumed = len(c.events("failsafe")), len(c.events("offboard_resumed"))
        modes_before = len(c.events("mode"))
        tap.cut = True
        wait_for(lambda: len(c.events("failsafe")) > failsafes, 5, "PX4's offboard-loss failsafe after the cut")
        wait_for(lambda: c.status().get("link_up") is False, 10, "the link declared lost")
        assert c.status()["link_losses"] == losses + 1
        assert c.status()["engagement"] == "disengaged"
        tap.cut = False
        t_back = time.monotonic_ns() // 1000
        wait_for(lambda: c.status().get("link_up"), 10, "the link back")
        assert c.status()["link_losses"] == losses + 1
        log = procs.log("bridge")
        assert "link lost: autopilot HEARTBEAT overdue" in log, log[-2000:]
        assert "link up" in log[log.index("link lost"):], log[-2000:]
        time.sleep(2.0)
        assert _between(tap, t_back, time.monotonic_ns() // 1000) == [], "setpoints after the link returned"
        modes = [e["mode"] for e in c.events("mode")][modes_before:]
        assert modes == ["AUTO.LOITER"], modes
        assert len(c.events("offboard_resumed")) == resumed, c.events("offboard_resumed")
        assert c.status()["engagement"] == "disengaged"
        t_offboard = time.monotonic_ns() // 1000
        assert "OFFBOARD" in _engage(c, tap)
        assert _between(tap, t_offboard, time.monotonic_ns() // 1000)
    finally:
        ctl.close()


def test_px4_switch_engages_before_and_after_a_disengage(netns, procs, tmp_path, tap):
    """PX4, one rule before and after a disengage: the operator's own switch into OFFBOARD (a
    ground station's here, the RC's alike) engages mppid before any `offboard`, and again after
    a switch out of it disengaged the bridge. Each change is told to the ground station. (The
    waits are bounds for a busy machine, 10 s each: what is asserted is that each happens.)"""
    ctl = StandInController()
    c = _chain(procs, tmp_path)
    try:
        wait_for(lambda: c.status().get("engagement") == "prestream" and c.status().get("streaming"), 5, "pre-stream")
        for attempt in ("before", "after"):
            n = len(tap.setpoints())  # PX4 takes OFFBOARD only with setpoints arriving
            wait_for(lambda: len(tap.setpoints()) > n + 10, 10, f"the pre-stream ({attempt})")
            _gcs(tap, mavlink.MAV_CMD_DO_SET_MODE, mavlink.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED, 6, 0)
            wait_for(lambda: c.status().get("engagement") == "engaged", 10, f"engaged by the switch ({attempt})")
            assert c.status()["mode"] == "OFFBOARD"
            _gcs(tap, mavlink.MAV_CMD_DO_SET_MODE, mavlink.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED, 4, 3)
            wait_for(lambda: c.status().get("engagement") != "engaged", 10, f"disengaged by the switch out ({attempt})")
            wait_for(lambda: c.status().get("engagement") == "prestream", 10, "pre-streamed again")
        texts = [t for _, t in _statustexts(tap)]
        assert sum("mppid engaged" in t for t in texts) == 2, texts
        assert sum("mppid disengaged: mode changed to" in t for t in texts) == 2, texts
    finally:
        ctl.close()


@pytest.mark.parametrize("action,mode", [(5, "AUTO.LOITER"), (0, "POSCTL")])
def test_px4_offboard_loss_does_what_com_obl_rc_act_says(netns, procs, tmp_path, tap, action, mode):
    """mppid stops answering in OFFBOARD: the bridge disengages after 0.5 s, PX4 (simulated)
    does what COM_OBL_RC_ACT says after COM_OF_LOSS_T (Hold, Position), not a landing the
    bridge assumed; the ground station heard both (the autopilot's and the bridge's text)."""
    ctl = StandInController()
    c = _chain(procs, tmp_path, vehicle_params=[f"COM_OBL_RC_ACT={action}", "COM_OF_LOSS_T=1.0"])
    try:
        _engage(c, tap)
        ctl.answer = False
        fs = c.wait_event("failsafe", 5)[0]
        assert fs["action"] == mode
        wait_for(lambda: c.status().get("mode") == mode.split(".")[-1] or c.status().get("mode") == mode, 3,
                 f"the HEARTBEAT to show {mode}")
        assert c.status()["engagement"] != "engaged"
        texts = [e["text"] for e in c.events("statustext")]
        assert any(t.startswith("mppid disengaged: mppid's setpoints stopped") for t in texts), texts
    finally:
        ctl.close()


def test_geofence_holds_the_vehicle_and_refuses_offboard_outside(netns, procs, tmp_path, tap):
    """ArduPilot with a cylinder fence of 10 m, max_z 2.5 m: mppid (stood in) climbing past it
    after `offboard` is disengaged at the fence, the vehicle put in BRAKE (the autopilot holds
    it), the operator told; `offboard` out there is refused, naming the fence."""
    ctl = StandInController(lambda seq: [9.81 * 1.3, 0.0, 0.0, 0.0])   # climbs
    c = _chain(procs, tmp_path, bridge_sets=["fence.shape=cylinder", "fence.radius=10", "fence.max_z=2.5"], **ARDUPILOT)
    try:
        c.ok("arm")
        c.ok("takeoff 1.5")
        _engage(c, tap)                                 # waits for the take-off, then GUIDED
        wait_for(lambda: "geofence" in c.status().get("disengaged_why", ""), 10, "the fence")
        st = c.status()
        assert st["engaged"] is False and "above the fence's max_z 2.5" in st["disengaged_why"], st
        wait_for(lambda: c.status().get("mode") == "BRAKE", 5, "the autopilot holding")
        texts = [e["text"] for e in c.events("statustext")]
        assert any("geofence" in t for t in texts), texts
        wait_for(lambda: "geofence" in c.ctl("offboard", 10)["message"], 10, "offboard refused outside the fence")
    finally:
        ctl.close()


def _engage_armed(c, tap, autopilot):
    """Engaged and armed on the ground: PX4 OFFBOARD then arm, ArduPilot GUIDED then arm."""
    _engage(c, tap)
    c.ok("arm")
    assert c.status()["engagement"] == "engaged"


@pytest.mark.parametrize("autopilot", ["px4", "ardupilot"])
def test_battery_failsafe_disengages(netns, procs, tmp_path, tap, autopilot):
    """The autopilot's battery failsafe (PX4 COM_LOW_BAT_ACT, ArduPilot BATT_FS_LOW_ACT; the
    simulated battery drains 30 %/s) lands the vehicle: the mode change disengages the bridge,
    which tells the ground station; mppid never flies the last of the battery."""
    ctl = StandInController()
    params = ["SIM_BATT_DRAIN=30"] + (["COM_LOW_BAT_ACT=2"] if autopilot == "px4" else
                                      ["BATT_FS_LOW_ACT=1", "GUID_OPTIONS=8", "MOT_THST_HOVER=0.4"])
    c = _chain(procs, tmp_path, autopilot=autopilot, vehicle_params=params)
    try:
        _engage_armed(c, tap, autopilot)
        fs = c.wait_event("failsafe", 10)[0]
        assert fs["reason"] == "battery low"
        wait_for(lambda: c.status().get("engagement") != "engaged", 10, "the bridge to disengage")
        wait_for(lambda: any("mode changed to LAND by someone else" in e["text"] for e in c.events("statustext")), 3,
                 "the ground station told")
        assert [e["mode"] for e in c.events("mode")][-1] in ("AUTO.LAND", "LAND")
    finally:
        ctl.close()


GROUND_STATION_LOSS = {
    # ArduPilot's FS_GCS_ENABLE 5 (LAND) after FS_GCS_TIMEOUT; PX4's NAV_DLL_ACT 1 (Hold) after COM_DL_LOSS_T.
    "ardupilot": (["FS_GCS_ENABLE=5", "FS_GCS_TIMEOUT=1", "GUID_OPTIONS=8", "MOT_THST_HOVER=0.4"], "LAND"),
    "px4": (["NAV_DLL_ACT=1", "COM_DL_LOSS_T=1", "COM_OF_LOSS_T=5"], "AUTO.LOITER"),
}


@pytest.mark.parametrize("autopilot", ["ardupilot", "px4"])
def test_ground_station_lost_disengages(netns, procs, tmp_path, tap, autopilot):
    """The autopilot's ground-station failsafe (ArduPilot FS_GCS_ENABLE, PX4 NAV_DLL_ACT): the
    ground station's HEARTBEATs stop while mppid flies; the autopilot changes mode, the bridge
    disengages on the mode change and does not re-engage."""
    params, mode = GROUND_STATION_LOSS[autopilot]
    ctl = StandInController()
    c = _chain(procs, tmp_path, autopilot=autopilot, vehicle_params=params)
    try:
        gcs, quiet = mavlink.MAVLink(None, srcSystem=255, srcComponent=190), threading.Event()

        def ground_station():  # HEARTBEATs at 4 Hz until told to fall silent
            while not quiet.wait(0.25):
                hb = gcs.heartbeat_encode(mavlink.MAV_TYPE_GCS, mavlink.MAV_AUTOPILOT_INVALID, 0, 0, 0)
                tap.a.sendto(hb.pack(gcs), tap.vehicle)
        threading.Thread(target=ground_station, daemon=True).start()
        _engage_armed(c, tap, autopilot)
        time.sleep(1.5)
        assert c.status()["engagement"] == "engaged" and not c.events("failsafe")
        quiet.set()
        fs = c.wait_event("failsafe", 5)[0]
        assert fs["reason"] == "ground station lost" and fs["action"] == mode
        wait_for(lambda: c.status().get("engaged") is False, 10, "the bridge to disengage")
        assert c.status()["disengaged_why"].startswith("mode changed to"), c.status()["disengaged_why"]
        t = time.monotonic_ns() // 1000
        time.sleep(1.0)
        if autopilot == "ardupilot":
            assert _between(tap, t, time.monotonic_ns() // 1000) == []
        else:  # out of OFFBOARD the pre-stream resumes, which PX4 ignores there; never OFFBOARD again
            assert c.status()["engagement"] == "prestream"
            modes = [e["mode"] for e in c.events("mode")]
            assert modes[-1] == mode and modes.count("OFFBOARD") == 1, modes
    finally:
        ctl.close()


@pytest.mark.parametrize("autopilot", ["px4", "ardupilot"])
def test_a_stopped_stream_ends_with_zero_rates_on_px4(netns, procs, tmp_path, tap, autopilot):
    """A real PX4 flies the last rate setpoint on until COM_OF_LOSS_T (docs/px4.md): mppid
    turning at 1 rad/s goes silent while engaged, and the bridge's last setpoint is zero body
    rates at the last thrust, once, so PX4 stops the turn; ArduPilot (which levels by itself
    after its last target) gets nothing made up."""
    ctl = StandInController(make_u=lambda seq: [12.0, 1.0, 0.0, 0.0])
    kw = ARDUPILOT if autopilot == "ardupilot" else {"vehicle_params": ["COM_OF_LOSS_T=5"]}
    c = _chain(procs, tmp_path, **kw)
    try:
        _engage(c, tap)
        ctl.answer = False
        wait_for(lambda: c.status().get("engaged") is False, 10, "the bridge to disengage")
        sps = [m for _, m in tap.setpoints()]
        turning = [m for m in sps if m.body_roll_rate == pytest.approx(1.0)]
        assert len(turning) > 25
        last = sps[-1]
        if autopilot == "px4":
            assert (last.body_roll_rate, last.body_pitch_rate, last.body_yaw_rate) == (0.0, 0.0, 0.0)
            assert last.thrust == pytest.approx(0.4 * 12.0 / 9.81, abs=1e-3)   # mppid's last, not hover (0.4)
            assert sum(1 for m in sps if m.body_roll_rate == 0.0) == 1
        else:
            assert last.body_roll_rate == pytest.approx(1.0), "ArduPilot: nothing made up"
    finally:
        ctl.close()


def test_statustext_on_engage_disengage_and_every_refusal(netns, procs, tmp_path, tap):
    """The ground station is told (STATUSTEXT from the bridge, component 191, chunks joined): a
    refusal to fly (GUID_OPTIONS without bit 3) once, each refused request, then, the parameter
    fixed, the engagement on `offboard` and the disengagement on `hold`, each with its reason."""
    ctl = StandInController()
    c = Chain(procs, tmp_path, autopilot="ardupilot", vehicle_params=["GUID_OPTIONS=1", "MOT_THST_HOVER=0.4"],
              bridge_sets=["telemetry.grace_s=1.0"])
    try:
        c.listen_lcm()
        c.start_bridge()
        c.start_vehicle(url=f"udpout:127.0.0.1:{TAP_PORT}")
        wait_for(lambda: "GUID_OPTIONS" in (c.status().get("refusal") or ""), 10, "the refusal")
        time.sleep(1.0)
        r = c.ctl("offboard")
        assert not r["ok"]
        wait_for(lambda: (mavlink.MAV_SEVERITY_WARNING, "mppid: " + r["message"]) in _statustexts(tap), 2,
                 "the refused request told")
        texts = _statustexts(tap)
        refusals = [(sev, t) for sev, t in texts if t.startswith("mppid refuses to fly: GUID_OPTIONS=1")]
        assert len(refusals) == 1 and refusals[0][0] == mavlink.MAV_SEVERITY_CRITICAL, texts
        assert "Set GUID_OPTIONS=9" in refusals[0][1]             # the whole text, over chunks
        assert (mavlink.MAV_SEVERITY_WARNING, "mppid: " + r["message"]) in texts
        assert not [t for _, t in texts if "not read yet" in t or "waiting for" in t]  # no noise at start
        procs.stop("vehicle")
        wait_for(lambda: c.status().get("link_up") is False, 5, "the link loss (parameters are read on link-up)")
        c.vehicle_params = ["GUID_OPTIONS=8", "MOT_THST_HOVER=0.4"]
        c.start_vehicle(url=f"udpout:127.0.0.1:{TAP_PORT}")
        wait_for(lambda: c.status().get("link_up") and not c.status().get("refusal"), 15, "checks passed")
        t0 = time.monotonic_ns() // 1000
        _engage(c, tap)
        c.ok("hold")
        time.sleep(0.3)
        texts = _statustexts(tap, since=t0)
        assert any(sev == mavlink.MAV_SEVERITY_NOTICE and t.startswith("mppid engaged: GUIDED entered: `offboard`")
                   for sev, t in texts), texts
        assert (mavlink.MAV_SEVERITY_WARNING, "mppid disengaged: hold requested; send offboard to fly again") in texts
        # the simulated autopilot, as a ground station, shows the same texts whole
        shown = [e["text"] for e in c.events("statustext")]
        assert "mppid disengaged: hold requested; send offboard to fly again" in shown
    finally:
        ctl.close()


def test_px4_bridge_restarted_in_offboard_never_takes_over(netns, procs, tmp_path, tap):
    """The bridge itself restarted (systemd) while PX4 is still in OFFBOARD (COM_OF_LOSS_T 5 s
    here): the new bridge finds the vehicle in OFFBOARD at its first HEARTBEAT, never switched
    there while it watched, and forwards nothing; PX4's own failsafe follows."""
    ctl = StandInController()
    c = _chain(procs, tmp_path, vehicle_params=["COM_OF_LOSS_T=5.0"])
    try:
        _engage(c, tap)
        procs.stop("bridge")
        c.start_bridge()
        t_back = time.monotonic_ns() // 1000
        wait_for(lambda: c.status().get("link_up"), 10, "the new bridge's link")
        wait_for(lambda: c.status().get("engagement") == "disengaged", 3, "the new bridge to stay disengaged")
        assert "not switched there while the bridge watched" in c.status()["disengaged_why"]
        time.sleep(1.0)
        assert c.status()["mode"] == "OFFBOARD"
        assert _between(tap, t_back, time.monotonic_ns() // 1000) == []
    finally:
        ctl.close()
