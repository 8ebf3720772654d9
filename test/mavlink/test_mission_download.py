"""The bridge's mission download (mppi_mavlink/missions.py) against a scripted autopilot that
answers each request at once, in-process: what the stand-in autopilot never does (a second
MISSION_COUNT in the middle of a download; answers meant for a ground station)."""
import io
import os

import pytest

os.environ.setdefault("MAVLINK20", "1")
from pymavlink import mavutil  # noqa: E402

from mppi_mavlink import missions  # noqa: E402
from mppi_mavlink.notices import Notices  # noqa: E402

M = mavutil.mavlink
SETTINGS = {"mavlink": {"target_component": 1, "system_id": 1, "dialect": "px4"}, "fence": {}}


class ScriptedAutopilot:
    """The link: what the bridge sends is decoded and answered by `answer(msg)`, at once."""
    link_up, target_system, conn_gen = True, 1, 1

    def __init__(self, answer):
        self.answer, self.sent, self.commands = answer, [], []
        self.enc = M.MAVLink(io.BytesIO(), srcSystem=1, srcComponent=191)
        self.ap_mav = M.MAVLink(None, srcSystem=1, srcComponent=1)
        self.m = None

    def send(self, fn):
        fn(self.enc)
        buf = self.enc.file.getvalue()
        self.enc.file.seek(0)
        self.enc.file.truncate()
        for msg in M.MAVLink(None).parse_buffer(buf) or []:
            self.sent.append(msg)
            for reply in self.answer(msg) or []:
                reply.pack(self.ap_mav)   # stamps its header, as from the autopilot
                self.m.on_message(reply.get_type(), reply)
        return True

    def command_long(self, command, params, name):
        """COMMAND_LONG accepted; REQUEST_MESSAGE answered with home or the origin."""
        self.commands.append((command, params[0]))
        if command == M.MAV_CMD_REQUEST_MESSAGE:
            msg = M.MAVLink_home_position_message(-353632621, 1491652374, 586000, 0, 0, 0, [1, 0, 0, 0], 0, 0, 0, 0) \
                if params[0] == M.MAVLINK_MSG_ID_HOME_POSITION else \
                M.MAVLink_gps_global_origin_message(-353632621, 1491652374, 584000, 0)
            msg.pack(self.ap_mav)
            self.m.on_message(msg.get_type(), msg)


def item(seq, target=1):
    return M.MAVLink_mission_item_int_message(target, 191, seq, M.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT,
                                              M.MAV_CMD_NAV_WAYPOINT, 0, 1, 0, 0, 0, 0, 10 + seq, 20, 2.0, 0)


def _missions(answer):
    ap = ScriptedAutopilot(answer)
    ap.m = missions.Missions(SETTINGS, ap, ap, Notices(ap))
    return ap, ap.m


def test_a_second_mission_count_during_the_download_ends_it():
    def answer(msg):
        if msg.get_type() == "MISSION_REQUEST_LIST":
            return [M.MAVLink_mission_count_message(1, 191, 3, 0)]
        if msg.get_type() == "MISSION_REQUEST_INT":
            return [item(0)] if msg.seq == 0 else [M.MAVLink_mission_count_message(1, 191, 4, 0)]
        return []
    ap, m = _missions(answer)
    with pytest.raises(missions.MissionChanged, match="a new MISSION_COUNT"):
        m.download()
    assert not any(s.get_type() == "MISSION_ACK" for s in ap.sent)


def test_answers_to_a_ground_station_are_not_taken_for_ours():
    """The autopilot answering a ground station's download (target system 255) beside ours."""
    def answer(msg):
        if msg.get_type() == "MISSION_REQUEST_LIST":
            return [M.MAVLink_mission_count_message(255, 190, 7, 0), M.MAVLink_mission_count_message(1, 191, 2, 0)]
        if msg.get_type() == "MISSION_REQUEST_INT":
            return [item(msg.seq, target=255), item(msg.seq)]
        return []
    ap, m = _missions(answer)
    r = m.execute(["download"])
    items = r["mission"]["items"]
    assert r["mission"]["home"] == pytest.approx((-35.3632621, 149.1652374, 586.0))
    assert r["mission"]["origin"][2] == pytest.approx(584.0)
    assert (M.MAV_CMD_SET_MESSAGE_INTERVAL, M.MAVLINK_MSG_ID_MISSION_CURRENT) in ap.commands
    assert [i["seq"] for i in items] == [0, 1] and items[1]["x"] == 11
    assert ap.sent[-1].get_type() == "MISSION_ACK" and ap.sent[-1].type == M.MAV_MISSION_ACCEPTED
    # Afterwards: the autopilot's MISSION_CURRENT with another total marks the mission changed.
    assert m.execute(["status"])["mission_status"]["changed"] == ""
    cur = M.MAVLink_mission_current_message(0, 5, 0, 0)
    cur.pack(ap.ap_mav)
    m.on_message("MISSION_CURRENT", cur)
    assert "5 items now, 2 were read" in m.execute(["status"])["mission_status"]["changed"]


def test_arducopters_total_leaves_out_home_and_a_late_item_is_ignored():
    """ArduPilot's MISSION_CURRENT counts the items without its home (item 0): 1 after a
    download of 2 is the same mission; 2 is a changed one. A MISSION_ITEM_INT arriving after the
    download (a repeat) changes nothing."""
    def answer(msg):
        if msg.get_type() == "MISSION_REQUEST_LIST":
            return [M.MAVLink_mission_count_message(1, 191, 2, 0)]
        return [item(msg.seq)] if msg.get_type() == "MISSION_REQUEST_INT" else []
    ap = ScriptedAutopilot(answer)
    ap.m = m = missions.Missions({**SETTINGS, "mavlink": {**SETTINGS["mavlink"], "dialect": "ardupilot"}}, ap, ap,
                                 Notices(ap))
    m.execute(["download"])
    for total, changed in ((1, ""), (2, "3 items now, 2 were read")):
        cur = M.MAVLink_mission_current_message(0, total, 0, 0)
        cur.pack(ap.ap_mav)
        late = item(1)
        late.pack(ap.ap_mav)
        m.on_message("MISSION_ITEM_INT", late)
        m.on_message("MISSION_CURRENT", cur)
        assert changed in m.execute(["status"])["mission_status"]["changed"]
        assert bool(changed) == bool(m.execute(["status"])["mission_status"]["changed"])
