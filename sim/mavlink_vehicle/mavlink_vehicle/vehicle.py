"""The simulated autopilot: a rate-controlled quadrotor (plant.py) behind a MAVLink front end
with PX4's custom modes (or ArduPilot Copter's, --autopilot ardupilot), arming checks,
its own position controller for take-off, hold and landing, and the offboard-loss failsafe.

Two ArduPilot behaviours that a bridge must handle, as ArduCopter has them: it streams no
telemetry to a link until the link asks (MAV_CMD_SET_MESSAGE_INTERVAL; at most state_hz),
and an attitude target received in GUIDED during its own take-off takes the vehicle over
(the take-off is abandoned where it is: `takeoff_taken_over` in the events).

One thread, paced by the wall clock: receive whatever MAVLink is waiting, step the physics
(RK4, physics_hz) up to now, send telemetry at state_hz, run the mission at 10 Hz; sleep in
select() on the link's socket until the next physics step, so a setpoint is applied within
one physics step of its arrival.
"""
from __future__ import annotations

import json
import math
import os
import select
import time

os.environ.setdefault("MAVLINK20", "1")
from pymavlink import mavutil  # noqa: E402

from mppi_mavlink.layout import QuadrotorRate as Q  # noqa: E402

from . import auto as auto_mod, missions as missions_mod, ned, plant as pl  # noqa: E402

mavlink = mavutil.mavlink

# PX4 custom mode: main mode in bits 16..23, sub mode in bits 24..31.
PX4_MODES = {"MANUAL": (1, 0), "POSCTL": (3, 0), "OFFBOARD": (6, 0), "AUTO.TAKEOFF": (4, 2),
             "AUTO.LOITER": (4, 3), "AUTO.MISSION": (4, 4), "AUTO.RTL": (4, 5), "AUTO.LAND": (4, 6)}
# PX4's COM_OBL_RC_ACT values this stand-in has (others: land).
OFFBOARD_LOSS_ACTIONS = {0: "POSCTL", 4: "AUTO.LAND", 5: "AUTO.LOITER"}
# PX4's NAV_DLL_ACT (data link lost) values this stand-in has (0: disabled; others: land).
DATALINK_LOSS_ACTIONS = {1: "AUTO.LOITER", 3: "AUTO.LAND"}
# ArduPilot Copter custom modes.
APM_MODES = {"STABILIZE": 0, "AUTO": 3, "GUIDED": 4, "LOITER": 5, "RTL": 6, "LAND": 9, "BRAKE": 17}
# The modes that fly the stored mission (auto.py).
MISSION_MODES = ("AUTO", "AUTO.MISSION")


def wall_us():
    return time.time_ns() // 1000


def connect(url, system_id, signing_key=None):
    """The autopilot's end of the link. With a signing key, as an autopilot with signing on:
    everything it sends is signed, and it takes only messages signed with the key (pymavlink's
    own implementation, not the bridge's: the test checks one against the other)."""
    conn = mavutil.mavlink_connection(url, source_system=system_id, source_component=1)
    if signing_key is not None:
        conn.setup_signing(signing_key, sign_outgoing=True, allow_unsigned_callback=lambda mav, msg_id: False)
    return conn


def default_params(offboard_loss_s):
    """The stand-in autopilot's parameters before --param.

    COM_OBL_RC_ACT: what PX4 does COM_OF_LOSS_T after the offboard setpoints stop (0 Position,
    4 Land, 5 Hold here; real PX4's default is 0, this stand-in's 4 so that it lands as it always did).
    The battery failsafe (PX4 COM_LOW_BAT_ACT 2 or 3: land at BAT_CRIT_THR; ArduPilot
    BATT_FS_LOW_ACT 1: LAND at BATT_LOW_PCT, a stand-in simplification of its voltage and
    capacity levels), with a battery that drains SIM_BATT_DRAIN %/s while armed (0: never);
    ArduPilot's ground-station failsafe (FS_GCS_ENABLE 5: LAND after FS_GCS_TIMEOUT s
    without a ground station's HEARTBEAT, once one was heard, armed); PX4's data-link-loss
    failsafe (NAV_DLL_ACT 1 Hold, 3 Land after COM_DL_LOSS_T s, the same way; 0, PX4's
    default, off)."""
    return {"MPC_THR_HOVER": 0.4, "MIS_TAKEOFF_ALT": 2.0, "COM_OF_LOSS_T": offboard_loss_s,
            "COM_OBL_RC_ACT": 4.0, "GUID_OPTIONS": 8.0, "MOT_THST_HOVER": 0.4, "COM_DISARM_LAND": 1.0,
            "COM_LOW_BAT_ACT": 0.0, "BAT_CRIT_THR": 0.07, "BATT_FS_LOW_ACT": 0.0, "BATT_LOW_PCT": 15.0,
            "SIM_BATT_DRAIN": 0.0, "FS_GCS_ENABLE": 0.0, "FS_GCS_TIMEOUT": 5.0,
            "NAV_DLL_ACT": 0.0, "COM_DL_LOSS_T": 10.0,
            "SIM_RC_THROTTLE": 0.0, "PILOT_SPEED_DN": 0.0, "PILOT_SPEED_UP": 250.0, "SIM_MIS_DROP": -1.0,
            "SIM_MIS_DROP_N": 1.0, "WPNAV_SPEED": 500.0, "MPC_XY_CRUISE": 5.0, "GUID_TIMEOUT": 3.0}


