"""PX4's collision prevention pushed at a trunk (`--autopilot px4 --controller position`,
config/missions/position_toward_trunk.yaml) without PX4: the flight's command lines and the
parameters only it loads, the ground station's Position-mode push against a fake PX4 GCS link,
and the push's figures in the score (ap_score._push)."""
from __future__ import annotations

import math
import os
import socket
import threading
import time

import numpy as np
import pytest
import yaml

os.environ.setdefault("MAVLINK20", "1")  # before pymavlink: MAVLink 1 would be the process's for the tests after
from pymavlink import mavutil  # noqa: E402

from sitl_harness import ap_gcs, ap_score, cli, paths  # noqa: E402
from sitl_harness.flights.base import FlightError, FlightSpec  # noqa: E402
from sitl_harness.flights.px4 import COLLISION_PREVENTION, Px4Flight, px4_params  # noqa: E402
from test_px4_flight import _fake_px4  # noqa: E402

M = mavutil.mavlink
MISSION = paths.MISSIONS / "position_toward_trunk.yaml"
TAKEOFF, HOLD, LAND = ap_gcs.PX4_AUTO_TAKEOFF, ap_gcs.PX4_AUTO_LOITER, (4 << 16) | (6 << 24)
POSCTL, MANUAL = 3 << 16, 1 << 16


def _plan(tmp_path, controller="position", scenario="position_toward_trunk", params=()):
    spec = FlightSpec(scenario=scenario, seed=51, out=tmp_path / "out", realtime=True, autopilot="px4",
                      controller=controller, px4_bin=str(_fake_px4(tmp_path)), autopilot_params=list(params))
    flight = Px4Flight.create(spec)
    flight.out.mkdir(parents=True)
    return flight, flight.plan().commands


def test_position_flight_runs_the_map_to_px4_with_mppid_not_flying(mppid_binary, tmp_path):
    flight, cmds = _plan(tmp_path)
    assert set(cmds) == {"logger", "recorder", "sim", "bridge", "sensors", "mapper", "mission"}   # no mppid
    sim = cmds["sim"][cmds["sim"].index("env"):]
    for name, value in px4_params(COLLISION_PREVENTION).items():
        assert f"PX4_PARAM_{name}={value}" in sim
    assert "PX4_PARAM_CP_DIST=2.0" in sim and "PX4_PARAM_COM_OF_LOSS_T=0.5" in sim   # over px4_mppid.params
    gcs = cmds["mission"]
    assert gcs[1:3] == ["-m", "sitl_harness.ap_gcs"] and gcs[-2:] == ["--position-push", "12"]
    assert gcs[gcs.index("--dialect") + 1] == "px4" and gcs[gcs.index("--url") + 1] == "udpin:127.0.0.1:14550"
    rec = cmds["recorder"]
    assert rec[rec.index("--gcs-port") + 1] == "0"   # the ground station has PX4's GCS port
    bridge = cmds["bridge"]
    assert "recv_buf_size" in bridge[bridge.index("--lcm-url") + 1]   # the bridge reads ~1 MB maps
    sensors = cmds["sensors"]
    flown = yaml.safe_load(open(sensors[sensors.index("--sensing") + 1]))["sensing"]
    assert flown["depth_camera"]["pitch_deg"] == -20   # SIH's mount (config/px4/sensor_mount.yaml)


def test_collision_prevention_parameters_only_for_that_controller(mppid_binary, tmp_path):
    for controller, scenario in (("px4", "circle_3ms"), ("mppid", "position_toward_trunk")):
        _, cmds = _plan(tmp_path / controller, controller, scenario)
        assert not [a for a in cmds["sim"] if a.startswith("PX4_PARAM_CP_")], controller
    _, cmds = _plan(tmp_path / "off", params=["CP_DIST=-1"])
    assert "PX4_PARAM_CP_DIST=-1" in cmds["sim"] and "PX4_PARAM_CP_DIST=2.0" not in cmds["sim"]   # ours win
    with pytest.raises(FlightError, match="--controller position flies a sensed mission"):
        _plan(tmp_path / "circle", scenario="circle_3ms")


