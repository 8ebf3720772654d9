"""The bridge against ArduPilot's two behaviours (the simulated autopilot has both, as
ArduCopter does): no telemetry until a peer asks for it, and an attitude target in GUIDED
takes over the autopilot's own take-off. So the bridge asks for its streams on link-up and
refuses to fly while they are too slow, forwards nothing before `offboard`, and stops on
`land`, `hold` or a mode change made by someone else. MAVLink through a tap that keeps
every datagram (test_faults.py), mppid stood in for by a controller that answers each state."""
import os
import time

import pytest

os.environ.setdefault("MAVLINK20", "1")
from pymavlink import mavutil  # noqa: E402

from mavtest import wait_for  # noqa: E402
from linktools import ARDUPILOT, StandInController  # noqa: E402
from mavchain import Chain  # noqa: E402

pytestmark = pytest.mark.timeout(90)
mavlink = mavutil.mavlink
TAP_PORT = 14561


def _chain(procs, tmp_path, bridge_sets=(), vehicle_args=(), **kw):
    c = Chain(procs, tmp_path, bridge_sets=["telemetry.grace_s=1.0", *bridge_sets], vehicle_args=vehicle_args,
              **{**ARDUPILOT, **kw})
    c.listen_lcm()
    c.start_bridge()
    c.start_vehicle(url=f"udpout:127.0.0.1:{TAP_PORT}")
    wait_for(lambda: c.status().get("link_up"), 15, "link up")
    return c


def _interval_requests(tap):
    return {int(m.param1): m.param2 for _, m in tap.decoded("down")
            if m.get_type() == "COMMAND_LONG" and m.command == mavlink.MAV_CMD_SET_MESSAGE_INTERVAL}


def _gcs_set_mode(tap, mode: int):
    """A ground station's DO_SET_MODE, straight to the autopilot (not through the bridge)."""
    gcs = mavlink.MAVLink(None, srcSystem=255, srcComponent=190)
    msg = gcs.command_long_encode(1, 1, mavlink.MAV_CMD_DO_SET_MODE, 0,
                                  mavlink.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED, mode, 0, 0, 0, 0, 0)
    tap.a.sendto(msg.pack(gcs), tap.vehicle)


def test_asks_for_telemetry_and_flies_nothing_without_it(netns, procs, tmp_path, tap):
    """Told not to ask, the bridge hears no state at all and refuses to fly, saying why; asking
    (the default) gets ATTITUDE_QUATERNION and LOCAL_POSITION_NED at 50 Hz, states flow."""
    ctl = StandInController()
    try:
        c = _chain(procs, tmp_path, bridge_sets=["telemetry.request=false"])
        wait_for(lambda: "telemetry" in (c.status().get("refusal") or ""), 10, "the telemetry refusal")
        st = c.status()
        assert st["states_published"] == 0 and "0.0 Hz" in st["refusal"] and "min_state_hz 30" in st["refusal"]
        for cmd in ("arm", "offboard"):
            r = c.ctl(cmd)
            assert not r["ok"] and "telemetry" in r["message"], r
        assert _interval_requests(tap) == {}
        assert any("telemetry" in m.error for _, m in c.link_msgs)
        procs.stop("bridge")

        c.bridge_sets = ["telemetry.grace_s=1.0"]
        c.start_bridge()  # the same autopilot, a bridge that asks
        wait_for(lambda: c.status().get("states_published", 0) >= 100 and not c.status().get("refusal"), 15,
                 "states from the streams asked for")
        asked = _interval_requests(tap)
        assert asked[mavlink.MAVLINK_MSG_ID_ATTITUDE_QUATERNION] == 20000
        assert asked[mavlink.MAVLINK_MSG_ID_LOCAL_POSITION_NED] == 20000
        assert mavlink.MAVLINK_MSG_ID_EXTENDED_SYS_STATE in asked
        wait_for(lambda: c.status().get("state_rate_hz", 0) >= 40, 5, "the state rate measured")
        assert c.status()["state_rate_hz"] <= 60
    finally:
        ctl.close()


def test_too_slow_telemetry_refuses_to_fly(netns, procs, tmp_path, tap):
    """An autopilot that can stream 15 Hz at most (a slow radio, say): asked for 50, the bridge
    measures 15 and refuses arm and offboard, naming the rate; no setpoint reaches the wire."""
    ctl = StandInController()
    try:
        c = _chain(procs, tmp_path, vehicle_args=["--state-hz", "15"])
        wait_for(lambda: "telemetry" in (c.status().get("refusal") or ""), 10, "the rate refusal")
        assert c.status()["states_published"] > 10  # states do flow, just too slowly
        rate = c.status()["state_rate_hz"]
        assert 10 <= rate <= 20, rate
        r = c.ctl("arm")
        assert not r["ok"] and "below telemetry.min_state_hz 30" in r["message"], r
        assert tap.setpoints() == []
    finally:
        ctl.close()


