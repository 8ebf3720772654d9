"""The bridge: autopilot telemetry (MAVLink) -> vehicle_state_t (LCM); mppid's command_t
(thrust N, body rates FLU) -> SET_ATTITUDE_TARGET (thrust 0..1, body rates FRD).

It composes its rooms: the link (link.py), the autopilot as seen and asked (autopilot.py),
its profile (autopilots/px4.py, autopilots/ardupilot.py), telemetry -> state (state.py), the
forwarding gate (gate.py, pure) and forwarding (forwarding.py), the engagement (engagement.py)
and its failsafe (failsafe.py), the flight checks (checks.py), what the operator is told
(notices.py), requests to mppid (mppid_link.py), the reports (report.py) and the map sent to
the autopilot (obstacle_distance.py).

Threads: the MAVLink receive thread (telemetry -> LCM at once, ACKs, params), the LCM
thread (commands -> the wire at once, so the bridge adds no period of its own), the
housekeeping thread (companion HEARTBEAT 1 Hz, link watch, reconnect, the failsafe, link
status), the map-to-the-autopilot thread (OBSTACLE_DISTANCE on the autopilot's clock,
whether mppid flies or not), and the control socket thread (arm / takeoff / offboard / land /
status, one at a time). Nothing is ever re-sent or made up, and nothing engages by itself: after `offboard`,
mppid's stream stopping, the link lost or a mode change made by someone else disengage the
bridge until the next `offboard` (engagement.py, failsafe.py, docs/failsafes.md).
"""
from __future__ import annotations

import logging
import threading
import time

from . import autopilots, lcm_types, realtime, report, telemetry
from .autopilot import Autopilot, CommandError
from .autopilots import decode_param  # noqa: F401  (re-exported: test_frames)
from .autopilots.base import mavlink
from .checks import NOT_READ, FlightChecks
from .engagement import DISENGAGED, ENGAGED, PRESTREAM, Engagement
from .failsafe import Failsafe
from .forwarding import COUNTERS, Forwarder
from .link import Link
from .missions import Missions
from .mppid_link import MppidParams
from .notices import CRITICAL, INFO, NOTICE, WARNING, Notices
from .obstacle_distance import ObstacleSender
from .state import StatePublisher, mono_us, rotate as _rotate, wall_us  # noqa: F401  (re-exported)

log = logging.getLogger("mppi_mavlink")
STATE_TYPES = ("ODOMETRY", "ATTITUDE_QUATERNION", "LOCAL_POSITION_NED")
TAKEOFF_STATES = (mavlink.MAV_LANDED_STATE_TAKEOFF, mavlink.MAV_LANDED_STATE_ON_GROUND)

__all__ = ["Bridge", "CommandError", "decode_param", "mono_us", "wall_us"]