def test_position_is_px4s_own_controller(capsys):
    assert cli.main(["run", "--scenario", "position_toward_trunk", "--realtime", "--controller", "position"]) == 2
    assert "needs --autopilot px4" in capsys.readouterr().err
    assert cli.main(["run", "--scenario", "position_toward_trunk", "--realtime", "--controller", "position",
                     "--autopilot", "ardupilot"]) == 2
    with pytest.raises(SystemExit):   # ArduCopter's stick push is --loiter-push
        ap_gcs._args(["--url", "u", "--mission", "m", "--seed", "1", "--lcm-url", "l", "--out", "o",
                      "--home", "0,0,0,0", "--position-push", "12"])
    assert "--position-push PX4's Position mode" in capsys.readouterr().err


def test_the_trunk_stands_ahead_of_sihs_initial_heading(tmp_path):
    doc = yaml.safe_load(MISSION.read_text())
    trunk = ap_gcs.write_world(doc, 51, tmp_path)
    yaw0 = math.degrees(float(px4_params(COLLISION_PREVENTION)["SIH_LOC_YAW0"]))   # from north, clockwise
    (east, north, radius), = trunk
    assert math.degrees(math.atan2(east, north)) == pytest.approx(yaw0, abs=1.0)
    assert math.hypot(east, north) == pytest.approx(10.0) and radius > 0
    assert doc["sensing"]["publish_obstacles"] is False   # only the camera sees it


class FakePx4:
    """PX4's GCS link as the Position-mode push meets it: HEARTBEAT with its custom mode and
    GLOBAL_POSITION_INT at 20 Hz, SET_MODE and DO_SET_MODE, arming (in AUTO.TAKEOFF: at 2 m and
    in Hold at once), NAV_LAND (landed and disarmed at once); with `leave_after`, Hold after that
    many forward sticks (collision prevention's own switch). Records the modes and the sticks."""

    def __init__(self, port: int, leave_after: int | None = None):
        self.conn = mavutil.mavlink_connection(f"udpout:127.0.0.1:{port}", source_system=1, source_component=1)
        self.mode, self.armed, self.alt, self.leave_after = MANUAL, False, 0.0, leave_after
        self.modes, self.sticks = [], []   # sticks: (mode, armed, x, y, z, r)
        self.stop = threading.Event()
        self.thread = threading.Thread(target=self._run, daemon=True)
        self.thread.start()

    def _set(self, mode: int):
        self.mode = mode
        self.modes.append(mode)

    def _run(self):
        due = 0.0
        while not self.stop.is_set():
            if time.monotonic() >= due:
                base = M.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED | (M.MAV_MODE_FLAG_SAFETY_ARMED if self.armed else 0)
                self.conn.mav.heartbeat_send(M.MAV_TYPE_QUADROTOR, M.MAV_AUTOPILOT_PX4, base, self.mode, 4)
                self.conn.mav.global_position_int_send(0, 0, 0, 0, int(self.alt * 1000), 0, 0, 0, 0)
                due = time.monotonic() + 0.05
            m = self.conn.recv_match(blocking=True, timeout=0.02)
            if m is not None:
                self._on(m)

    def _on(self, m):
        t = m.get_type()
        if t == "SET_MODE":
            self._set(m.custom_mode)
        elif t == "MANUAL_CONTROL":
            self.sticks.append((self.mode, self.armed, m.x, m.y, m.z, m.r))
            if m.x > 0 and sum(s[2] > 0 for s in self.sticks) == self.leave_after:
                self._set(HOLD)
        elif t == "COMMAND_LONG":
            if m.command == M.MAV_CMD_COMPONENT_ARM_DISARM:
                self.armed = m.param1 == 1
                if self.armed and self.mode == TAKEOFF:
                    self.alt = 2.0
                    self._set(HOLD)
            elif m.command == M.MAV_CMD_DO_SET_MODE:
                self._set((int(m.param2) << 16) | (int(m.param3) << 24))
            elif m.command == M.MAV_CMD_NAV_LAND:
                self._set(LAND)
                self.alt, self.armed = 0.0, False
            self.conn.mav.command_ack_send(m.command, M.MAV_RESULT_ACCEPTED)

    def close(self):
        self.stop.set()
        self.thread.join()
        self.conn.close()


