"""Sensed flights and the uploaded survey through PX4 SITL (flights/px4.py), without PX4: the
processes a flight starts and how they are wired (a fake px4_sitl_sih build), the ground
station's mission in PX4's numbering (ap_gcs.py), and the referee's truth on the sensors' bus
(px4_truth.py over a real UDP link standing in for PX4's SIH display link)."""
from __future__ import annotations

import math
import os
import socket
import threading
import time

import pytest
import yaml

os.environ.setdefault("MAVLINK20", "1")
from pymavlink import mavutil  # noqa: E402

from sitl_helpers import missing  # noqa: E402
from sitl_harness import ap_gcs, cli, paths, px4_score, px4_truth  # noqa: E402
from sitl_harness.flights.base import FlightError, FlightSpec, sensor_bus  # noqa: E402
from sitl_harness.flights.px4 import GCS_URL, Px4Flight  # noqa: E402
from test_px4_flight import _fake_px4  # noqa: E402

M = mavutil.mavlink
ORIGIN = (473977432, 85455942, 489400)   # SIH's default home: lat, lon 1e-7 deg, alt mm


def _commands(tmp_path, scenario, controller="mppid"):
    if paths.find_binary("mppid-sensors") is None or paths.find_binary("mppid-mapper") is None:
        missing("mppid-sensors / mppid-mapper not built (cmake --build <build> --target mppid-sensors mppid-mapper)")
    spec = FlightSpec(scenario=scenario, seed=7, out=tmp_path / "out", realtime=True, autopilot="px4",
                      px4_bin=str(_fake_px4(tmp_path)), controller=controller)
    flight = Px4Flight.create(spec)
    flight.out.mkdir(parents=True)
    return spec, flight.plan().commands


def _arg(cmd, flag):
    return cmd[cmd.index(flag) + 1]


def _wiring(spec, cmds):
    """What every sensed PX4 flight has: the truth at 50 Hz on the sensors' bus, the sensors and
    the mapper on it, mppid's bus with room for the maps, the frames kept out of the log."""
    bus = sensor_bus(spec.lcm_url)
    rec = cmds["recorder"]
    assert "sitl_harness.px4_truth" in rec and _arg(rec, "--lcm-url") == bus and float(_arg(rec, "--truth-hz")) == 50
    assert _arg(cmds["sensors"], "--sensor-lcm-url") == bus and _arg(cmds["mapper"], "--sensor-lcm-url") == bus
    assert _arg(cmds["sensors"], "--lcm-url") == spec.lcm_url   # the trees come on the flight's bus
    assert any("MPPI_DEPTH" in c for c in cmds["logger"])


def test_a_sensed_mission_through_px4_flies_mppid_on_the_mappers_map(mppid_binary, tmp_path):
    spec, cmds = _commands(tmp_path, "rate_forest_sensed")
    _wiring(spec, cmds)
    assert {"sim", "controller", "bridge", "mission", "sensors", "mapper"} <= set(cmds) and "gcs" not in cmds
    assert "--gcs-port" not in cmds["recorder"]             # PX4's GCS link's messages: the referee's
    ctrl = cmds["controller"]
    assert _arg(ctrl, "--lcm-url").endswith("&recv_buf_size=4194304")      # 1 MB maps
    assert "config/vehicles/px4_sih_identified.yaml" in _arg(ctrl, "--vehicle")
    own = yaml.safe_load((paths.MISSIONS / "rate_forest_sensed.yaml").read_text())["mppid"]["set"]
    assert [ctrl[i + 1] for i, c in enumerate(ctrl) if c == "--set"][-len(own):] == own
    assert _arg(cmds["bridge"], "--config").endswith("config/bridge/px4_sitl.yaml")
    assert "fly" in cmds["mission"] and _arg(cmds["mission"], "--bridge").endswith("bridge.sock")
    # The known-tree mission is flown as before: the truth at PX4's rate, on no bus.
    _, known = _commands(tmp_path / "known", "rate_forest")
    assert not {"sensors", "mapper"} & set(known)
    assert "--lcm-url" not in known["recorder"] and "--truth-hz" not in known["recorder"]


def test_the_uploaded_survey_through_px4(mppid_binary, tmp_path):
    spec, cmds = _commands(tmp_path, "survey_forest_sensed")
    _wiring(spec, cmds)
    gcs = cmds["gcs"]
    assert "sitl_harness.ap_gcs" in gcs and _arg(gcs, "--dialect") == "px4" and _arg(gcs, "--url") == GCS_URL
    assert not any(c.startswith("--home") for c in gcs)     # PX4's positions: about its estimator's origin
    assert _arg(cmds["recorder"], "--gcs-port") == "0"      # the port is the ground station's
    assert "--fly-auto" not in gcs
    mission = cmds["mission"]
    assert "from-autopilot" in mission and f"control.socket={_arg(mission, '--bridge')}" in cmds["bridge"]
    assert "controller" in cmds
    # --controller auto: PX4's AUTO.MISSION flies it; the ground station follows it, no mppid.
    _, auto = _commands(tmp_path / "auto", "survey_forest_sensed", controller="auto")
    assert "controller" not in auto and "gcs" not in auto
    assert "--fly-auto" in auto["mission"] and _arg(auto["mission"], "--dialect") == "px4"


