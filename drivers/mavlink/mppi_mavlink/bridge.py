"""The bridge: autopilot telemetry (MAVLink) -> vehicle_state_t (LCM); mppid's command_t
(thrust N, body rates FLU) -> SET_ATTITUDE_TARGET (thrust 0..1, body rates FRD).

Threads: the MAVLink receive thread (telemetry -> LCM at once, ACKs, params), the LCM
thread (commands -> the wire at once, so the bridge adds no period of its own), the
housekeeping thread (companion HEARTBEAT 1 Hz, link watch, reconnect, link status), and the
control socket thread (arm / takeoff / offboard / land / status, one at a time).

The forwarding gate (`_gate`): a command reaches the wire only when its seq advanced, it is
a thrust+rates command, mppid's latest status says healthy and is fresh, it answers a state
the bridge published less than max_state_age_s ago, every value is finite, the thrust map
is known, nothing refuses flight (GUID_OPTIONS, too slow a telemetry stream) and the bridge
is engaged (below). Nothing is ever re-sent or made up: a hung or dead mppid stops the
stream, and the autopilot's offboard-loss failsafe takes over.

Engagement: ArduPilot takes any SET_ATTITUDE_TARGET in GUIDED over its own take-off, so it
gets nothing before `offboard` is requested; PX4 ignores setpoints outside OFFBOARD and needs
a stream before it, so it is pre-streamed from the start, as before. Either way the bridge
disengages (forwards nothing until the next `offboard`) on `land`, `hold`, `disarm`, an
ArduPilot `takeoff`, and on a mode change or disarm made by someone else after `offboard`.
"""
from __future__ import annotations

import json
import logging
import math
import os
import struct
import threading
import time
from collections import OrderedDict

os.environ.setdefault("MAVLINK20", "1")  # ODOMETRY and the SET_ATTITUDE_TARGET extensions
from pymavlink import mavutil  # noqa: E402

from . import clock_sync, frames, lcm_types, signing, telemetry  # noqa: E402
from .thrust import ThrustMap  # noqa: E402

log = logging.getLogger("mppi_mavlink")

mavlink = mavutil.mavlink
PX4_MAIN_OFFBOARD = 6
PX4_MAIN_AUTO = 4
PX4_SUB_LOITER = 3
PX4_SUB_LAND = 6
APM_COPTER_GUIDED = 4
APM_COPTER_LOITER = 5
APM_COPTER_LAND = 9
GUID_OPTIONS_THRUST_AS_THRUST = 8
ATTITUDE_IGNORE = mavlink.ATTITUDE_TARGET_TYPEMASK_ATTITUDE_IGNORE


def mono_us() -> int:
    return time.monotonic_ns() // 1000


def wall_us() -> int:
    return time.time_ns() // 1000


class BootClock:
    """Autopilot boot time -> this machine's wall clock: offset = min(receive - sample),
    the least-delayed sample, relaxed by 100 us/s so clock drift is followed; a boot time
    jumping back more than 1 s (autopilot reboot) restarts it."""

    def __init__(self):
        self.offset = None
        self.last_boot = None
        self.last_wall = None

    def to_wall_us(self, boot_us: int, recv_wall_us: int) -> int:
        off = recv_wall_us - boot_us
        if self.offset is None or boot_us < self.last_boot - 1_000_000:
            self.offset = off
        else:
            relax = 1e-4 * max(0, recv_wall_us - self.last_wall)
            self.offset = min(off, self.offset + relax)
        self.last_boot, self.last_wall = boot_us, recv_wall_us
        return int(boot_us + self.offset)


def decode_param(msg, autopilot: int) -> float:
    """PARAM_VALUE's value: PX4 sends integer parameters byte-wise in the float field;
    ArduPilot casts them to float."""
    v = msg.param_value
    if autopilot == mavlink.MAV_AUTOPILOT_PX4 and msg.param_type in (
            mavlink.MAV_PARAM_TYPE_INT32, mavlink.MAV_PARAM_TYPE_UINT32, mavlink.MAV_PARAM_TYPE_INT16,
            mavlink.MAV_PARAM_TYPE_UINT16, mavlink.MAV_PARAM_TYPE_INT8, mavlink.MAV_PARAM_TYPE_UINT8):
        return float(struct.unpack("<i", struct.pack("<f", v))[0])
    return float(v)


class CommandError(RuntimeError):
    pass