def _free_udp_port() -> int:
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def _push(monkeypatch, leave_after=None, seconds=0.6):
    """The ground station's push against a FakePx4: (summary, its log, the fake)."""
    monkeypatch.setattr(ap_gcs, "SETTLE_S", 0.2)
    port = _free_udp_port()
    gcs = mavutil.mavlink_connection(f"udpin:127.0.0.1:{port}", source_system=255, source_component=190)
    px4 = FakePx4(port, leave_after)
    log = []
    try:
        assert gcs.wait_heartbeat(timeout=10) is not None
        summary = ap_gcs.fly_position_push(gcs, log.append, lambda s: None, seconds, 2.0)
    finally:
        px4.close()
        gcs.close()
    return summary, log, px4


def test_the_ground_station_pushes_px4_in_position_mode(monkeypatch):
    summary, log, px4 = _push(monkeypatch)
    assert summary == {"outcome": "done"}
    assert px4.modes == [TAKEOFF, HOLD, POSCTL, LAND]   # take-off, its Hold, Position, Land
    assert px4.sticks and all(armed for mode, armed, *_ in px4.sticks if mode != LAND)   # only once in the air
    assert {s[0] for s in px4.sticks} <= {HOLD, POSCTL, LAND}
    assert all((y, z, r) == (0, ap_gcs.STICK_MID, 0) for _, _, _, y, z, r in px4.sticks)   # altitude held
    xs = [s[2] for s in px4.sticks]
    first = xs.index(ap_gcs.PUSH_STICK)
    assert set(xs) == {0, ap_gcs.PUSH_STICK} and px4.sticks[first - 1][0] == POSCTL   # centred in Position first
    pushed = [s for s in px4.sticks if s[2] == ap_gcs.PUSH_STICK]
    assert all(s[0] == POSCTL for s in pushed)
    assert xs[-1] == 0 and 0 not in xs[first:first + len(pushed)]   # one push, then released
    assert [e["event"] for e in log] == ["push", "released"] and log[0]["wall_us"] < log[1]["wall_us"]


def test_px4_leaving_position_mode_in_the_push_is_recorded(monkeypatch):
    summary, _, px4 = _push(monkeypatch, leave_after=2, seconds=30.0)   # the push ends when PX4 leaves
    assert summary == {"outcome": "done", "left_position_mode": f"{HOLD:#x}"}
    assert px4.modes == [TAKEOFF, HOLD, POSCTL, HOLD, LAND], [hex(m) for m in px4.modes]   # landed at the end


def _truth(speeds, dt=0.1, y0=0.0):
    """A truth along north at the given speeds, one sample every dt, on the wall clock."""
    rows, y = [], y0
    for k, v in enumerate(speeds):
        rows.append({"wall_us": int(1e12 + k * dt * 1e6), "x": [0.0, y, 2.0], "v": [0.0, v, 0.0]})
        y += v * dt
    return rows


@pytest.mark.parametrize("speeds,stopped,closest", [
    ([2.0] * 30 + [0.0] * 80, True, 10.0 - 6.0 - 0.3 - 0.2),     # 6 m run, then held: short of it
    ([2.0] * 110, False, -0.5),                                    # through the trunk (its axis at 10 m)
])
def test_the_push_is_scored_where_it_stopped(speeds, stopped, closest):
    truth = _truth(speeds)
    mission = [{"event": "push", "wall_us": truth[0]["wall_us"]}, {"event": "released", "wall_us": truth[99]["wall_us"]}]
    X = np.array([r["x"] for r in truth])
    push = ap_score._push(mission, truth, X, {"trees": [[0.0, 10.0, 0.3]], "vehicle_radius": 0.2})["push"]
    assert push["stopped"] is stopped and push["closest_m"] == pytest.approx(closest, abs=0.01)
    assert push["max_speed"] == pytest.approx(2.0) and push["seconds"] == pytest.approx(9.9)
    assert push["start_xy"] == [0.0, 0.0]
    assert ap_score._push(mission[:1], truth, X, {"trees": [[0.0, 10.0, 0.3]]}) == {}   # no release: no push