def test_px4s_own_controllers_fly_what_they_can(tmp_path, capsys):
    binary = _fake_px4(tmp_path)
    spec = FlightSpec(scenario="circle_3ms", out=tmp_path / "out", realtime=True, autopilot="px4",
                      px4_bin=str(binary), controller="auto")
    flight = Px4Flight.create(spec)
    flight.out.mkdir(parents=True)
    with pytest.raises(FlightError, match="flies a mission uploaded to PX4"):
        flight.plan()
    assert cli.main(["run", "--scenario", "survey_forest_sensed", "--realtime", "--controller", "auto"]) == 2
    assert "needs --autopilot ardupilot or px4" in capsys.readouterr().err


def _items(dialect, home):
    doc = yaml.safe_load((paths.MISSIONS / "survey_forest_sensed.yaml").read_text())
    return doc, ap_gcs.mission_items(doc, home, dialect)


def test_the_ground_stations_survey_in_px4s_numbering():
    home = [47.3977432, 8.5455942, 489.4]
    doc, px4 = _items("px4", home)
    _, ardupilot = _items("ardupilot", home + [0.0])
    assert [m.seq for m in px4] == list(range(len(px4)))                 # from 0, no home item
    assert [m.command for m in px4] == [m.command for m in ardupilot[1:]]  # the same mission after ArduPilot's home
    assert ardupilot[0].command == M.MAV_CMD_NAV_WAYPOINT and ardupilot[0].frame == M.MAV_FRAME_GLOBAL_INT
    assert px4[0].command == M.MAV_CMD_NAV_TAKEOFF and px4[0].z == doc["takeoff"]
    assert (px4[0].x, px4[0].y) == (round(home[0] * 1e7), round(home[1] * 1e7))  # where it stands, not lat, lon 0
    assert px4[-1].command == M.MAV_CMD_NAV_LAND
    speed = next(m for m in px4 if m.command == M.MAV_CMD_DO_CHANGE_SPEED)   # PX4 refuses it in a global frame
    assert speed.frame == M.MAV_FRAME_MISSION and speed.param2 == doc["autopilot_mission"]["speed"]
    assert ap_gcs.last_waypoint(px4) == len(px4) - 2 and ap_gcs.last_waypoint(ardupilot) == len(ardupilot) - 2
    # Each waypoint where its leg is, in metres about home (the estimator's origin for PX4), in PX4's
    # projection to 0.2 % (gps_offset is flat on a 6 378 100 m earth, PX4's sphere 6 371 000 m).
    for m, leg in zip([m for m in px4 if m.command == M.MAV_CMD_NAV_WAYPOINT], doc["legs"]):
        n, e = px4_score.project(m.x, m.y, round(home[0] * 1e7), round(home[1] * 1e7))
        assert [float(e), float(n), m.z] == pytest.approx(leg["goal"]["at"], rel=2e-3, abs=1e-3)
        assert m.param2 == leg["goal"]["radius"] and m.frame == M.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT
    with pytest.raises(ValueError, match="dialect 'qgc'"):
        ap_gcs.mission_items(doc, home, "qgc")


def _free_udp_port() -> int:
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def _hil_state(boot_us, north_m, up_m):
    lat = ORIGIN[0] + round(math.degrees(north_m / px4_score.PX4_EARTH_R) * 1e7)
    return M.MAVLink_hil_state_quaternion_message(
        boot_us, [1.0, 0.0, 0.0, 0.0], 0.1, 0.2, 0.3, lat, ORIGIN[1], ORIGIN[2] + round(up_m * 1000),
        150, 50, -25, 0, 0, 0, 0, 0)


