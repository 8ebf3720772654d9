"""The mission the operator uploaded to the autopilot, read over the bridge's own link (the
one connection to the autopilot), and the mission's progress shown where the ground station
shows it. The flying is the mission tool's (drivers/mission: `mppid-mission from-autopilot`),
which asks for all of it through the control socket (`mission ...`, below).

Download as QGroundControl does it: MISSION_REQUEST_LIST -> MISSION_COUNT -> for each item
MISSION_REQUEST_INT -> MISSION_ITEM_INT, then MISSION_ACK; every answer awaited TIMEOUT_S and
asked for again up to RETRIES times (QGroundControl's 1.5 s and 5), so a lost item is
re-requested. The mission changing while it is read (a second MISSION_COUNT, or a
MISSION_CURRENT with another total) ends the download: MissionChanged. After a download, the
same signs mark the mission changed (`mission status`), which the tool reads between legs.
Home (HOME_POSITION) and the local frame's origin (GPS_GLOBAL_ORIGIN) come with it, asked for
with MAV_CMD_REQUEST_MESSAGE.

Control requests (one line in, one JSON line out, as the others):
    mission download         {"mission": {"dialect", "items": [...], "home", "origin", "fence"}}
    mission status           {"mission_status": {"changed", "current", "total", "downloads"}}
    mission current SEQ TEXT MISSION_SET_CURRENT (the autopilot's current item follows) + STATUSTEXT
    mission reached SEQ      MISSION_ITEM_REACHED
    mission refuse TEXT      a refusal: STATUSTEXT (critical) and the bridge's log
    mission say TEXT         STATUSTEXT (info)
"""
from __future__ import annotations

import logging
import threading
import time

from .autopilot import CommandError
from .autopilots.base import mavlink
from .notices import CRITICAL, INFO

log = logging.getLogger("mppi_mavlink")
TIMEOUT_S = 1.5
RETRIES = 5
MISSION = mavlink.MAV_MISSION_TYPE_MISSION
ITEM_FIELDS = ("seq", "frame", "command", "autocontinue", "param1", "param2", "param3", "param4", "x", "y", "z")


class MissionError(RuntimeError):
    pass


class MissionChanged(MissionError):
    pass