def test_takeoff_is_never_taken_over_and_a_mode_change_stops_the_stream(netns, procs, tmp_path, tap):
    """Arm, the autopilot's take-off to 1.5 m while mppid (stood in) answers every state:
    nothing reaches the wire and the take-off completes; `offboard` waits for it, then
    forwards; a ground station's LOITER ends the forwarding at once; `offboard` resumes it;
    `land` stops it again."""
    ctl = StandInController()
    try:
        c = _chain(procs, tmp_path)
        wait_for(lambda: not c.status().get("refusal") and c.status().get("states_published", 0) >= 60, 15,
                 "checks passed and states")
        assert c.status()["engaged"] is False
        c.ok("arm")
        c.ok("takeoff 1.5")
        time.sleep(0.5)
        assert tap.setpoints() == [], "a setpoint reached the autopilot during its take-off"
        msg = c.ok("offboard")  # waits for the take-off to end
        assert "GUIDED" in msg
        done = c.events("takeoff_complete")
        assert done and not c.events("takeoff_taken_over")
        assert c.status()["dropped_disengaged"] > 50  # mppid's commands during the take-off
        wait_for(lambda: len(tap.setpoints()) > 25, 5, "setpoints after offboard")

        t_mode = time.monotonic_ns() // 1000
        _gcs_set_mode(tap, 5)  # LOITER, from someone else
        wait_for(lambda: c.status().get("engaged") is False, 3, "the bridge to disengage")
        assert "mode changed to LOITER by someone else" in c.status()["disengaged_why"]
        late = [t for t, _ in tap.setpoints() if t > t_mode + 1_200_000]  # the HEARTBEAT is 1 Hz
        assert late == [], f"{len(late)} setpoints after the mode change"

        c.ok("offboard")
        n = len(tap.setpoints())
        wait_for(lambda: len(tap.setpoints()) > n + 25, 5, "setpoints again after offboard")
        c.ok("land")
        t_land = time.monotonic_ns() // 1000
        time.sleep(0.5)
        assert [t for t, _ in tap.setpoints() if t > t_land + 100_000] == []
        assert c.status()["engaged"] is False and c.status()["disengaged_why"] == "land requested"
    finally:
        ctl.close()


def test_the_simulated_autopilot_gives_its_takeoff_to_an_attitude_target(netns, procs, tmp_path):
    """The regression the take-off test guards against, shown on the simulated autopilot
    itself: a SET_ATTITUDE_TARGET in GUIDED during its take-off takes the vehicle over."""
    c = Chain(procs, tmp_path, **ARDUPILOT)
    c.start_vehicle(url="udpout:127.0.0.1:14540")
    gcs = mavutil.mavlink_connection("udpin:127.0.0.1:14540", source_system=255, source_component=190)
    try:
        gcs.wait_heartbeat(timeout=10)
        time.sleep(1.2)  # the estimator's 1 s
        for cmd, params in ((mavlink.MAV_CMD_DO_SET_MODE, [mavlink.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED, 4]),
                            (mavlink.MAV_CMD_COMPONENT_ARM_DISARM, [1]), (mavlink.MAV_CMD_NAV_TAKEOFF,
                                                                          [0, 0, 0, 0, 0, 0, 3.0])):
            gcs.mav.command_long_send(1, 1, cmd, 0, *(list(params) + [0] * (7 - len(params))))
            ack = gcs.recv_match(type="COMMAND_ACK", blocking=True, timeout=3)
            assert ack is not None and ack.result == mavlink.MAV_RESULT_ACCEPTED, (cmd, ack)
        wait_for(lambda: c.events("takeoff_complete") or any(
            r.get("x", [0, 0, 0])[2] > 0.5 for r in _truth(tmp_path)), 10, "the climb to start")
        gcs.mav.set_attitude_target_send(0, 1, 1, mavlink.ATTITUDE_TARGET_TYPEMASK_ATTITUDE_IGNORE,
                                         [1, 0, 0, 0], 0.0, 0.0, 0.0, 0.4)
        ev = c.wait_event("takeoff_taken_over", 3)
        assert ev[0]["z"] < 3.0 - 0.15 and not c.events("takeoff_complete")
    finally:
        gcs.close()
        c.stop_vehicle()


def _truth(out):
    from mavtest import read_jsonl
    return [r for r in read_jsonl(out / "truth.jsonl") if "x" in r]