class Vehicle:
    # ArduPilot flies a rate setpoint for at most this long; later, the vehicle holds level until
    # the next one. PX4 flies the last one until COM_OF_LOSS_T runs out, as the real one does
    # (PX4 SIH, docs/px4.md: 3 rad/s of roll flown on through a 0.5 s pause turned it over).
    SETPOINT_HOLD_S = 0.1

    def __init__(self, url, autopilot="px4", params=None, world=None, mission=None, out=None, physics_hz=500.0,
                 state_hz=50.0, system_id=1, offboard_loss_s=0.5, start=(0.0, 0.0, 0.0), mass=1.0, signing_key=None, clock_drift=0.0):
        self.ap = autopilot
        self.conn = connect(url, system_id, signing_key)
        self.params = default_params(offboard_loss_s)
        self.battery = 90.0                # % remaining
        self.last_gcs_t = None
        self.param_types = {"GUID_OPTIONS": mavlink.MAV_PARAM_TYPE_INT32}
        self.params.update(params or {})
        hover = self.params["MOT_THST_HOVER" if autopilot == "ardupilot" else "MPC_THR_HOVER"]
        self.pp = pl.Params(mass=mass, max_thrust=mass * 9.81 / hover)
        self.plant = pl.Plant(self.pp, start)
        self.dt = 1.0 / physics_hz
        self.state_period = 1.0 / state_hz
        self.mission = mission
        self.world = world
        self.out = out
        self.boot = time.monotonic()
        self.t = 0.0                       # simulated time since boot, follows the wall clock
        self.clock_rate = 1.0 + clock_drift  # the autopilot's clock (its stamps) runs this fast
        self.armed = False
        self.mode = "AUTO.LOITER" if autopilot == "px4" else "STABILIZE"
        self.setpoint = None               # (thrust 0..1, p, q, r FRD)
        self.setpoint_t = None
        self.takeoff_alt = None
        self.hold_sp = None                # position setpoint of the vehicle's own controller
        self.stale_hold = None
        # PX4: in its offboard-loss fallback (COM_OBL_RC_ACT) with OFFBOARD still the user's
        # intended mode: setpoints arriving again take it back into OFFBOARD by itself, as the
        # real one does (PX4 SITL, docs/px4.md: the link cut for 3 s, PX4 went Hold and back).
        self.offboard_fallback = False
        self.landed_since = None
        self.counters = {"setpoints": 0, "setpoints_rejected": 0, "nonfinite_rejected": 0, "failsafes": 0,
                         "overruns": 0, "heartbeats_from_companion": 0, "states_sent": 0}
        self.events = []
        self.companion = None
        self.wire = open(os.path.join(out, "wire.jsonl"), "w") if out else None
        self.truth = open(os.path.join(out, "truth.jsonl"), "w") if out else None
        self.gcs_seen = set()
        self.text_parts = {}               # STATUSTEXT chunks by id
        # ArduPilot: message id -> [interval s, next send time], set by SET_MESSAGE_INTERVAL.
        self.streams = {}
        self.taking_off = False
        # The mission protocol (missions.py): the mission a ground station uploaded; home where it starts.
        self.missions = missions_mod.MissionStore(self.conn, autopilot, self.event, self.params)
        self.missions.home_enu = tuple(float(c) for c in start)
        self.missions.on_current = self.on_mission_current
        self.auto = auto_mod.Auto(self)   # AUTO / AUTO.MISSION: the stored mission flown by the autopilot

    # ---- helpers ------------------------------------------------------------------------
    def event(self, what, **kw):
        e = {"event": what, "t": round(self.t, 4), "wall_us": wall_us(), **kw}
        self.events.append(e)
        if self.truth:
            self.truth.write(json.dumps(e) + "\n")
            self.truth.flush()

    def statustext(self, text, severity=mavlink.MAV_SEVERITY_INFO):
        self.conn.mav.statustext_send(severity, text.encode()[:50])

    def set_mode(self, mode, why=""):
        # PX4: any mode change but its own offboard-loss fallback moves the user's intended mode.
        self.offboard_fallback = self.offboard_fallback and why == "offboard lost"
        if mode != self.mode:
            self.event("mode", mode=mode, previous=self.mode, why=why)
            self.mode = mode

    def custom_mode(self):
        if self.ap == "px4":
            main, sub = PX4_MODES[self.mode]
            return (main << 16) | (sub << 24)
        return APM_MODES[self.mode]

    def offboard_mode(self):
        """Where companion targets are flown: PX4 OFFBOARD; ArduCopter GUIDED and AUTO's
        guided sub-mode (a NAV_GUIDED_ENABLE item: auto.py)."""
        if self.ap == "ardupilot" and self.mode == "AUTO":
            return self.auto.guided
        return self.mode == "OFFBOARD" or (self.ap == "ardupilot" and self.mode == "GUIDED")

    def on_mission_current(self, seq):
        """MISSION_SET_CURRENT in AUTO: that item starts at once (both autopilots)."""
        if self.mode in MISSION_MODES:
            self.auto.start(seq)

    def fresh_setpoint(self, age=None):
        age = self.params["COM_OF_LOSS_T"] if age is None else age
        return self.setpoint_t is not None and self.t - self.setpoint_t <= age

    # ---- MAVLink in ---------------------------------------------------------------------
    def receive(self):
        while True:
            msg = self.conn.recv_match(blocking=False)
            if msg is None:
                return
            t = msg.get_type()
            if t == "BAD_DATA":
                continue
            now = time.monotonic_ns() // 1000
            if t == "SET_ATTITUDE_TARGET":
                self.on_setpoint(msg, now)
            elif t == "HEARTBEAT":
                self.on_heartbeat(msg)
            elif t == "STATUSTEXT":  # a companion's, which an autopilot routes to the ground station
                self.on_statustext(msg)
            elif t == "COMMAND_LONG":
                self._wire({"mono_us": now, "type": t, "command": msg.command,
                            "params": [msg.param1, msg.param2, msg.param3, msg.param4, msg.param5, msg.param6,
                                       msg.param7]})
                self.on_command(msg)
            elif t.startswith("PARAM_"):
                self.on_param_message(msg, t, now)
            elif t in ("OBSTACLE_DISTANCE", "OBSTACLE_DISTANCE_3D"):
                self.on_obstacle_distance(msg, t, now)
            elif t.startswith("MISSION_"):
                self.missions.on_message(t, msg, self.t)

    def on_heartbeat(self, msg):
        """A companion's (the bridge's: counted, the first one an event) or a ground station's."""
        if msg.type == mavlink.MAV_TYPE_ONBOARD_CONTROLLER:
            self.counters["heartbeats_from_companion"] += 1
            if self.companion is None:
                self.companion = (msg.get_srcSystem(), msg.get_srcComponent())
                self.event("companion_heartbeat", system=msg.get_srcSystem(), component=msg.get_srcComponent())
        elif msg.type == mavlink.MAV_TYPE_GCS:
            self.gcs_seen.add((msg.get_srcSystem(), msg.get_srcComponent()))
            self.last_gcs_t = self.t

    def on_param_message(self, msg, t, now):
        """PARAM_REQUEST_READ, PARAM_REQUEST_LIST and PARAM_SET (a known name, a finite value)."""
        if t == "PARAM_REQUEST_READ":
            self._wire({"mono_us": now, "type": t, "id": _pid(msg.param_id)})
            self.send_param(_pid(msg.param_id))
        elif t == "PARAM_REQUEST_LIST":
            for name in sorted(self.params):
                self.send_param(name)
        elif t == "PARAM_SET":
            name = _pid(msg.param_id)
            self._wire({"mono_us": now, "type": t, "id": name, "value": msg.param_value})
            if name in self.params and math.isfinite(msg.param_value):
                self.params[name] = float(msg.param_value)
            self.send_param(name)

    def on_obstacle_distance(self, m, t, now):
        """Proximity data from a companion (the bridge's map, obstacle_distance.py): counted and
        logged whole with this autopilot's clock at arrival (`t`), as a proximity driver takes it."""
        rec = {"mono_us": now, "type": t, "t": round(self.t, 4), "src": [m.get_srcSystem(), m.get_srcComponent()],
               "frame": m.frame, "min_distance": m.min_distance, "max_distance": m.max_distance}
        if t == "OBSTACLE_DISTANCE":
            self.counters["obstacle_distance"] = self.counters.get("obstacle_distance", 0) + 1
            rec.update(time_usec=m.time_usec, distances=list(m.distances), increment=m.increment,
                       increment_f=m.increment_f, angle_offset=m.angle_offset)
        else:
            self.counters["obstacle_distance_3d"] = self.counters.get("obstacle_distance_3d", 0) + 1
            rec.update(time_boot_ms=m.time_boot_ms, obstacle_id=m.obstacle_id, x=m.x, y=m.y, z=m.z)
        self._wire(rec)

    def on_statustext(self, m):
        """Recorded as a ground station shows it: MAVLink 2 chunks (one id, 50 characters each
        but the last) joined."""
        text, cid = _pid(m.text), getattr(m, "id", 0)
        if cid:
            parts = self.text_parts.setdefault(cid, [])
            parts.append(text)
            if len(text) == 50:
                return
            text = "".join(self.text_parts.pop(cid))
        self.event("statustext", text=text, severity=m.severity, src=m.get_srcComponent())

    def _wire(self, rec):
        if self.wire:
            self.wire.write(json.dumps(rec) + "\n")

    def on_setpoint(self, m, now_us):
        vals = [m.thrust, m.body_roll_rate, m.body_pitch_rate, m.body_yaw_rate]
        finite = all(math.isfinite(v) for v in vals)
        self._wire({"mono_us": now_us, "type": "SET_ATTITUDE_TARGET", "seq": m.get_seq(),
                    "src": [m.get_srcSystem(), m.get_srcComponent()], "type_mask": m.type_mask,
                    "thrust": vals[0] if finite else repr(vals[0]), "rates": [repr(v) if not math.isfinite(v) else v
                                                                              for v in vals[1:]],
                    "finite": finite})
        if not finite:
            self.counters["nonfinite_rejected"] += 1
            return
        rates_ignored = m.type_mask & 0b111
        if not (m.type_mask & mavlink.ATTITUDE_TARGET_TYPEMASK_ATTITUDE_IGNORE) or rates_ignored or \
                m.type_mask & mavlink.ATTITUDE_TARGET_TYPEMASK_THROTTLE_IGNORE:
            self.counters["setpoints_rejected"] += 1  # this autopilot takes rates + thrust only
            return
        self.setpoint = (min(max(vals[0], 0.0), 1.0), vals[1], vals[2], vals[3])
        self.setpoint_t = self.t
        self.counters["setpoints"] += 1
        if self.ap == "px4" and self.offboard_fallback and self.armed:
            self.set_mode("OFFBOARD", "offboard lost")   # the fallback ends: back to the intended mode
            self.offboard_fallback = False
            self.event("offboard_resumed", reason="setpoints back, OFFBOARD still the intended mode")
        if self.ap == "ardupilot" and self.mode == "GUIDED" and self.taking_off:
            self.taking_off = False
            self.event("takeoff_taken_over", z=round(self.plant.x[Q.PZ], 3))

    def ack(self, cmd, result, text=None):
        self.conn.mav.command_ack_send(cmd, result)
        if text:
            self.statustext(text, mavlink.MAV_SEVERITY_WARNING if result else mavlink.MAV_SEVERITY_INFO)
            self.event("command", command=cmd, result=result, text=text)

    def on_command(self, m):
        c = m.command
        if c == mavlink.MAV_CMD_COMPONENT_ARM_DISARM:
            return self.on_arm_disarm(m)
        if c == mavlink.MAV_CMD_DO_SET_MODE:
            return self.on_set_mode(m)
        if c == mavlink.MAV_CMD_NAV_TAKEOFF:
            return self.on_takeoff(m)
        if c == mavlink.MAV_CMD_NAV_LAND:
            self.hold_sp = list(self.plant.x[Q.POS])   # lands where it is, as both autopilots do
            self.set_mode("AUTO.LAND" if self.ap == "px4" else "LAND", "command")
            return self.ack(c, mavlink.MAV_RESULT_ACCEPTED)
        if c == mavlink.MAV_CMD_SET_MESSAGE_INTERVAL:
            self.set_stream(int(m.param1), m.param2)
            return self.ack(c, mavlink.MAV_RESULT_ACCEPTED)
        if c in (mavlink.MAV_CMD_REQUEST_MESSAGE, mavlink.MAV_CMD_REQUEST_AUTOPILOT_CAPABILITIES):
            self.ack(c, mavlink.MAV_RESULT_ACCEPTED)
            if c == mavlink.MAV_CMD_REQUEST_MESSAGE and int(m.param1) == mavlink.MAVLINK_MSG_ID_HOME_POSITION:
                self.missions.send_home()
            elif c == mavlink.MAV_CMD_REQUEST_MESSAGE and int(m.param1) == mavlink.MAVLINK_MSG_ID_GPS_GLOBAL_ORIGIN:
                self.missions.send_origin()
            return None
        return self.ack(c, mavlink.MAV_RESULT_UNSUPPORTED)

    def on_arm_disarm(self, m):
        """Arms after the arming check; disarms on the ground, or in the air when forced (21196)."""
        c = m.command
        if m.param1 >= 0.5:
            why = self.arming_check()
            if why:
                return self.ack(c, mavlink.MAV_RESULT_DENIED, "Arming denied: " + why)
            self.armed = True
            self.landed_since = None
            self.event("armed")
        else:
            if not self.plant.on_ground and int(m.param2) != 21196:
                return self.ack(c, mavlink.MAV_RESULT_DENIED, "Disarm denied: in air")
            self.disarm("command")
        return self.ack(c, mavlink.MAV_RESULT_ACCEPTED)

    def on_set_mode(self, m):
        """A known mode; OFFBOARD only with fresh setpoints; the holding modes hold where it is."""
        c = m.command
        mode = self.decode_mode(m)
        if mode is None:
            return self.ack(c, mavlink.MAV_RESULT_UNSUPPORTED, "Mode not supported")
        if mode == "OFFBOARD" and not self.fresh_setpoint():
            return self.ack(c, mavlink.MAV_RESULT_TEMPORARILY_REJECTED, "Offboard denied: no setpoints")
        if mode in MISSION_MODES and len(self.missions.items) <= self.missions.first:
            return self.ack(c, mavlink.MAV_RESULT_DENIED, "Mode change failed: no mission")
        if mode in ("AUTO.LOITER", "LOITER", "BRAKE", "AUTO.LAND", "LAND", "GUIDED"):
            self.hold_sp = list(self.plant.x[Q.POS])
        if mode in ("AUTO.RTL", "RTL"):   # above home at the altitude flown, then down
            self.hold_sp = [*self.missions.home_enu[:2], float(self.plant.x[Q.PZ])]
        self.set_mode(mode, "command")
        if mode in MISSION_MODES:
            self.auto.start(self.missions.current)
        return self.ack(c, mavlink.MAV_RESULT_ACCEPTED)

    def on_takeoff(self, m):
        """Armed only; ArduPilot in GUIDED to param7, PX4 into AUTO.TAKEOFF (MIS_TAKEOFF_ALT without param7)."""
        c = m.command
        if not self.armed:
            return self.ack(c, mavlink.MAV_RESULT_DENIED, "Takeoff denied: disarmed")
        if self.ap == "ardupilot":
            if self.mode != "GUIDED":
                return self.ack(c, mavlink.MAV_RESULT_DENIED, "Takeoff denied: not in GUIDED")
            alt = m.param7
        else:
            alt = m.param7 if math.isfinite(m.param7) else self.params["MIS_TAKEOFF_ALT"]  # home AMSL is 0
            self.set_mode("AUTO.TAKEOFF", "command")
        self.takeoff_alt = float(alt)
        self.hold_sp = [self.plant.x[Q.PX], self.plant.x[Q.PY], float(alt)]
        self.taking_off = self.ap == "ardupilot"
        self.setpoint_t = None  # GUIDED's take-off replaces whatever target it had
        return self.ack(c, mavlink.MAV_RESULT_ACCEPTED)

    def set_stream(self, msg_id: int, interval_us: float):
        """ArduPilot's MAV_CMD_SET_MESSAGE_INTERVAL: -1 stops a message, 0 is its default
        rate (here state_hz), else every interval_us, no faster than state_hz."""
        if interval_us < 0:
            self.streams.pop(msg_id, None)
            return
        interval = self.state_period if interval_us == 0 else max(interval_us * 1e-6, self.state_period)
        self.streams[msg_id] = [interval, self.t]
        self.event("stream", msg_id=msg_id, interval_s=round(interval, 4))

    def streaming(self, msg_id: int) -> bool:
        """PX4 streams everything unasked; ArduPilot what was asked for, each at its interval."""
        if self.ap == "px4":
            return True
        st = self.streams.get(msg_id)
        if st is None or self.t + 1e-9 < st[1]:
            return False
        st[1] = max(st[1] + st[0], self.t)
        return True

    def landed_state(self):
        if self.plant.on_ground and not (self.taking_off or self.mode == "AUTO.TAKEOFF"):
            return mavlink.MAV_LANDED_STATE_ON_GROUND
        if self.mode in ("AUTO.LAND", "LAND"):
            return mavlink.MAV_LANDED_STATE_LANDING
        if self.taking_off or self.mode == "AUTO.TAKEOFF":
            return mavlink.MAV_LANDED_STATE_TAKEOFF
        return mavlink.MAV_LANDED_STATE_IN_AIR

    def decode_mode(self, m):
        if self.ap == "px4":
            main, sub = int(m.param2), int(m.param3)
            for name, (mm, ss) in PX4_MODES.items():
                if mm == main and (ss == sub or (mm != 4 and sub == 0)):
                    return name
            return None
        for name, num in APM_MODES.items():
            if num == int(m.param2):
                return name
        return None

    def arming_check(self) -> str:
        if self.t < 1.0:
            return "estimator not ready"
        if not self.plant.on_ground:
            return "not landed"
        if self.mode == "OFFBOARD" and not self.fresh_setpoint():
            return "no offboard setpoints"
        if self.ap == "ardupilot" and self.mode not in ("GUIDED", "STABILIZE", "LOITER"):
            return f"mode {self.mode} not armable"
        return ""

    def disarm(self, why):
        if self.armed:
            self.armed = False
            self.event("disarmed", why=why)

    def send_param(self, name):
        if name not in self.params:
            return
        v = self.params[name]
        ptype = self.param_types.get(name, mavlink.MAV_PARAM_TYPE_REAL32)
        if ptype == mavlink.MAV_PARAM_TYPE_INT32 and self.ap == "px4":
            import struct
            v = struct.unpack("<f", struct.pack("<i", int(v)))[0]  # PX4: integers byte-wise
        names = sorted(self.params)
        self.conn.mav.param_value_send(name.encode(), float(v), ptype, len(names), names.index(name))

    # ---- the autopilot's own controllers ------------------------------------------------
    def position_control(self, p_sp, vz_sp=None, yaw_sp=0.0, vmax=None, level=False):
        """Cascaded P position -> P velocity -> thrust direction -> body rates (FLU); the
        horizontal speed up to 2 m/s an axis, or `vmax` along the line (a mission's legs);
        `level`: no horizontal acceleration (level, drifting)."""
        x = self.plant.x
        err = [p_sp[i] - x[Q.PX + i] for i in range(2)]
        if vmax is None:
            vs = [min(max(1.0 * e, -2.0), 2.0) for e in err]
        else:
            scale = min(1.0, vmax / max(math.hypot(*err), 1e-9))
            vs = [e * scale for e in err]
        vs.append(vz_sp if vz_sp is not None else min(max(1.5 * (p_sp[2] - x[Q.PZ]), -1.0), 1.5))
        a = [min(max(3.0 * (vs[i] - x[Q.VX + i]), -4.0), 4.0) for i in range(3)]
        if level:
            a[0] = a[1] = 0.0
        f = [self.pp.mass * a[0], self.pp.mass * a[1], self.pp.mass * (a[2] + self.pp.gravity)]
        fn = math.sqrt(sum(c * c for c in f))
        bz_des = [c / fn for c in f]
        r = ned.quat_to_matrix(x[Q.QUAT])
        bz = [r[0][2], r[1][2], r[2][2]]
        e = [bz[1] * bz_des[2] - bz[2] * bz_des[1], bz[2] * bz_des[0] - bz[0] * bz_des[2],
             bz[0] * bz_des[1] - bz[1] * bz_des[0]]
        eb = ned.matvec(ned.transpose(r), e)
        yaw = pl.yaw_of(x)
        dyaw = math.atan2(math.sin(yaw_sp - yaw), math.cos(yaw_sp - yaw))
        thrust = max(0.0, sum(fi * bi for fi, bi in zip(f, bz)))
        return [thrust, 6.0 * eb[0], 6.0 * eb[1], 2.0 * dyaw]

    def control(self):
        """The command applied to the plant this physics step."""
        if not self.armed:
            return [0.0, 0.0, 0.0, 0.0]
        x = self.plant.x
        hover = self.params["MOT_THST_HOVER" if self.ap == "ardupilot" else "MPC_THR_HOVER"]
        hold_s = self.params["COM_OF_LOSS_T"] if self.ap == "px4" else self.SETPOINT_HOLD_S
        if self.offboard_mode() and self.fresh_setpoint(hold_s):
            self.stale_hold = None
            th, p, q, r = self.setpoint
            if self.ap == "ardupilot" and not int(self.params["GUID_OPTIONS"]) & 8:
                # ArduPilot without bit 3: thrust is a climb rate, 0.5 = hold altitude.
                u = self.position_control(list(x[Q.POS]), vz_sp=(th - 0.5) * 5.0)
                return [u[Q.THRUST], p, -q, -r]
            return [th / hover * self.pp.mass * self.pp.gravity, p, -q, -r]  # FRD -> FLU
        if self.mode in MISSION_MODES:
            return self.auto_control()
        if self.mode == "OFFBOARD" or (self.mode == "GUIDED" and self.setpoint_t is not None):
            # Setpoints late: hold level where it is until they return or the failsafe engages.
            if self.stale_hold is None:
                self.stale_hold = list(x[Q.POS])
            return self.position_control(self.stale_hold)
        if self.mode in ("AUTO.LAND", "LAND", "AUTO.RTL", "RTL"):
            if self.mode.endswith("RTL") and math.dist(self.hold_sp[:2], x[Q.PX:Q.PX + 2]) > 0.5:
                return self.position_control(self.hold_sp, vmax=self.params["MPC_XY_CRUISE"])
            if self.hold_sp is None or len(self.hold_sp) != 3:
                self.hold_sp = list(x[Q.POS])
            return self.position_control([self.hold_sp[0], self.hold_sp[1], 0.0], vz_sp=-0.8 if x[Q.PZ] > 0.6 else -0.4)
        if self.hold_sp is None:
            self.hold_sp = list(x[Q.POS])
        if self.plant.on_ground and self.mode not in ("AUTO.TAKEOFF", "GUIDED"):
            return [0.0, 0.0, 0.0, 0.0]  # armed, idle on the ground
        if self.ap == "ardupilot" and self.mode == "LOITER":
            return self.position_control(self.hold_sp, vz_sp=self.pilot_climb_rate())
        return self.position_control(self.hold_sp)

    def auto_control(self):
        """AUTO / AUTO.MISSION, setpoints not fresh: the vehicle's own controller; in the guided
        sub-mode, held where the last target left it, level after GUID_TIMEOUT (auto.py)."""
        u = self.auto.control()
        if u is not None:
            return u
        if self.setpoint_t is None:
            return self.position_control(self.auto.target)
        if self.t - self.setpoint_t > self.params["GUID_TIMEOUT"]:
            return self.auto.guided_timeout()
        if self.stale_hold is None:
            self.stale_hold = list(self.plant.x[Q.POS])
        return self.position_control(self.stale_hold)

    def pilot_climb_rate(self) -> float:
        """ArduCopter's LOITER (and ALT_HOLD, POSHOLD) read the throttle stick as a climb rate:
        SIM_RC_THROTTLE (0 low .. 1 high; 0: no RC, as ArduCopter SITL's own) outside a 10 %
        dead band around the middle, scaled to PILOT_SPEED_UP and PILOT_SPEED_DN (cm/s; 0:
        PILOT_SPEED_UP). BRAKE and GUIDED read no stick."""
        stick = self.params["SIM_RC_THROTTLE"]
        down = self.params["PILOT_SPEED_DN"] or self.params["PILOT_SPEED_UP"]
        if stick < 0.45:
            return -down / 100.0 * (0.45 - stick) / 0.45
        if stick > 0.55:
            return self.params["PILOT_SPEED_UP"] / 100.0 * (stick - 0.55) / 0.45
        return 0.0

    def other_failsafes(self):
        """The battery and the ground station (the constructor's comment), at the physics rate."""
        landing = self.mode in ("AUTO.LAND", "LAND")
        if self.armed:
            self.battery = max(0.0, self.battery - self.params["SIM_BATT_DRAIN"] * self.dt)
        if self.ap == "px4":
            low = int(self.params["COM_LOW_BAT_ACT"]) in (2, 3) and self.battery <= 100 * self.params["BAT_CRIT_THR"]
        else:
            low = int(self.params["BATT_FS_LOW_ACT"]) == 1 and self.battery <= self.params["BATT_LOW_PCT"]
        silent = self.last_gcs_t is not None and self.t - self.last_gcs_t > \
            self.params["FS_GCS_TIMEOUT" if self.ap == "ardupilot" else "COM_DL_LOSS_T"]
        dll = int(self.params["NAV_DLL_ACT"])
        gcs = silent and (int(self.params["FS_GCS_ENABLE"]) == 5 if self.ap == "ardupilot" else dll != 0)
        action = "LAND" if self.ap == "ardupilot" else "AUTO.LAND"
        if gcs and self.ap == "px4" and not low:
            action = DATALINK_LOSS_ACTIONS.get(dll, "AUTO.LAND")
            if self.mode == action:
                return
        if self.armed and not landing and (low or gcs):
            reason = "battery low" if low else "ground station lost"
            self.counters["failsafes"] += 1
            self.hold_sp = list(self.plant.x[Q.POS])
            self.set_mode(action, reason)
            self.event("failsafe", reason=reason, action=self.mode)
            self.statustext(f"Failsafe: {reason}, landing", mavlink.MAV_SEVERITY_CRITICAL)

    def supervise(self):
        """Failsafe, take-off completion, auto-disarm; at the physics rate."""
        self.other_failsafes()
        if self.mode == "OFFBOARD" and self.setpoint_t is not None and not self.fresh_setpoint():
            self.counters["failsafes"] += 1
            self.hold_sp = list(self.plant.x[Q.POS])
            action = OFFBOARD_LOSS_ACTIONS.get(int(self.params["COM_OBL_RC_ACT"]), "AUTO.LAND")
            self.set_mode(action, "offboard lost")
            self.offboard_fallback = True
            self.event("failsafe", reason="offboard setpoints lost", action=action,
                       last_setpoint_age_s=round(self.t - self.setpoint_t, 4))
            self.statustext(f"Failsafe: offboard lost, {action}", mavlink.MAV_SEVERITY_CRITICAL)
        if self.mode == "OFFBOARD" and self.setpoint_t is None and not self.plant.on_ground:
            pass
        if self.mode == "AUTO.TAKEOFF" and self.takeoff_alt is not None and \
                abs(self.plant.x[Q.PZ] - self.takeoff_alt) < 0.15:
            self.hold_sp = [self.plant.x[Q.PX], self.plant.x[Q.PY], self.takeoff_alt]
            self.set_mode("AUTO.LOITER", "takeoff complete")
        if self.taking_off and (self.mode != "GUIDED" or abs(self.plant.x[Q.PZ] - self.takeoff_alt) < 0.15):
            self.taking_off = False  # ArduPilot stays in GUIDED, holding where the take-off ended
            self.event("takeoff_complete", z=round(self.plant.x[Q.PZ], 3))
        if self.mode in MISSION_MODES and self.armed:
            self.auto.verify()
        if self.armed and self.plant.on_ground and (self.mode in ("AUTO.LAND", "LAND", "AUTO.RTL", "RTL")
                                                    or (self.mode in MISSION_MODES and self.auto.landed())):
            self.landed_since = self.landed_since if self.landed_since is not None else self.t
            if self.t - self.landed_since > self.params["COM_DISARM_LAND"]:
                self.disarm("landed")
                self.event("landed")
        else:
            self.landed_since = None
        if self.plant.crashed and not any(e["event"] == "collision" for e in self.events):
            self.event("collision", reason=self.plant.crashed, **{"with": "ground"})

    # ---- MAVLink out --------------------------------------------------------------------
    def send_heartbeat(self):
        base = mavlink.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED | (mavlink.MAV_MODE_FLAG_SAFETY_ARMED if self.armed else 0)
        ap = mavlink.MAV_AUTOPILOT_PX4 if self.ap == "px4" else mavlink.MAV_AUTOPILOT_ARDUPILOTMEGA
        state = mavlink.MAV_STATE_ACTIVE if self.armed else mavlink.MAV_STATE_STANDBY
        self.conn.mav.heartbeat_send(mavlink.MAV_TYPE_QUADROTOR, ap, base, self.custom_mode(), state)

    def send_telemetry(self):
        x = self.plant.x
        p, v, q, vb, w = ned.state_to_ned(x)
        tb_us = int(self.t * self.clock_rate * 1e6)
        tb_ms = tb_us // 1000
        mono = time.monotonic_ns() // 1000
        cov = [math.nan] + [0.0] * 20
        if self.ap == "px4":  # ArduPilot sends no ODOMETRY
            self.conn.mav.odometry_send(tb_us, mavlink.MAV_FRAME_LOCAL_NED, mavlink.MAV_FRAME_BODY_FRD,
                                        p[0], p[1], p[2], list(q), vb[0], vb[1], vb[2], w[0], w[1], w[2], cov, cov, 0,
                                        mavlink.MAV_ESTIMATOR_TYPE_UNKNOWN, 100)
            self._wire({"mono_us": mono, "type": "ODOMETRY", "time_usec": tb_us})
        # Position first: a bridge pairs each attitude with the latest position.
        if self.streaming(mavlink.MAVLINK_MSG_ID_LOCAL_POSITION_NED):
            self.conn.mav.local_position_ned_send(tb_ms, p[0], p[1], p[2], v[0], v[1], v[2])
        if self.streaming(mavlink.MAVLINK_MSG_ID_ATTITUDE_QUATERNION):
            self.conn.mav.attitude_quaternion_send(tb_ms, q[0], q[1], q[2], q[3], w[0], w[1], w[2])
            self.counters["states_sent"] += 1

    def send_slow(self):
        sensors = 0x7FFF
        if self.streaming(mavlink.MAVLINK_MSG_ID_SYS_STATUS):
            self.conn.mav.sys_status_send(sensors, sensors, sensors, 100, 15800, -1, int(self.battery), 0, 0, 0, 0, 0,
                                          0)
        if self.streaming(mavlink.MAVLINK_MSG_ID_EXTENDED_SYS_STATE):
            self.conn.mav.extended_sys_state_send(mavlink.MAV_VTOL_STATE_UNDEFINED, self.landed_state())

    # ---- run ----------------------------------------------------------------------------
    def step_physics(self, next_state):
        """Physics steps up to the wall clock, stopping at the next telemetry tick (next_state)."""
        target = time.monotonic() - self.boot
        steps = 0
        while self.t + self.dt <= target:
            self.plant.u = self.plant.saturate(self.control())
            self.plant.step(self.dt)
            self.t += self.dt
            self.supervise()
            steps += 1
            if steps >= 50:  # fell > 0.1 s behind: skip, don't catch up
                self.counters["overruns"] += 1
                self.t = target
                break
            if self.t >= next_state:
                break  # telemetry at its tick, not after a catch-up burst

    def run(self, duration=0.0, stop=None):
        next_state = next_hb = next_slow = next_mission = 0.0
        fd = self.conn.fd if hasattr(self.conn, "fd") and self.conn.fd is not None else None
        while stop is None or not stop.is_set():
            self.receive()
            self.step_physics(next_state)
            if self.t >= next_state:
                next_state = max(next_state + self.state_period, self.t)
                self.send_telemetry()
                self.log_truth()
            if self.t >= next_hb:
                next_hb = self.t + 1.0
                self.send_heartbeat()
                self.missions.send_current()
            self.missions.tick(self.t)
            if self.t >= next_slow:
                next_slow = self.t + 0.5
                self.send_slow()
            if self.mission is not None and self.t >= next_mission:
                next_mission = self.t + 0.1
                self.mission.update(self.t, self.plant.x, self.offboard_mode() and self.fresh_setpoint(),
                                    not self.plant.on_ground)
                self.events_flushed()
            if duration and self.t > duration:
                break
            wait = max(0.0, self.boot + self.t + self.dt - time.monotonic())
            if fd is not None:
                select.select([fd], [], [], wait)
            else:
                time.sleep(wait)

    def events_flushed(self):
        """Mission events into the truth log as they happen."""
        while self.mission is not None and self.mission.events:
            e = {**self.mission.events.pop(0), "wall_us": wall_us()}
            self.events.append(e)
            if self.truth is not None:
                self.truth.write(json.dumps(e) + "\n")
                self.truth.flush()

    def log_truth(self):
        if self.mission is not None and self.world is not None:
            if self.mission.phase == "run":
                self.mission.record(self.t, self.plant.x)
            if self.world.get("obstacles") and not self.plant.on_ground:
                if self.mission.clearance(self.plant.x) < 0 and not any(e["event"] == "collision" for e in self.events):
                    self.event("collision", **{"with": "cylinder"})
        if self.truth:
            self.truth.write(json.dumps({"t": round(self.t, 4), "x": [round(c, 5) for c in self.plant.x],
                                         "u": [round(c, 4) for c in self.plant.u], "mode": self.mode,
                                         "armed": self.armed, "ground": self.plant.on_ground}) + "\n")

    def summary(self):
        sg = self.conn.mav.signing
        if sg.secret_key is not None:
            # pymavlink counts a bad signature in reject_count too.
            self.counters["rejected_unsigned"] = sg.reject_count - sg.badsig_count
            self.counters["rejected_bad_signature"] = sg.badsig_count
            self.counters["accepted_signed"] = sg.goodsig_count
        s = {"autopilot": self.ap, "counters": self.counters, "signing": sg.secret_key is not None, "events": self.events,
             "companion": self.companion, "gcs_seen": sorted(self.gcs_seen), "final_mode": self.mode,
             "armed": self.armed, "final_state": self.plant.x, "t": self.t}
        if self.mission is not None:
            s["mission"] = self.mission.summary()
        return s

    def close(self):
        for f in (self.wire, self.truth):
            if f:
                f.close()


def _pid(p):
    return (p if isinstance(p, str) else p.decode(errors="replace")).rstrip("\x00")