class Bridge:
    def __init__(self, settings, lcm_url: str | None = None):
        self.s = settings
        m, l = settings["mavlink"], settings["lcm"]
        self.dialect = m["dialect"]
        self.profile = autopilots.load(self.dialect)
        self.link = Link(m, self.dialect)
        self.lcm_url = lcm_url or l["url"]
        self.mppi_lcm = lcm_types.import_mppi_lcm()
        self.link_t = lcm_types.import_link_type()
        import lcm as _lcm
        self.lc = _lcm.LCM(self.lcm_url)
        self.stop = threading.Event()
        self.counters = dict.fromkeys(COUNTERS, 0)
        self.ap = Autopilot(m, self.link, self.profile, threading.Condition())
        self.checks = FlightChecks(settings, self.profile)
        self.engagement = Engagement(self.profile.prestream, self._on_engagement)
        self.states = StatePublisher(settings, self.mppi_lcm, self._publish, self.counters)
        self.fwd = Forwarder(settings, self.mppi_lcm, self.link, self.ap, self.states, self.engagement, self.checks,
                             lambda on, why: self._publish_link(force=True))
        self.mppid = MppidParams(self.mppi_lcm, self._publish, l["params_channel"], m["command_timeout_s"])
        self.notices = Notices(self.link)
        self.missions = Missions(settings, self.link, self.ap, self.notices)   # the operator's mission (missions.py)
        self.failsafe = Failsafe(settings, self.engagement, self.fwd, self.ap, self.profile, self.notices,
                                 self.states)
        self.fwd.on_mppid_restart = lambda: self.failsafe.stream_lost("mppid restarted (its command seq stepped back)")
        self.told_refusal = ""
        self.lc.subscribe(l["command_channel"], self.fwd.on_command)
        self.lc.subscribe(l["status_channel"], self.fwd.on_status)
        self.lc.subscribe(l["param_result_channel"], self.mppid.on_result)
        self.obstacles = ObstacleSender(settings, self.link, self.profile, self.counters,
                                        self.mppi_lcm.local_map_t._get_packed_fingerprint())
        if settings["obstacle_distance"]["enabled"]:
            self.states.on_published = self.obstacles.on_state
            self.lc.subscribe(settings["obstacle_distance"]["map_channel"], self.obstacles.on_map)
        self.link_up_mono = None
        self.link_seq = 0

    def _publish(self, channel: str, data: bytes):
        self.lc.publish(channel, data)

    @property
    def refusal(self) -> str:
        return self.checks.refusal

    # ---- receive thread ---------------------------------------------------------------
    def _on_mavlink(self, msg):
        t = msg.get_type()
        if t == "BAD_DATA":
            return
        if t == "HEARTBEAT":
            before = self.ap.on_heartbeat(msg)
            if before is not None:
                was_armed, was_mode = before
                offboard = self.profile.offboard_mode
                self.engagement.watch(self.ap.custom_mode, self.ap.mode, self.ap.armed, was_armed,
                                      offboard(self.ap.custom_mode), None if was_mode is None else offboard(was_mode))
            return
        if not self.ap.from_target(msg):
            return
        if t in STATE_TYPES:
            self.states.on_message(t, msg)
            return
        if self.missions.on_message(t, msg):
            return
        self.ap.on_message(t, msg)
        if t == "EXTENDED_SYS_STATE":
            self.engagement.on_landed_state(msg.landed_state, TAKEOFF_STATES)

    def _on_engagement(self, why: str, changed: bool):
        """After every engagement change: a stopped stream or the link message says so, and
        the ground station is told (STATUSTEXT)."""
        state = self.engagement.snapshot().state
        if self.fwd.streaming and state == DISENGAGED:
            self.fwd.set_streaming(False, why)
        else:
            self._publish_link(force=True)
        if changed:
            self._tell_engagement(state, why)

    def _tell_engagement(self, state: str, why: str):
        if state == ENGAGED:
            self.notices.tell(NOTICE, f"mppid engaged: {why}")
        elif state == PRESTREAM:
            self.notices.tell(INFO, f"mppid pre-streaming: {why}")
        else:
            self.notices.tell(WARNING, f"mppid disengaged: {why}; send offboard to fly again")

    # ---- housekeeping ------------------------------------------------------------------
    def _housekeeping(self):
        next_hb = next_link = next_reopen = 0.0
        link_period = 1.0 / self.s["lcm"]["link_hz"]
        while not self.stop.is_set():
            now = time.monotonic()
            if now >= next_hb:
                next_hb = now + 1.0
                self._send_heartbeat()
            self._watch_link(now)
            if not self.ap.link_up and now >= next_reopen and (self.link.mav is None or self._link_lost(now)):
                next_reopen = now + self.s["mavlink"]["reconnect_period_s"]
                self.link.reopen()
            self.fwd.check_stream()
            self.failsafe.check(now)
            self._tell_refusal()
            rate = self.states.rate.rate(now)
            if self.checks.check_state_rate(rate, self.ap.link_up, now - (self.link_up_mono or now)):
                self._publish_link(force=True)
            if now >= next_link:
                next_link = now + link_period
                self._publish_link()
            self.stop.wait(0.02)

    def _tell_refusal(self):
        """A refusal to fly, once each time it appears or changes its reason."""
        r = self.refusal if self.ap.link_up and self.refusal != NOT_READ else ""
        if r.split(":")[0] != self.told_refusal.split(":")[0] and r:
            self.notices.tell(CRITICAL, f"mppid refuses to fly: {r}")
        self.told_refusal = r

    def _send_heartbeat(self):
        ok_state = mavlink.MAV_STATE_ACTIVE if self.fwd.streaming else (
            mavlink.MAV_STATE_CRITICAL if self.refusal and self.ap.link_up else mavlink.MAV_STATE_STANDBY)
        self.link.send(lambda mv: mv.heartbeat_send(mavlink.MAV_TYPE_ONBOARD_CONTROLLER,
                                                    mavlink.MAV_AUTOPILOT_INVALID, 0, 0, ok_state))

    def _link_lost(self, now: float) -> bool:
        hb = self.ap.last_hb_mono
        return hb is not None and now - hb > self.s["mavlink"]["reconnect_period_s"]

    def _watch_link(self, now: float):
        """Lost: the next HEARTBEAT is overdue by heartbeat_timeout_s (1 s past PX4's 1 Hz)."""
        ap, timeout = self.ap, self.s["mavlink"]["heartbeat_timeout_s"]
        hb = ap.last_hb_mono
        up = hb is not None and now - hb < ap.hb_period + timeout
        if up == ap.link_up:
            return
        ap.link_up = up
        if up:
            log.info("link up: autopilot %d heartbeat, mode %s, %s", ap.target_system, ap.mode,
                     "armed" if ap.armed else "disarmed")
            self.link_up_mono = now
            realtime.thread(self._on_link_up, "link-up").start()
        else:
            ap.link_losses += 1
            log.error("link lost: autopilot HEARTBEAT overdue by %.1f s (%.1f s since the last)", timeout, now - hb)
            self.failsafe.stream_lost("the link to the autopilot was lost")
        self._publish_link(force=True)

    def _on_link_up(self):
        e = self.engagement.snapshot()
        if e.state == DISENGAGED and self.engagement.transitions:  # missed while the link was down
            self.notices.tell(WARNING, f"mppid disengaged: {e.why}; send offboard to fly again")
        self._request_telemetry()
        self.checks.check_params(self.ap.read_param)
        self._publish_link(force=True)

    def _request_telemetry(self):
        """MAV_CMD_SET_MESSAGE_INTERVAL for every message the bridge reads (telemetry.py); a
        refusal is logged, and the state rate check says what it costs."""
        t = self.s["telemetry"]
        if not t["request"]:
            return
        for mid, name, interval_us in telemetry.requests(self.profile.state_messages, t["state_hz"], t["status_hz"]):
            try:
                self.ap.command_long(mavlink.MAV_CMD_SET_MESSAGE_INTERVAL, [mid, interval_us], f"stream {name}")
            except CommandError as e:
                log.warning("%s", e)
        log.info("telemetry asked for: states at %g Hz, status at %g Hz", t["state_hz"], t["status_hz"])

    def _publish_link(self, force=False):
        self.link_seq += 1
        msg = report.link_message(self, self.link_t())
        msg.seq = self.link_seq
        try:
            self.lc.publish(self.s["lcm"]["link_channel"], msg.encode())
        except OSError:
            pass

    # ---- commands to the autopilot (explicit, from the control socket) -----------------
    def _require_fly(self, what):
        if self.refusal:
            raise CommandError(f"{what} refused: {self.refusal}")
        if what == "offboard" and self.failsafe.fence_breach():
            raise CommandError(f"offboard refused: {self.failsafe.fence_breach()}")

    def do_arm(self):
        self._require_fly("arm")
        self.ap.command_long(mavlink.MAV_CMD_COMPONENT_ARM_DISARM, [1.0], "arm")
        self.ap.wait_mode(lambda: self.ap.armed, "arm")
        return "armed"

    def do_disarm(self):
        self.engagement.disengage("disarm requested")
        self.ap.command_long(mavlink.MAV_CMD_COMPONENT_ARM_DISARM, [0.0], "disarm")
        self.ap.wait_mode(lambda: not self.ap.armed, "disarm")
        return "disarmed"

    def do_takeoff(self, altitude=None):
        self._require_fly("takeoff")
        alt = float(altitude if altitude is not None else self.s["takeoff"]["altitude"])
        self.profile.takeoff(self.ap, self.engagement, alt)
        return f"taking off to {alt:g} m"

    def do_offboard(self):
        self._require_fly("offboard")
        self.engagement.expect_offboard(True)
        try:
            return self._offboard()
        finally:
            self.engagement.expect_offboard(False)

    def _stream_ok(self, what: str) -> str:
        """Waits up to offboard.wait_s for mppid's stream; why it is good (CommandError if not)."""
        deadline = time.monotonic() + self.s["offboard"]["wait_s"]
        ok, why = self.fwd.stream_ok()
        while not ok and time.monotonic() < deadline:
            time.sleep(0.05)
            ok, why = self.fwd.stream_ok()
        if not ok:
            raise CommandError(f"{what} refused: {why}")
        return why

    def _offboard(self):
        self.profile.before_offboard(self.engagement, self.s["offboard"]["takeoff_wait_s"])
        why = self._stream_ok("offboard")
        mode = self.profile.offboard(self.ap)
        self.engagement.engage(self.ap.custom_mode, self.ap.mode)
        self._engaged_now()
        return f"{mode} ({why})"

    def do_segment(self):
        """ArduCopter: engages in AUTO's guided sub-mode, no mode change (docs/missions.md):
        the mission's current item must be a NAV_GUIDED_ENABLE with param1 > 0 of the mission
        read last; the operator's mode switch or a disarm ends it, as after `offboard`."""
        self._require_fly("segment")
        if not self.profile.guided_segments:
            raise CommandError(f"segment refused: {self.profile.name} has no guided segments in its missions")
        if not self.profile.in_mission_mode(self.ap.custom_mode):
            raise CommandError(f"segment refused: the vehicle is in {self.ap.mode}, not AUTO")
        why = self.missions.guided_item_why()
        if why:
            raise CommandError(f"segment refused: {why}")
        stream = self._stream_ok("segment")
        self.engagement.engage(self.ap.custom_mode, self.ap.mode, "`segment` (AUTO's guided sub-mode)")
        self._engaged_now()
        return f"AUTO's guided sub-mode, attitude/rate targets ({stream})"

    def do_resume(self, seq):
        """The vehicle back to the autopilot's own mission from item `seq` (docs/missions.md):
        forwarding stopped, MISSION_SET_CURRENT, then the mission mode (ArduPilot AUTO, PX4
        AUTO.MISSION) if the vehicle is not in it (AUTO's guided sub-mode: it is)."""
        seq = int(seq)
        self.engagement.disengage(f"handed back to the autopilot's mission at item {seq}")
        r = self.missions.execute(["current", str(seq)])
        if not r["ok"]:
            raise CommandError(r["message"])
        if not self.profile.in_mission_mode(self.ap.custom_mode):
            self.profile.mission_mode(self.ap)
        return f"the autopilot flies its mission from item {seq} ({self.ap.mode})"

    def do_rtl(self):
        """Forwarding stopped, the autopilot's own return (PX4 AUTO.RTL, ArduPilot RTL)."""
        self.engagement.disengage("rtl requested: the autopilot's own return")
        self.profile.rtl(self.ap)
        return "returning (the autopilot's RTL)"

    def do_release(self):
        """Forwarding stopped, nothing asked of the autopilot (its mission went on by itself)."""
        self.engagement.disengage("released: the autopilot's mission goes on")
        return "released"

    def _engaged_now(self):
        # Until now mppid's setpoints were not flown (the autopilot's take-off, a pre-stream):
        # what its estimates (disturbance, mass, delay) learnt from them is wrong. Asked for
        # beside `offboard`'s answer; not fatal.
        realtime.thread(self._restart_mppid_estimates, "restart-estimates").start()

    def _restart_mppid_estimates(self):
        why = self.mppid.ask("daemon.restart_estimates", 1.0)
        if why:
            log.warning("engaged, but mppid's estimates were not restarted: %s", why)
        else:
            log.info("mppid's estimates restarted: its setpoints fly from now on")

    def do_land(self):
        self.engagement.disengage("land requested")
        self.profile.land(self.ap)
        return "landing"

    def do_hold(self):
        self.engagement.disengage("hold requested")
        self.profile.hold(self.ap)
        return "holding"

    def do_identify(self, on=1.0):
        """The identification manoeuvre (docs/sysid.md): asks mppid for it (daemon.identify on
        MPPI_PARAMS) and relays its answer. Only while mppid flies the vehicle: armed, its
        setpoints streaming. `identify 0` stops it, at any time."""
        start = on != 0
        if start:
            self._require_fly("identify")
            if not (self.ap.armed and self.fwd.streaming):
                raise CommandError("identify refused: mppid is not flying the vehicle (armed, its setpoints streaming)")
        why = self.mppid.ask("daemon.identify", 1.0 if start else 0.0)
        if why:
            raise CommandError(f"identify: {why}")
        return "identification manoeuvre started (mppid: doublets and thrust steps)" if start else "identification stopped"

    def status(self) -> dict:
        return report.status(self)

    def execute(self, line: str) -> dict:
        parts = line.split()
        if not parts:
            return {"ok": False, "message": "empty command"}
        name, args = parts[0], parts[1:]
        table = {"arm": self.do_arm, "disarm": self.do_disarm, "takeoff": self.do_takeoff,
                 "offboard": self.do_offboard, "land": self.do_land, "hold": self.do_hold, "identify": self.do_identify,
                 "segment": self.do_segment, "resume": self.do_resume, "release": self.do_release, "rtl": self.do_rtl}
        if name == "status":
            return {"ok": True, "message": "status", "status": self.status()}
        if name == "mission":
            return self.missions.execute(args)
        if name not in table:
            return {"ok": False, "message": f"unknown command {name!r} (arm, disarm, takeoff [m], offboard, land, "
                                            f"hold, identify [0|1], segment, resume SEQ, release, rtl, status, "
                                            f"mission ...)"}
        try:
            msg = table[name](*[float(a) for a in args])
            log.info("%s: %s", name, msg)
            return {"ok": True, "message": msg}
        except (CommandError, TypeError, ValueError) as e:
            log.error("%s", e)
            self.notices.tell(WARNING, f"mppid: {e}")
            return {"ok": False, "message": str(e)}

    # ---- run ---------------------------------------------------------------------------
    def start(self):
        try:
            self.link.open()
        except OSError as e:  # a TCP autopilot (a SITL) not listening yet: housekeeping retries
            log.warning("cannot open %s yet (%s): retrying every %g s", self.s["mavlink"]["url"], e,
                        self.s["mavlink"]["reconnect_period_s"])
        prio = self.s["realtime"]["priority"]   # the latency path's threads (realtime.py)
        if prio:
            realtime.settle()
        self.threads = [realtime.thread(f, n, prio) for f, n in (
            (lambda: self.link.receive_loop(self.stop, self._on_mavlink), "mavlink-rx"), (self._lcm_loop, "lcm"),
            (self._housekeeping, "housekeeping"))]
        for t in self.threads:
            t.start()
        self.obstacles.start(self.stop)

    def _lcm_loop(self):
        while not self.stop.is_set():
            try:
                self.lc.handle_timeout(50)
            except Exception:
                log.exception("LCM handle")

    def close(self):
        self.stop.set()
        for t in getattr(self, "threads", []):
            t.join(timeout=2)
        self.link.close()
        self.fwd.close()