def test_the_px4_referee_asks_px4_for_its_streams_on_the_display_link(tmp_path):
    """PX4's side: a UDP link sending to the referee's port, as PX4's SIH display link does; the
    referee asks for the estimate, the truth's rate and the origin until they come."""
    port = _free_udp_port()
    rec = px4_truth.Recorder(tmp_path, port, truth_hz=50.0)
    px4 = mavutil.mavlink_connection(f"udpout:127.0.0.1:{port}", source_system=1, source_component=1)
    px4.mav.send(_hil_state(1_000_000, 0.0, 0.0))
    asked, deadline = set(), time.monotonic() + 10.0
    done = lambda: len(asked) >= 3 or time.monotonic() > deadline  # noqa: E731
    t = threading.Thread(target=rec.run, args=(done,))
    t.start()
    while not done():
        m = px4.recv_match(type="COMMAND_LONG", blocking=True, timeout=0.5)
        if m is not None:
            asked.add((m.command, m.param1, m.param2))
    t.join(5.0)
    rec.f.close()
    assert asked == {(M.MAV_CMD_SET_MESSAGE_INTERVAL, M.MAVLINK_MSG_ID_LOCAL_POSITION_NED, 1e6 / 50),
                     (M.MAV_CMD_SET_MESSAGE_INTERVAL, M.MAVLINK_MSG_ID_HIL_STATE_QUATERNION, 1e6 / 50),
                     (M.MAV_CMD_REQUEST_MESSAGE, M.MAVLINK_MSG_ID_GPS_GLOBAL_ORIGIN, 0)}


def test_the_px4_referee_takes_the_messages_from_the_gcs_link_where_px4_forwards_the_bridges(tmp_path):
    """And claims the link (PX4 answers its first sender): a later sender does not take it away."""
    rec = px4_truth.Recorder(tmp_path, _free_udp_port(), gcs_port=_free_udp_port())
    gcs_port = rec.gcs.port.getsockname()[1]
    px4 = mavutil.mavlink_connection(f"udpout:127.0.0.1:{gcs_port}", source_system=1, source_component=1)
    rec.handle(M.MAVLink_statustext_message(6, b"on the display link"))   # the same text twice: once kept
    deadline = time.monotonic() + 10.0
    t = threading.Thread(target=rec.run_texts, args=(lambda: time.monotonic() > deadline
                                                     or "disengaged" in (tmp_path / "truth_raw.jsonl").read_text(),))
    t.start()
    while t.is_alive():
        px4.mav.statustext_send(4, b"mppid: disengaged")
        t.join(0.2)
    rec.f.close()
    texts = [ln for ln in (tmp_path / "truth_raw.jsonl").read_text().splitlines() if "statustext" in ln]
    assert texts and all("mppid: disengaged" in ln for ln in texts)
    claim = px4.recv_match(type="COMMAND_LONG", blocking=True, timeout=5.0)   # PX4's partner on that link now
    assert claim is not None and claim.command == M.MAV_CMD_REQUEST_MESSAGE


def test_the_px4_referee_publishes_the_truth_in_the_states_frame_and_clock(tmp_path):
    from mppi_lcm import vehicle_state_t
    rec = px4_truth.Recorder(tmp_path, _free_udp_port(), lcm_url="memq://")
    got = []
    rec.truth_out.lc.subscribe("SIM_TRUTH", lambda ch, data: got.append(vehicle_state_t.decode(data)))
    base = 10**12                                       # our clock at PX4's boot, less the least delay
    rec.handle(_hil_state(1_000_000, 0.0, 0.0), wall_us=base + 1_000_000 + 3_000)
    rec.truth_out.lc.handle_timeout(10)
    assert got == []                                    # no origin yet: no frame to put the truth in
    rec.handle(M.MAVLink_gps_global_origin_message(*ORIGIN))
    for k, delay_us in enumerate((4_000, 1_000, 2_500)):
        boot = 1_020_000 + 20_000 * k
        rec.handle(_hil_state(boot, 1.0 * k, 2.0), wall_us=base + boot + delay_us)
    while rec.truth_out.lc.handle_timeout(10) > 0:
        pass
    rec.f.close()
    assert len(got) == 3
    m = got[-1]
    assert (m.model, m.nx, m.n, m.vehicle_count) == (m.MODEL_QUADROTOR_RATE, 13, 13, 1)
    assert list(m.x[0:3]) == pytest.approx([0.0, 2.0, 2.0], abs=0.01)   # ENU about the origin: north is y
    assert list(m.x[3:6]) == pytest.approx([0.5, 1.5, 0.25])           # NED cm/s (150, 50, -25) -> ENU m/s
    assert list(m.x[6:10]) == pytest.approx([math.sqrt(0.5), 0, 0, math.sqrt(0.5)])  # facing north: yaw 90 in ENU
    assert list(m.x[10:13]) == pytest.approx([0.1, -0.2, -0.3])        # FRD -> FLU
    # PX4's boot clock on ours as the bridge maps the states' (clock_sync: the least delay so far).
    assert [g.sample_utime for g in got] == [base + 1_020_000 + 3_000, base + 1_040_000 + 1_000,
                                             base + 1_060_000 + 1_000]
    lines = (tmp_path / "truth_raw.jsonl").read_text().splitlines()
    assert sum('"truth": 1' in ln for ln in lines) == 4 and sum('"origin"' in ln for ln in lines) == 1