class Bridge:
    def __init__(self, settings, lcm_url: str | None = None):
        self.s = settings
        m, l = settings["mavlink"], settings["lcm"]
        self.dialect = m["dialect"]
        # MAVLink 2 signing (signing.py): the key is read, and its file's permissions
        # checked, before anything is opened; SigningError says what is wrong.
        self.signing_key = signing.load_key(m["signing_key_file"]) if m["signing_key_file"] else None
        self.signing_dropped = {"rejected_unsigned": 0, "rejected_bad_signature": 0}  # of closed connections
        self.lcm_url = lcm_url or l["url"]
        self.mppi_lcm = lcm_types.import_mppi_lcm()
        self.link_t = lcm_types.import_link_type()
        import lcm as _lcm
        self.lc = _lcm.LCM(self.lcm_url)
        self.lc.subscribe(l["command_channel"], self._on_command)
        self.lc.subscribe(l["status_channel"], self._on_status)
        self.lc.subscribe(l["param_result_channel"], self._on_param_result)
        self.param_seq = 0
        self.param_results = {}  # update seq -> param_result_t, mppid's answers to our requests

        self.stop = threading.Event()
        self.send_lock = threading.Lock()   # pymavlink's encoder is not thread-safe
        self.cond = threading.Condition()   # ACKs, PARAM_VALUEs, heartbeats
        self.mav = None
        self.conn_gen = 0

        self._init_link()
        self._init_thrust(settings)
        self._init_engagement()
        self._init_state()
        self._init_forwarding(settings)

    def _init_link(self):
        """The link to the autopilot and what it told us: heartbeat, mode, battery, answers."""
        self.target_system = 0
        self.autopilot_type = mavlink.MAV_AUTOPILOT_PX4 if self.dialect == "px4" else mavlink.MAV_AUTOPILOT_ARDUPILOTMEGA
        self.last_hb_mono = None
        self.hb_period = 1.0      # the autopilot's HEARTBEAT interval, measured (PX4, ArduPilot: 1 s)
        self.link_up = False
        self.link_losses = 0
        self.armed = False
        self.custom_mode = None
        self.base_mode = 0
        self.mode = "unknown"
        self.battery_voltage = -1.0
        self.battery_remaining = -1
        self.acks = {}
        self.params = {}
        self.statustexts = []

    def _init_thrust(self, settings):
        """The thrust map (from the settings or the autopilot's hover thrust) and the refusals to fly."""
        vh = settings["vehicle"]
        self.thrust = None
        self.hover_source = ""
        if vh["hover_thrust"] is not None:
            self.thrust = ThrustMap(vh["mass"], vh["gravity"], float(vh["hover_thrust"]))
            self.hover_source = "settings"
        self.param_refusal = "autopilot parameters not read yet"
        self.rate_refusal = ""
        self.params_checked_gen = -1
        self.state_rate = telemetry.StateRate(1.0)
        self.link_up_mono = None

    def _init_engagement(self):
        """Engagement (module doc): PX4 is pre-streamed from the start, ArduPilot waits for
        `offboard`. engaged_mode: the custom mode `offboard` confirmed; leaving it ends it."""
        self.engaged = self.dialect == "px4"
        self.engaged_mode = None
        self.disengaged_why = "" if self.engaged else "waiting for `offboard`"
        self.landed_state = None
        self.takeoff_in_progress = False

    def _init_state(self):
        """The state stream to mppid: sequence numbers, publish times, the latest odometry."""
        self.boot_clock = clock_sync.ClockSync()  # the autopilot's clock on ours, drift followed
        self.state_seq = 0
        self.state_times = OrderedDict()   # seq -> (monotonic us when published, MAVLink time_usec)
        self.last_odom_mono = None
        self.last_lpn = None
        self.state_lock = threading.Lock()

    def _init_forwarding(self, settings):
        """The command forwarding: its timeouts, the last command and status, counters, the trace."""
        fw = settings["forwarding"]
        self.status_timeout_us = int(fw["status_timeout_s"] * 1e6)
        self.max_state_age_us = int(fw["max_state_age_s"] * 1e6)
        self.restart_gap_us = int(fw["restart_gap_s"] * 1e6)
        self.last_cmd_seq = None
        self.last_status_mono = None
        self.last_status_healthy = False
        self.last_forward_mono = None
        self.ready_since = None
        self.last_ready_mono = None
        self.ready_times = []  # monotonic us of recent commands that passed the gate (offboard's stream check)
        self.counters = dict(setpoints_sent=0, dropped_not_advanced=0, dropped_unhealthy=0, dropped_nonfinite=0,
                             dropped_stale=0, dropped_refused=0, dropped_disengaged=0, dropped_undecodable=0,
                             states_published=0, states_rejected=0)
        self.streaming = False
        self.trace = open(settings["trace"]["file"], "a", buffering=1) if settings["trace"]["file"] else None
        self.link_seq = 0
        self.last_link_key = None

    @property
    def refusal(self) -> str:
        """Why the bridge will not fly ('' when it may): the parameter checks, then the
        telemetry rate."""
        return self.param_refusal or self.rate_refusal

    # ---- the MAVLink connection -------------------------------------------------------
    def _open(self):
        m = self.s["mavlink"]
        url = m["url"]
        conn = mavutil.mavlink_connection(url, baud=m["baud"], source_system=m["system_id"],
                                          source_component=m["component_id"],
                                          autoreconnect=False, robust_parsing=True)
        if self.signing_key is not None:
            signing.install(conn.mav, self.signing_key, m["signing_link_id"])
        old = self.mav
        if old is not None and self.signing_key is not None:
            for k, v in signing.counters(old.mav).items():
                self.signing_dropped[k] += v
        self.mav = conn
        self.conn_gen += 1
        log.info("MAVLink connection %s open (%s dialect, %s)", url, self.dialect,
                 "signed" if self.signing_key is not None else "unsigned")

    def _reopen(self):
        url = self.s["mavlink"]["url"]
        if self.mav is not None and url.startswith(("udpin:", "udp:", "udpout:", "udpbcast:")):
            return  # a datagram socket stays valid; the autopilot simply talks again
        try:
            old = self.mav
            self._open()
            if old is not None:
                try:
                    old.close()
                except Exception:
                    pass
        except Exception as e:
            log.warning("reconnect to %s failed: %s", url, e)

    def _send(self, fn, *args):
        with self.send_lock:
            if self.mav is None:
                return False
            try:
                fn(self.mav.mav, *args)
                return True
            except OSError as e:
                log.debug("send failed: %s", e)
                return False

    # ---- receive thread ---------------------------------------------------------------
    def _rx_loop(self):
        while not self.stop.is_set():
            mav = self.mav
            if mav is None:
                time.sleep(0.05)
                continue
            try:
                msg = mav.recv_match(blocking=True, timeout=0.1)
            except (OSError, ValueError) as e:
                log.debug("receive failed: %s", e)
                time.sleep(0.05)
                continue
            if msg is None:
                continue
            try:
                self._on_mavlink(msg)
            except Exception:
                log.exception("handling %s", msg.get_type())

    def _on_mavlink(self, msg):
        t = msg.get_type()
        if t == "BAD_DATA":
            return
        src = msg.get_srcSystem()
        if t == "HEARTBEAT":
            if msg.autopilot == mavlink.MAV_AUTOPILOT_INVALID or msg.type in (
                    mavlink.MAV_TYPE_GCS, mavlink.MAV_TYPE_ONBOARD_CONTROLLER):
                return  # ground stations, companions (ourselves through a router)
            if self.target_system and src != self.target_system:
                return
            with self.cond:
                if not self.target_system:
                    self.target_system = src
                    log.info("autopilot found: system %d, autopilot type %d", src, msg.autopilot)
                self.autopilot_type = msg.autopilot
                now = time.monotonic()
                if self.last_hb_mono is not None and now - self.last_hb_mono < 5.0:
                    self.hb_period += 0.2 * (min(now - self.last_hb_mono, 2.0) - self.hb_period)
                self.last_hb_mono = now
                was_armed = self.armed
                self.armed = bool(msg.base_mode & mavlink.MAV_MODE_FLAG_SAFETY_ARMED)
                self.base_mode, self.custom_mode = msg.base_mode, msg.custom_mode
                self.mode = mavutil.mode_string_v10(msg)
                self.cond.notify_all()
            self._watch_engagement(was_armed)
            return
        if self.target_system and src != self.target_system:
            return
        if t == "ODOMETRY":
            self._on_odometry(msg)
        elif t == "ATTITUDE_QUATERNION":
            self._on_attitude(msg)
        elif t == "LOCAL_POSITION_NED":
            self.last_lpn = (msg, wall_us())
        elif t == "EXTENDED_SYS_STATE":
            with self.cond:
                self.landed_state = msg.landed_state
                if msg.landed_state != mavlink.MAV_LANDED_STATE_TAKEOFF and msg.landed_state != \
                        mavlink.MAV_LANDED_STATE_ON_GROUND:
                    self.takeoff_in_progress = False
                self.cond.notify_all()
        elif t == "SYS_STATUS":
            self.battery_voltage = msg.voltage_battery / 1000.0 if msg.voltage_battery != 65535 else -1.0
            self.battery_remaining = msg.battery_remaining
        elif t == "COMMAND_ACK":
            with self.cond:
                self.acks[msg.command] = msg.result
                self.cond.notify_all()
        elif t == "PARAM_VALUE":
            name = msg.param_id.rstrip("\x00") if isinstance(msg.param_id, str) else msg.param_id.decode().rstrip("\x00")
            with self.cond:
                self.params[name] = decode_param(msg, self.autopilot_type)
                self.cond.notify_all()
        elif t == "STATUSTEXT":
            text = msg.text if isinstance(msg.text, str) else msg.text.decode(errors="replace")
            text = text.rstrip("\x00")
            log.info("autopilot: %s", text)
            with self.cond:
                self.statustexts = [(tt, x) for tt, x in self.statustexts if time.monotonic() - tt < 2.0]
                self.statustexts.append((time.monotonic(), text))

    def _on_odometry(self, msg):
        if self.s["vehicle"]["state_source"] == "split":
            return
        if msg.frame_id not in (mavlink.MAV_FRAME_LOCAL_NED, mavlink.MAV_FRAME_LOCAL_FRD):
            return
        try:
            q_ned = frames.quat_normalize(tuple(msg.q))
        except ValueError:  # a zero or non-finite quaternion: no attitude, no state
            self.counters["states_rejected"] += 1
            return
        v = (msg.vx, msg.vy, msg.vz)
        if msg.child_frame_id in (mavlink.MAV_FRAME_BODY_FRD, mavlink.MAV_FRAME_BODY_NED):
            v = _rotate(q_ned, v)  # ODOMETRY's velocity is in the child (body) frame
        self.last_odom_mono = time.monotonic()
        self._publish_state(msg.time_usec, (msg.x, msg.y, msg.z), v, q_ned,
                            (msg.rollspeed, msg.pitchspeed, msg.yawspeed))

    def _on_attitude(self, msg):
        src = self.s["vehicle"]["state_source"]
        if src == "odometry":
            return
        if src == "auto" and self.last_odom_mono is not None and time.monotonic() - self.last_odom_mono < 0.5:
            return
        if self.last_lpn is None or wall_us() - self.last_lpn[1] > 200_000:
            return
        p = self.last_lpn[0]
        try:
            q_ned = frames.quat_normalize((msg.q1, msg.q2, msg.q3, msg.q4))
        except ValueError:
            self.counters["states_rejected"] += 1
            return
        self._publish_state(msg.time_boot_ms * 1000, (p.x, p.y, p.z), (p.vx, p.vy, p.vz), q_ned,
                            (msg.rollspeed, msg.pitchspeed, msg.yawspeed))

    def _publish_state(self, boot_us, p_ned, v_ned, q_ned, w_frd):
        p = frames.ned_to_enu(p_ned)
        v = frames.ned_to_enu(v_ned)
        q = frames.q_ned_frd_to_enu_flu(q_ned)
        w = frames.frd_to_flu(w_frd)
        x = list(p) + list(v) + list(q) + list(w)
        if not all(math.isfinite(c) for c in x):
            self.counters["states_rejected"] += 1
            return
        now_wall = wall_us()
        msg = self.mppi_lcm.vehicle_state_t()
        with self.state_lock:
            self.state_seq += 1
            msg.seq = self.state_seq
            self.state_times[msg.seq] = (mono_us(), boot_us)
            while len(self.state_times) > 256:
                self.state_times.popitem(last=False)
        msg.utime = now_wall
        msg.sample_utime = self.boot_clock.update(int(boot_us), now_wall)
        msg.model = self.mppi_lcm.vehicle_state_t.MODEL_QUADROTOR_RATE
        msg.vehicle_count = 1
        msg.nx = 13
        msg.n = 13
        msg.x = x
        self.lc.publish(self.s["lcm"]["state_channel"], msg.encode())
        self.counters["states_published"] += 1
        self.state_rate.add(time.monotonic())

    # ---- LCM thread: the forwarding gate -----------------------------------------------
    def _lcm_loop(self):
        while not self.stop.is_set():
            try:
                self.lc.handle_timeout(50)
            except Exception:
                log.exception("LCM handle")

    def _on_status(self, channel, data):
        try:
            st = self.mppi_lcm.controller_status_t.decode(data)
        except (ValueError, struct.error):  # wrong type, or truncated: not a status
            return
        self.last_status_mono = mono_us()
        self.last_status_healthy = bool(st.healthy) and st.mode != 2

    def _on_param_result(self, channel, data):
        try:
            r = self.mppi_lcm.param_result_t.decode(data)
        except (ValueError, struct.error):
            return
        with self.cond:
            self.param_results[r.update_seq] = r
            self.cond.notify_all()

    def _on_command(self, channel, data):
        now = mono_us()
        try:
            cmd = self.mppi_lcm.command_t.decode(data)
        except (ValueError, struct.error):  # wrong type (fingerprint), truncated, or n the bytes do not back
            self.counters["dropped_undecodable"] += 1
            return
        reason = self._gate(cmd, now)
        if reason is None:
            self._note_ready(now)
            if not self.engaged:
                reason = "disengaged"
        if reason is not None:
            self.counters["dropped_" + reason] += 1
            if self.streaming and (self.last_forward_mono is None or now - self.last_forward_mono > 100_000):
                self._set_streaming(False, reason)
            return
        self._forward(cmd, now)

    def _gate(self, cmd, now) -> str | None:
        mppi_lcm = self.mppi_lcm
        # seq must advance; a step back after a silence is a restarted mppid.
        if self.last_cmd_seq is not None and cmd.seq <= self.last_cmd_seq:
            quiet = self.last_forward_mono is None or now - self.last_forward_mono > self.restart_gap_us
            if cmd.seq == self.last_cmd_seq or not quiet:
                return "not_advanced"
            log.warning("command seq stepped back %d -> %d after %.1f s of silence: mppid restarted",
                        self.last_cmd_seq, cmd.seq, (now - (self.last_forward_mono or now)) / 1e6)
        self.last_cmd_seq = cmd.seq
        if self.refusal:
            return "refused"
        if cmd.kind != mppi_lcm.command_t.KIND_THRUST_RATES or cmd.n < 4 or len(cmd.u) < 4:
            return "refused"
        if cmd.mode not in (mppi_lcm.command_t.MODE_NORMAL, mppi_lcm.command_t.MODE_HOLD_PLAN,
                            mppi_lcm.command_t.MODE_FAILSAFE):
            return "refused"  # a mode this bridge does not know is never forwarded
        if cmd.mode == mppi_lcm.command_t.MODE_FAILSAFE or (
                cmd.mode == mppi_lcm.command_t.MODE_HOLD_PLAN and not self.s["forwarding"]["forward_hold_plan"]):
            return "unhealthy"
        if (self.last_status_mono is None or now - self.last_status_mono > self.status_timeout_us
                or not self.last_status_healthy):
            return "unhealthy"
        u = [float(c) for c in cmd.u[:4]]
        if not all(math.isfinite(c) for c in u):
            return "nonfinite"
        with self.state_lock:
            st = self.state_times.get(cmd.state_seq)
        if st is None or now - st[0] > self.max_state_age_us:
            return "stale"
        if self.thrust is None or not self.link_up or not self.target_system:
            return "refused"
        return None

    def _note_ready(self, now):
        """A command that passed the gate: `offboard` checks the stream of these (forwarded or,
        while disengaged, not)."""
        if self.last_ready_mono is None or now - self.last_ready_mono > 500_000:
            self.ready_since = now
        self.last_ready_mono = now
        self.ready_times.append(now)
        if len(self.ready_times) > 512:
            del self.ready_times[:256]

    def _watch_engagement(self, was_armed: bool):
        """After `offboard`: a mode change or a disarm that the bridge did not ask for ends the
        engagement (the operator, a failsafe or the RC took over)."""
        if not self.engaged or self.engaged_mode is None:
            return
        if self.custom_mode != self.engaged_mode:
            self._disengage(f"mode changed to {self.mode} by someone else")
        elif was_armed and not self.armed:
            self._disengage("the autopilot disarmed")

    def _disengage(self, why: str):
        if self.engaged:
            log.warning("forwarding stopped: %s; nothing goes to the autopilot until the next `offboard`", why)
        self.engaged, self.engaged_mode, self.disengaged_why = False, None, why
        self.takeoff_in_progress = False
        if self.streaming:
            self._set_streaming(False, why)
        else:
            self._publish_link(force=True)

    def _forward(self, cmd, now):
        thrust = self.thrust.to_normalized(float(cmd.u[0]))
        rates = frames.flu_to_frd((float(cmd.u[1]), float(cmd.u[2]), float(cmd.u[3])))
        values = (thrust,) + tuple(rates)
        if not all(math.isfinite(c) for c in values):  # the last gate before the encoder
            self.counters["dropped_nonfinite"] += 1
            return
        m = self.s["mavlink"]
        boot_ms = int(time.monotonic() * 1000) & 0xFFFFFFFF
        ok = self._send(lambda mv: mv.set_attitude_target_send(
            boot_ms, self.target_system, m["target_component"], ATTITUDE_IGNORE, [1.0, 0.0, 0.0, 0.0],
            rates[0], rates[1], rates[2], thrust))
        if not ok:
            return
        sent = mono_us()
        self.counters["setpoints_sent"] += 1
        self.last_forward_mono = sent
        if not self.streaming:
            self._set_streaming(True, "")
        if self.trace is not None:
            st = self.state_times.get(cmd.state_seq, (0, 0))
            self.trace.write(json.dumps({"mono_us": sent, "cmd_seq": cmd.seq, "state_seq": cmd.state_seq,
                                         "state_time_usec": st[1], "state_pub_mono_us": st[0],
                                         "thrust": thrust, "rates_frd": rates}) + "\n")

    def _set_streaming(self, on: bool, reason: str):
        self.streaming = on
        if on:
            log.info("setpoint stream started")
        else:
            log.warning("setpoint stream stopped (%s)", reason or "no fresh command")
        self._publish_link(force=True)

    # ---- housekeeping ------------------------------------------------------------------
    def _housekeeping(self):
        m = self.s["mavlink"]
        next_hb = next_link = next_reopen = 0.0
        link_period = 1.0 / self.s["lcm"]["link_hz"]
        while not self.stop.is_set():
            now = time.monotonic()
            if now >= next_hb:
                next_hb = now + 1.0
                ok_state = mavlink.MAV_STATE_ACTIVE if self.streaming else (
                    mavlink.MAV_STATE_CRITICAL if self.refusal and self.link_up else mavlink.MAV_STATE_STANDBY)
                self._send(lambda mv: mv.heartbeat_send(mavlink.MAV_TYPE_ONBOARD_CONTROLLER,
                                                        mavlink.MAV_AUTOPILOT_INVALID, 0, 0, ok_state))
            hb = self.last_hb_mono
            # Lost: the next HEARTBEAT is overdue by heartbeat_timeout_s (1 s past PX4's 1 Hz).
            up = hb is not None and now - hb < self.hb_period + m["heartbeat_timeout_s"]
            if up != self.link_up:
                self.link_up = up
                if up:
                    log.info("link up: autopilot %d heartbeat, mode %s, %s", self.target_system, self.mode,
                             "armed" if self.armed else "disarmed")
                    self.link_up_mono = now
                    threading.Thread(target=self._on_link_up, daemon=True).start()
                else:
                    self.link_losses += 1
                    log.error("link lost: autopilot HEARTBEAT overdue by %.1f s (%.1f s since the last)",
                              m["heartbeat_timeout_s"], now - hb)
                self._publish_link(force=True)
            lost = hb is not None and now - hb > m["reconnect_period_s"]
            if not up and now >= next_reopen and (self.mav is None or lost):
                next_reopen = now + m["reconnect_period_s"]
                self._reopen()
            if self.streaming and (self.last_forward_mono is None or mono_us() - self.last_forward_mono > 200_000):
                self._set_streaming(False, "no fresh command for 200 ms")
            self._check_state_rate(now)
            if now >= next_link:
                next_link = now + link_period
                self._publish_link()
            self.stop.wait(0.02)

    def _check_state_rate(self, now: float):
        t = self.s["telemetry"]
        why = "" if not self.link_up else telemetry.rate_refusal(
            self.state_rate.rate(now), t["min_state_hz"], now - (self.link_up_mono or now), t["grace_s"])
        changed = bool(why) != bool(self.rate_refusal)
        self.rate_refusal = why  # the text follows the rate; the log and the link message the verdict
        if changed:
            if why:
                log.error("%s", why)
            else:
                log.info("telemetry: states at %.1f Hz", self.state_rate.rate(now))
            self._publish_link(force=True)

    def _publish_link(self, force=False):
        msg = self.link_t()
        msg.utime = wall_us()
        self.link_seq += 1
        msg.seq = self.link_seq
        msg.link_up = int(self.link_up)
        msg.heartbeat_age_s = -1.0 if self.last_hb_mono is None else float(time.monotonic() - self.last_hb_mono)
        msg.link_losses = self.link_losses
        msg.dialect = self.dialect
        msg.target_system = self.target_system
        msg.armed = int(self.armed)
        msg.mode = self.mode
        msg.streaming = int(self.streaming)
        c = self.counters
        msg.setpoints_sent = c["setpoints_sent"]
        msg.dropped_not_advanced = c["dropped_not_advanced"]
        msg.dropped_unhealthy = c["dropped_unhealthy"]
        msg.dropped_nonfinite = c["dropped_nonfinite"]
        msg.dropped_stale = c["dropped_stale"]
        msg.dropped_refused = c["dropped_refused"]
        msg.dropped_undecodable = c["dropped_undecodable"]
        msg.states_rejected = c["states_rejected"]
        msg.hover_thrust = float(self.thrust.hover) if self.thrust else -1.0
        msg.hover_source = self.hover_source
        msg.battery_voltage = float(self.battery_voltage)
        msg.battery_remaining = int(max(-1, min(100, self.battery_remaining)))
        msg.error = self.refusal or ""
        msg.engaged = int(self.engaged)
        msg.dropped_disengaged = c["dropped_disengaged"]
        msg.state_rate_hz = float(self.state_rate.rate(time.monotonic()))
        msg.signing = int(self.signing_key is not None)
        sc = self.signing_counters()
        msg.rejected_unsigned = sc["rejected_unsigned"]
        msg.rejected_bad_signature = sc["rejected_bad_signature"]
        try:
            self.lc.publish(self.s["lcm"]["link_channel"], msg.encode())
        except OSError:
            pass

    # ---- parameters and flight checks ---------------------------------------------------
    def read_param(self, name: str) -> float:
        m = self.s["mavlink"]
        for _ in range(int(m["param_retries"])):
            with self.cond:
                self.params.pop(name, None)
            self._send(lambda mv: mv.param_request_read_send(self.target_system, m["target_component"],
                                                             name.encode(), -1))
            deadline = time.monotonic() + m["param_timeout_s"]
            with self.cond:
                while name not in self.params and time.monotonic() < deadline:
                    self.cond.wait(deadline - time.monotonic())
                if name in self.params:
                    return self.params[name]
        raise CommandError(f"parameter {name}: no PARAM_VALUE after {m['param_retries']} requests")

    def _on_link_up(self):
        self._request_telemetry()
        self._check_params()

    def _request_telemetry(self):
        """MAV_CMD_SET_MESSAGE_INTERVAL for every message the bridge reads (telemetry.py); a
        refusal is logged, and the state rate check says what it costs."""
        t = self.s["telemetry"]
        if not t["request"]:
            return
        for mid, name, interval_us in telemetry.requests(self.dialect, t["state_hz"], t["status_hz"]):
            try:
                self.command_long(mavlink.MAV_CMD_SET_MESSAGE_INTERVAL, [mid, interval_us], f"stream {name}")
            except CommandError as e:
                log.warning("%s", e)
        log.info("telemetry asked for: states at %g Hz, status at %g Hz", t["state_hz"], t["status_hz"])

    def _check_params(self):
        """On every link-up: the hover thrust (unless set in the settings) and, on ArduPilot,
        GUID_OPTIONS bit 3. Sets self.param_refusal to the reason the bridge will not fly, or ''."""
        vh = self.s["vehicle"]
        refusal = ""
        try:
            if self.dialect == "ardupilot":
                g = int(self.read_param("GUID_OPTIONS"))
                if not g & GUID_OPTIONS_THRUST_AS_THRUST:
                    refusal = (f"GUID_OPTIONS={g}: bit 3 (value 8, 'SetAttitudeTarget interprets Thrust As Thrust') "
                               f"is not set, so ArduPilot would read the thrust as a climb rate; refusing to fly. "
                               f"Set GUID_OPTIONS={g | 8} on the autopilot")
            if vh["hover_thrust"] is None:
                name = "MPC_THR_HOVER" if self.dialect == "px4" else "MOT_THST_HOVER"
                h = self.read_param(name)
                if not (0.01 <= h <= 0.99):
                    refusal = refusal or f"{name}={h} is not a usable hover-thrust fraction (0.01..0.99); refusing to fly"
                else:
                    self.thrust = ThrustMap(vh["mass"], vh["gravity"], h)
                    self.hover_source = f"param {name}"
                    log.info("hover thrust %.3f from %s: %.2f N at full thrust", h, name, self.thrust.max_thrust)
        except CommandError as e:
            refusal = f"{e}; refusing to fly (set vehicle.hover_thrust to fly without it)" if not refusal else refusal
        if refusal:
            log.error("%s", refusal)
        elif self.param_refusal:
            log.info("flight checks passed")
        self.param_refusal = refusal
        self._publish_link(force=True)

    # ---- commands to the autopilot (explicit, from the control socket) -----------------
    def command_long(self, command: int, params, name: str) -> None:
        m = self.s["mavlink"]
        if not self.link_up:
            raise CommandError(f"{name}: link to the autopilot is down")
        for attempt in range(int(m["command_retries"])):
            with self.cond:
                self.acks.pop(command, None)
            p = list(params) + [0.0] * (7 - len(params))
            self._send(lambda mv: mv.command_long_send(self.target_system, m["target_component"], command,
                                                       attempt, *p))
            deadline = time.monotonic() + m["command_timeout_s"]
            with self.cond:
                while command not in self.acks and time.monotonic() < deadline:
                    self.cond.wait(deadline - time.monotonic())
                result = self.acks.get(command)
            if result is None:
                continue
            if result == mavlink.MAV_RESULT_ACCEPTED:
                return
            if result == mavlink.MAV_RESULT_IN_PROGRESS:
                continue
            rname = mavlink.enums["MAV_RESULT"][result].name if result in mavlink.enums["MAV_RESULT"] else str(result)
            time.sleep(0.05)  # the STATUSTEXT saying why comes right after the ACK
            with self.cond:
                why = "; ".join(x for tt, x in self.statustexts if time.monotonic() - tt < 1.0)
            raise CommandError(f"{name}: autopilot answered {rname}" + (f" ({why})" if why else ""))
        raise CommandError(f"{name}: no COMMAND_ACK after {m['command_retries']} attempts "
                           f"of {m['command_timeout_s']} s")

    def _wait_mode(self, predicate, what: str):
        deadline = time.monotonic() + self.s["mavlink"]["mode_confirm_timeout_s"]
        with self.cond:
            while not predicate() and time.monotonic() < deadline:
                self.cond.wait(max(0.0, deadline - time.monotonic()))
            if not predicate():
                raise CommandError(f"{what}: accepted, but the autopilot's HEARTBEAT still reports {self.mode}")

    def _px4_main(self):
        return None if self.custom_mode is None else (self.custom_mode >> 16) & 0xFF

    def _require_fly(self, what):
        if self.refusal:
            raise CommandError(f"{what} refused: {self.refusal}")

    def do_arm(self):
        self._require_fly("arm")
        self.command_long(mavlink.MAV_CMD_COMPONENT_ARM_DISARM, [1.0], "arm")
        self._wait_mode(lambda: self.armed, "arm")
        return "armed"

    def do_disarm(self):
        self._disengage("disarm requested")
        self.command_long(mavlink.MAV_CMD_COMPONENT_ARM_DISARM, [0.0], "disarm")
        self._wait_mode(lambda: not self.armed, "disarm")
        return "disarmed"

    def do_takeoff(self, altitude=None):
        self._require_fly("takeoff")
        alt = float(altitude if altitude is not None else self.s["takeoff"]["altitude"])
        if self.dialect == "px4":
            # PX4 reads param7 as AMSL; NaN takes MIS_TAKEOFF_ALT (above home), set first.
            self._send(lambda mv: mv.param_set_send(self.target_system, self.s["mavlink"]["target_component"],
                                                    b"MIS_TAKEOFF_ALT", alt, mavlink.MAV_PARAM_TYPE_REAL32))
            self.command_long(mavlink.MAV_CMD_NAV_TAKEOFF, [-1.0, 0, 0, math.nan, math.nan, math.nan, math.nan],
                              "takeoff")
        else:
            # ArduPilot flies any attitude target in GUIDED instead of its take-off.
            self._disengage("takeoff requested: the autopilot's own take-off flies")
            if self.custom_mode != APM_COPTER_GUIDED:
                self.command_long(mavlink.MAV_CMD_DO_SET_MODE,
                                  [mavlink.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED, APM_COPTER_GUIDED], "mode GUIDED")
            self.command_long(mavlink.MAV_CMD_NAV_TAKEOFF, [0, 0, 0, 0, 0, 0, alt], "takeoff")
            self.takeoff_in_progress = True
        return f"taking off to {alt:g} m"

    def stream_ok(self) -> tuple[bool, str]:
        """Whether mppid's commands pass the gate fast enough and long enough for `offboard`
        (on PX4 they are on the wire already: the pre-stream)."""
        o = self.s["offboard"]
        now = mono_us()
        if self.ready_since is None or self.last_ready_mono is None or now - self.last_ready_mono > 500_000:
            return False, "no command stream (is mppid running, healthy and getting states?)"
        if now - self.ready_since < o["prestream_s"] * 1e6:
            return False, f"stream only {(now - self.ready_since) / 1e6:.2f} s old"
        window = [t for t in self.ready_times if now - t <= o["prestream_s"] * 1e6]
        rate = len(window) / o["prestream_s"]
        if rate < o["min_rate_hz"]:
            return False, f"stream at {rate:.1f} Hz, below {o['min_rate_hz']:g} Hz"
        return True, f"stream at {rate:.1f} Hz for {(now - self.ready_since) / 1e6:.1f} s"

    def _wait_takeoff_done(self):
        """ArduPilot: `offboard` right after `takeoff` waits for the take-off to end (landed
        state IN_AIR), or mppid's first setpoint would take it over."""
        deadline = time.monotonic() + self.s["offboard"]["takeoff_wait_s"]
        with self.cond:
            while self.takeoff_in_progress and time.monotonic() < deadline:
                self.cond.wait(max(0.0, deadline - time.monotonic()))
            if self.takeoff_in_progress:
                raise CommandError(f"offboard refused: the take-off is not complete after "
                                   f"{self.s['offboard']['takeoff_wait_s']:g} s")

    def do_offboard(self):
        self._require_fly("offboard")
        if self.dialect == "px4":
            self.engaged = True  # pre-stream again after a stop
        else:
            self._wait_takeoff_done()
        deadline = time.monotonic() + self.s["offboard"]["wait_s"]
        ok, why = self.stream_ok()
        while not ok and time.monotonic() < deadline:
            time.sleep(0.05)
            ok, why = self.stream_ok()
        if not ok:
            raise CommandError(f"offboard refused: {why}")
        if self.dialect == "px4":
            self.command_long(mavlink.MAV_CMD_DO_SET_MODE,
                              [mavlink.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED, PX4_MAIN_OFFBOARD, 0], "mode OFFBOARD")
            self._wait_mode(lambda: self._px4_main() == PX4_MAIN_OFFBOARD, "mode OFFBOARD")
            self._engage()
            return f"OFFBOARD ({why})"
        self.command_long(mavlink.MAV_CMD_DO_SET_MODE,
                          [mavlink.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED, APM_COPTER_GUIDED], "mode GUIDED")
        self._wait_mode(lambda: self.custom_mode == APM_COPTER_GUIDED, "mode GUIDED")
        self._engage()
        return f"GUIDED, attitude/rate targets ({why})"

    def _engage(self):
        with self.cond:
            self.engaged, self.engaged_mode, self.disengaged_why = True, self.custom_mode, ""
        log.info("engaged in mode %s: mppid's setpoints go to the autopilot", self.mode)
        self._publish_link(force=True)
        # Until now mppid's setpoints were not flown (the autopilot's take-off, a pre-stream):
        # what its estimates (disturbance, mass, delay) learnt from them is wrong. Asked for
        # beside `offboard`'s answer; not fatal.
        threading.Thread(target=self._restart_mppid_estimates, name="restart-estimates", daemon=True).start()

    def _restart_mppid_estimates(self):
        why = self._ask_mppid("daemon.restart_estimates", 1.0)
        if why:
            log.warning("engaged, but mppid's estimates were not restarted: %s", why)
        else:
            log.info("mppid's estimates restarted: its setpoints fly from now on")

    def do_land(self):
        self._disengage("land requested")
        if self.dialect == "px4":
            self.command_long(mavlink.MAV_CMD_NAV_LAND, [0, 0, 0, math.nan, math.nan, math.nan, math.nan], "land")
        else:
            self.command_long(mavlink.MAV_CMD_DO_SET_MODE,
                              [mavlink.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED, APM_COPTER_LAND], "mode LAND")
        return "landing"

    def do_hold(self):
        self._disengage("hold requested")
        if self.dialect == "px4":
            self.command_long(mavlink.MAV_CMD_DO_SET_MODE,
                              [mavlink.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED, PX4_MAIN_AUTO, PX4_SUB_LOITER], "mode HOLD")
        else:
            self.command_long(mavlink.MAV_CMD_DO_SET_MODE,
                              [mavlink.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED, APM_COPTER_LOITER], "mode LOITER")
        return "holding"

    def _ask_mppid(self, key: str, value: float) -> str:
        """A parameter update for mppid on MPPI_PARAMS, and its answer: "" when applied, else why not."""
        msg = self.mppi_lcm.param_update_t()
        with self.cond:
            self.param_seq += 1
            msg.seq = self.param_seq
        msg.utime, msg.key, msg.value = int(time.time() * 1e6), key, float(value)
        self.lc.publish(self.s["lcm"]["params_channel"], msg.encode())
        deadline = time.monotonic() + self.s["mavlink"]["command_timeout_s"]
        with self.cond:
            while msg.seq not in self.param_results and time.monotonic() < deadline:
                self.cond.wait(max(0.0, deadline - time.monotonic()))
            r = self.param_results.pop(msg.seq, None)
        if r is None:
            return "mppid did not answer (is it running on this LCM bus?)"
        if r.status != self.mppi_lcm.param_result_t.STATUS_APPLIED:
            return f"refused by mppid: {r.reason}"
        return ""

    def do_identify(self, on=1.0):
        """The identification manoeuvre (docs/sysid.md): asks mppid for it (daemon.identify on
        MPPI_PARAMS) and relays its answer. Only while mppid flies the vehicle: armed, its
        setpoints streaming. `identify 0` stops it, at any time."""
        start = on != 0
        if start:
            self._require_fly("identify")
            if not (self.armed and self.streaming):
                raise CommandError("identify refused: mppid is not flying the vehicle (armed, its setpoints streaming)")
        why = self._ask_mppid("daemon.identify", 1.0 if start else 0.0)
        if why:
            raise CommandError(f"identify: {why}")
        return "identification manoeuvre started (mppid: doublets and thrust steps)" if start else "identification stopped"

    def signing_counters(self) -> dict:
        """Messages the signature check dropped, since start (0 on an unsigned link)."""
        out = dict(self.signing_dropped)
        mav = self.mav
        if mav is not None and self.signing_key is not None:
            for k, v in signing.counters(mav.mav).items():
                out[k] += v
        return out

    def status(self) -> dict:
        hb = self.last_hb_mono
        return {"link_up": self.link_up, "heartbeat_age_s": None if hb is None else round(time.monotonic() - hb, 3),
                "link_losses": self.link_losses, "dialect": self.dialect, "target_system": self.target_system,
                "armed": self.armed, "mode": self.mode, "streaming": self.streaming,
                "hover_thrust": self.thrust.hover if self.thrust else None, "hover_source": self.hover_source,
                "refusal": self.refusal, "battery_voltage": self.battery_voltage,
                "engaged": self.engaged, "disengaged_why": self.disengaged_why,
                "state_rate_hz": round(self.state_rate.rate(time.monotonic()), 1),
                "landed_state": self.landed_state,
                "controller_healthy": self.last_status_healthy, "signing": self.signing_key is not None,
                **self.signing_counters(), **self.counters}

    def execute(self, line: str) -> dict:
        parts = line.split()
        if not parts:
            return {"ok": False, "message": "empty command"}
        name, args = parts[0], parts[1:]
        table = {"arm": self.do_arm, "disarm": self.do_disarm, "takeoff": self.do_takeoff,
                 "offboard": self.do_offboard, "land": self.do_land, "hold": self.do_hold, "identify": self.do_identify}
        if name == "status":
            return {"ok": True, "message": "status", "status": self.status()}
        if name not in table:
            return {"ok": False, "message": f"unknown command {name!r} (arm, disarm, takeoff [m], offboard, land, "
                                            f"hold, identify [0|1], status)"}
        try:
            msg = table[name](*[float(a) for a in args])
            log.info("%s: %s", name, msg)
            return {"ok": True, "message": msg}
        except (CommandError, TypeError, ValueError) as e:
            log.error("%s", e)
            return {"ok": False, "message": str(e)}

    # ---- run ---------------------------------------------------------------------------
    def start(self):
        try:
            self._open()
        except OSError as e:  # a TCP autopilot (a SITL) not listening yet: housekeeping retries
            log.warning("cannot open %s yet (%s): retrying every %g s", self.s["mavlink"]["url"], e,
                        self.s["mavlink"]["reconnect_period_s"])
        self.threads = [threading.Thread(target=f, name=n, daemon=True) for f, n in (
            (self._rx_loop, "mavlink-rx"), (self._lcm_loop, "lcm"), (self._housekeeping, "housekeeping"))]
        for t in self.threads:
            t.start()

    def close(self):
        self.stop.set()
        for t in getattr(self, "threads", []):
            t.join(timeout=2)
        if self.mav is not None:
            try:
                self.mav.close()
            except Exception:
                pass
        if self.trace is not None:
            self.trace.close()


def _rotate(q, v):
    """v rotated by the unit quaternion q (w, x, y, z): R(q) v."""
    w, x, y, z = q
    vx, vy, vz = v
    # t = 2 q_vec x v; v' = v + w t + q_vec x t
    tx = 2.0 * (y * vz - z * vy)
    ty = 2.0 * (z * vx - x * vz)
    tz = 2.0 * (x * vy - y * vx)
    return (vx + w * tx + (y * tz - z * ty),
            vy + w * ty + (z * tx - x * tz),
            vz + w * tz + (x * ty - y * tx))