class Missions:
    def __init__(self, settings, link, ap, notices):
        self.s, self.link, self.ap, self.notices = settings, link, ap, notices
        self.cond = threading.Condition()
        self.reading = False
        self.count = None          # the MISSION_COUNT of the download under way
        self.items = {}
        self.acked = None
        self.changed_why = ""      # why the mission read last is no longer the autopilot's
        self.total = None          # items in the mission read last
        self.current = None        # the autopilot's current item (MISSION_CURRENT)
        self.downloads = 0
        self.home = self.origin = None
        self.mission_id = None
        self._current_asked = None    # the link (its conn_gen) MISSION_CURRENT was asked on

    # ---- receive thread --------------------------------------------------------------------
    def on_message(self, t: str, msg) -> bool:
        """The autopilot's mission messages, home and origin (True: handled here)."""
        if t not in ("MISSION_COUNT", "MISSION_ITEM_INT", "MISSION_ACK", "MISSION_CURRENT", "HOME_POSITION",
                     "GPS_GLOBAL_ORIGIN"):
            return False
        if getattr(msg, "mission_type", MISSION) != MISSION:
            return True
        if t in ("MISSION_COUNT", "MISSION_ITEM_INT", "MISSION_ACK") and \
                msg.target_system not in (0, self.s["mavlink"]["system_id"]):
            return True   # the autopilot's answers to a ground station's own upload or download
        with self.cond:
            if t == "MISSION_COUNT":
                self._on_count(msg.count)
            elif t == "MISSION_ITEM_INT" and self.reading:
                self.items[msg.seq] = {k: getattr(msg, k) for k in ITEM_FIELDS}
            elif t == "MISSION_ACK":
                self.acked = msg.type
            elif t == "MISSION_CURRENT":
                self._on_current(msg)
            elif t == "HOME_POSITION":
                self.home = (msg.latitude * 1e-7, msg.longitude * 1e-7, msg.altitude * 1e-3)
            elif t == "GPS_GLOBAL_ORIGIN":
                self.origin = (msg.latitude * 1e-7, msg.longitude * 1e-7, msg.altitude * 1e-3)
            self.cond.notify_all()
        return True

    def _on_count(self, count):
        if self.reading and self.count is None:
            self.count = count
        elif self.reading and count != self.count:
            self.changed_why = f"a new MISSION_COUNT ({count} items, was {self.count}) while it was read"
        elif not self.reading and self.total is not None and count != self.total:
            self.changed_why = f"the autopilot's mission has {count} items now, {self.total} were read"

    def _on_current(self, msg):
        self.current = msg.seq
        expected = self.count if self.reading else self.total
        # ArduPilot's `total` leaves out its home, item 0 (GCS_Common.cpp); PX4 stores no home.
        total = msg.total + (1 if self.s["mavlink"]["dialect"] == "ardupilot" and msg.total else 0)
        if expected is not None and total != expected and not self.changed_why:
            self.changed_why = (f"the autopilot's mission has {total} items now, {expected} "
                                + ("while it was read" if self.reading else "were read"))
        mission_id = getattr(msg, "mission_id", None)   # MAVLink's newer MISSION_CURRENT (with pymavlink's newer)
        if mission_id is not None:
            if self.mission_id not in (None, mission_id):
                self.changed_why = self.changed_why or f"the autopilot's mission_id changed ({mission_id})"
            self.mission_id = mission_id

    # ---- the download (control thread) -------------------------------------------------------
    def _await(self, pred, what: str, send):
        """Sends, waits TIMEOUT_S for pred() (under the condition), and again, RETRIES times."""
        for _ in range(RETRIES):
            self.link.send(send)
            deadline = time.monotonic() + TIMEOUT_S
            with self.cond:
                while not pred() and not self.changed_why and time.monotonic() < deadline:
                    self.cond.wait(deadline - time.monotonic())
                if self.changed_why:
                    raise MissionChanged(f"the mission changed while it was read: {self.changed_why}")
                if pred():
                    return
            log.info("mission download: no %s in %g s, asking again", what, TIMEOUT_S)
        raise MissionError(f"mission download: no {what} after {RETRIES} requests of {TIMEOUT_S:g} s")

    def download(self) -> list[dict]:
        if not self.ap.link_up:
            raise MissionError("mission download: the link to the autopilot is down")
        tgt, comp = self.ap.target_system, self.s["mavlink"]["target_component"]
        with self.cond:
            self.reading, self.count, self.items, self.changed_why = True, None, {}, ""
        try:
            self._await(lambda: self.count is not None, "MISSION_COUNT",
                        lambda mv: mv.mission_request_list_send(tgt, comp, MISSION))
            for seq in range(self.count):
                self._await(lambda: seq in self.items, f"MISSION_ITEM_INT {seq}",
                            lambda mv: mv.mission_request_int_send(tgt, comp, seq, MISSION))
            self.link.send(lambda mv: mv.mission_ack_send(tgt, comp, mavlink.MAV_MISSION_ACCEPTED, MISSION))
            with self.cond:
                self.total, self.downloads = self.count, self.downloads + 1
                return [self.items[i] for i in range(self.count)]
        finally:
            with self.cond:
                self.reading = False

    def _ask_for_current(self):
        """MISSION_CURRENT once a second (how a change is seen; ArduPilot sends a companion's
        link only what it asked for); once per link, a refusal logged."""
        if self._current_asked == self.link.conn_gen:
            return
        self._current_asked = self.link.conn_gen
        try:
            self.ap.command_long(mavlink.MAV_CMD_SET_MESSAGE_INTERVAL, [mavlink.MAVLINK_MSG_ID_MISSION_CURRENT, 1e6],
                                 "stream MISSION_CURRENT")
        except CommandError as e:
            log.warning("%s: a mission changed in flight may go unseen", e)

    def _home_and_origin(self) -> tuple:
        for msg_id, attr in ((mavlink.MAVLINK_MSG_ID_HOME_POSITION, "home"),
                             (mavlink.MAVLINK_MSG_ID_GPS_GLOBAL_ORIGIN, "origin")):
            with self.cond:
                setattr(self, attr, None)
            try:
                self.ap.command_long(mavlink.MAV_CMD_REQUEST_MESSAGE, [msg_id], f"request {attr}")
            except CommandError as e:
                raise MissionError(str(e)) from None
            deadline = time.monotonic() + TIMEOUT_S
            with self.cond:
                while getattr(self, attr) is None and time.monotonic() < deadline:
                    self.cond.wait(deadline - time.monotonic())
            if getattr(self, attr) is None:
                raise MissionError(f"mission download: no {attr.upper()} message from the autopilot")
        return self.home, self.origin

    def guided_item_why(self) -> str:
        """'' when the autopilot's current item is a NAV_GUIDED_ENABLE with param1 > 0 in the
        mission read last; else why not."""
        with self.cond:
            if self.total is None:
                return "no mission read yet (mission download)"
            if self.changed_why:
                return f"the mission changed: {self.changed_why}"
            it = self.items.get(self.current)
        if it is None or it["command"] != mavlink.MAV_CMD_NAV_GUIDED_ENABLE or not it["param1"] > 0.5:
            return f"the autopilot's current item ({self.current}) is not a NAV_GUIDED_ENABLE with param1 1"
        return ""

    # ---- control requests --------------------------------------------------------------------
    def execute(self, args: list[str]) -> dict:
        what = args[0] if args else ""
        try:
            if what == "download":
                self._ask_for_current()
                items = self.download()
                home, origin = self._home_and_origin()
                fence = {k: v for k, v in self.s["fence"].items() if v is not None}
                log.info("mission read from the autopilot: %d items", len(items))
                return {"ok": True, "message": f"{len(items)} items", "mission": {
                    "dialect": self.s["mavlink"]["dialect"], "items": items, "home": home, "origin": origin,
                    "fence": fence, "current": self.current}}
            if what == "status":
                with self.cond:
                    st = {"changed": self.changed_why, "current": self.current, "total": self.total,
                          "downloads": self.downloads}
                return {"ok": True, "message": st["changed"] or "unchanged", "mission_status": st}
            return self._progress(what, args[1:])
        except MissionError as e:
            log.error("%s", e)
            return {"ok": False, "message": str(e), "changed": isinstance(e, MissionChanged)}
        except (ValueError, IndexError):
            return {"ok": False, "message": f"mission: bad request {' '.join(args)!r}"}

    def _progress(self, what: str, rest: list[str]) -> dict:
        tgt, comp = self.ap.target_system, self.s["mavlink"]["target_component"]
        if what == "current":
            seq = int(rest[0])
            self.link.send(lambda mv: mv.mission_set_current_send(tgt, comp, seq))
            if rest[1:]:
                self.notices.tell(INFO, " ".join(rest[1:]))
            return {"ok": True, "message": f"current item {seq}"}
        if what == "reached":
            seq = int(rest[0])
            self.link.send(lambda mv: mv.mission_item_reached_send(seq))
            return {"ok": True, "message": f"item {seq} reached"}
        if what in ("refuse", "say") and rest:
            text = " ".join(rest)
            (log.error if what == "refuse" else log.info)("%s", text)
            self.notices.tell(CRITICAL if what == "refuse" else INFO, text)
            return {"ok": True, "message": text}
        return {"ok": False, "message": "mission: download, status, current SEQ [TEXT], reached SEQ, refuse TEXT, "
                                        "say TEXT"}
