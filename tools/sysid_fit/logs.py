"""Flight logs as the fit needs them: the rate model's states and the commands, on one clock.

* An LCM log of vehicle_state_t (MPPI_STATE) and command_t (MPPI_COMMAND), as tools/record,
  the SITL harness or a flight through the MAVLink bridge writes it. In real time a command
  takes effect from its publish time (command_t.utime) on, on the clock of the states'
  sample_utime (the same host's wall clock: the bridge and mppid-sim stamp it so). A
  lock-step log (it holds MPPI_SIM_CLOCK ticks) has states on the simulated clock: a command
  then counts from its state's tick, plus the latency the simulator charged (measured: the
  command's utime less the tick's, both wall clock; or the fixed --lockstep-latency).
  The bridge's hover thrust in use (mavlink_link_t on MPPI_MAVLINK_LINK), when logged.
  When the log holds the bridge's link messages with `engaged`, only the engaged intervals
  count (mppid's setpoints reached the autopilot; before `offboard`, during ArduPilot's own
  takeoff and after land or hold they did not; on PX4 only in OFFBOARD: its pre-stream reaches
  the autopilot but is not flown): states and commands outside are dropped.
* An ArduPilot dataflash log (.BIN, pymavlink's DFReader): RATE (desired and achieved body
  rates), CTUN (throttle out), ATT and the EKF's position and velocity (XKF1, NKF1), turned
  into the same arrays (NED/FRD -> ENU/FLU; throttle -> newtons through the vehicle's mass and
  hover throttle).
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[2]

STATE_CHANNEL, COMMAND_CHANNEL, CLOCK_CHANNEL, LINK_CHANNEL = "MPPI_STATE", "MPPI_COMMAND", "MPPI_SIM_CLOCK", "MPPI_MAVLINK_LINK"
RATE_MODEL, THRUST_RATES, MODE_FAILSAFE = 2, 2, 2


class LogError(ValueError):
    pass


@dataclass
class FlightData:
    t: np.ndarray                 # state times [s] from the first state
    x: np.ndarray                 # (N, 13) rate-model states: p, v, q (w x y z), w (body rates)
    tc: np.ndarray                # when each command takes effect at the earliest (before any delay) [s]
    u: np.ndarray                 # (M, 4) thrust [N], body rates [rad/s]
    source: str
    clock: str                    # realtime | lockstep | dataflash
    hover_thrust: float | None = None   # the bridge's hover throttle in use, when logged
    notes: list[str] = field(default_factory=list)
    engaged: list[tuple[float, float]] | None = None   # the bridge's engaged intervals [s], when logged

    def between(self, t0: float, t1: float) -> "FlightData":
        """The states in [t0, t1) with every command (the fit needs those before t0 too)."""
        k = (self.t >= t0) & (self.t < t1)
        return FlightData(self.t[k], self.x[k], self.tc, self.u, self.source, self.clock, self.hover_thrust,
                          self.notes, self.engaged)

    def spans(self) -> list[tuple[float, float]]:
        """The intervals of flight that count: the engaged ones, else the whole log."""
        return self.engaged if self.engaged is not None else [(float(self.t[0]), float(self.t[-1]))]

    def split_time(self, fraction: float) -> float:
        """The time before which `fraction` of the counted flight time lies."""
        spans = self.spans()
        left = fraction * sum(b - a for a, b in spans)
        for a, b in spans:
            if left <= b - a:
                return a + left
            left -= b - a
        return spans[-1][1]

    def within(self, spans: list[tuple[float, float]]) -> "FlightData":
        """Only the states and commands inside the intervals [a, b) (times in s)."""
        ks, kc = _inside(self.t, spans), _inside(self.tc, spans)
        return FlightData(self.t[ks], self.x[ks], self.tc[kc], self.u[kc], self.source, self.clock,
                          self.hover_thrust, self.notes, list(spans))


def _inside(t: np.ndarray, spans) -> np.ndarray:
    k = np.zeros(len(t), dtype=bool)
    for a, b in spans:
        k |= (t >= a) & (t < b)
    return k


def _lcm_messages(path) -> dict:
    """The log's rate-model states by seq, thrust-rate commands, lock-step ticks by seq,
    the bridge's engagement and hover thrust (a message that does not decode is skipped)."""
    from mppi_mavlink import lcm_types
    lcm_types.import_mppi_lcm()
    import lcm
    from mppi_lcm import command_t, sim_clock_t, vehicle_state_t
    try:
        link_t = lcm_types.import_link_type()
    except Exception:  # noqa: BLE001 - the link type is optional (no bridge in the flight)
        link_t = None

    out = {"states": {}, "commands": [], "ticks": {}, "hover": [], "link": []}
    log = lcm.EventLog(str(path), "r")
    for ev in log:
        try:
            if ev.channel == STATE_CHANNEL:
                m = vehicle_state_t.decode(ev.data)
                if m.model == RATE_MODEL and m.vehicle_count == 1 and m.nx == 13 and all(map(math.isfinite, m.x)):
                    out["states"][m.seq] = (m.sample_utime, list(m.x))
            elif ev.channel == COMMAND_CHANNEL:
                m = command_t.decode(ev.data)
                if m.kind == THRUST_RATES and m.n == 4 and m.mode != MODE_FAILSAFE and all(map(math.isfinite, m.u)):
                    out["commands"].append((m.utime, m.state_seq, list(m.u)))
            elif ev.channel == CLOCK_CHANNEL:
                m = sim_clock_t.decode(ev.data)
                out["ticks"].setdefault(m.seq, (m.sim_utime, m.utime))
            elif ev.channel == LINK_CHANNEL and link_t is not None:
                m = link_t.decode(ev.data)
                # PX4 takes setpoints only in OFFBOARD: its pre-stream (`engaged` too) is not flown.
                out["link"].append((m.utime, bool(m.engaged) and (m.dialect != "px4" or m.mode == "OFFBOARD")))
                if m.hover_thrust > 0 and math.isfinite(m.hover_thrust):
                    out["hover"].append(m.hover_thrust)
        except ValueError:
            continue  # a message that does not decode is not data
    log.close()
    return out


def _command_times(commands, ticks, lockstep_latency) -> np.ndarray:
    """When each command acted [us]: sent (real time), or its tick's sim time plus the latency
    (lock-step: the given one, else the measured one); NaN where its tick is missing."""
    if not ticks:
        return np.array([c[0] for c in commands], dtype=np.float64)
    tc = []
    for utime, state_seq, _ in commands:
        tick = ticks.get(state_seq)
        if tick is None:
            tc.append(np.nan)
            continue
        sim_us, wall_us = tick
        charged = lockstep_latency * 1e6 if lockstep_latency is not None else max(0.0, utime - wall_us)
        tc.append(sim_us + charged)
    return np.array(tc, dtype=np.float64)


def read_lcm(path: str | Path, lockstep_latency: float | None = None) -> FlightData:
    m = _lcm_messages(path)
    states, commands = m["states"], m["commands"]
    if len(states) < 50:
        raise LogError(f"{path}: {len(states)} rate-model states (MPPI_STATE, model quadrotor_rate): too few to fit")
    if len(commands) < 50:
        raise LogError(f"{path}: {len(commands)} thrust-rate commands (MPPI_COMMAND): too few to fit")
    seqs = sorted(states)
    ts = np.array([states[s][0] for s in seqs], dtype=np.float64)
    order = np.argsort(ts, kind="stable")
    ts, x = ts[order], np.array([states[s][1] for s in seqs], dtype=np.float64)[order]
    keep = np.concatenate([[True], np.diff(ts) > 0])
    ts, x = ts[keep], x[keep]

    clock = "lockstep" if m["ticks"] else "realtime"
    tc = _command_times(commands, m["ticks"], lockstep_latency)
    u = np.array([c[2] for c in commands], dtype=np.float64)
    ok = np.isfinite(tc)
    tc, u = tc[ok], u[ok]
    order = np.argsort(tc, kind="stable")
    t0 = ts[0]
    hover = m["hover"]
    data = FlightData((ts - t0) * 1e-6, x, (tc[order] - t0) * 1e-6, u[order], str(path), clock,
                      float(np.median(hover)) if hover else None)
    if clock == "lockstep" and lockstep_latency is None:
        data.notes.append("lock-step log: each command counted from its tick plus the measured latency")
    if m["link"] and clock == "realtime":
        data = engaged_only(data, [((a - t0) * 1e-6, (b - t0) * 1e-6) for a, b in engaged_intervals(m["link"])])
    return data


def engaged_intervals(link: list[tuple[int, bool]]) -> list[tuple[int, int]]:
    """[start, end) of each run of engaged link messages (utime, engaged): from the first
    engaged one to the next that is not (the bridge publishes at once on either change), or
    to the last message when the log ends engaged."""
    out, start = [], None
    for utime, engaged in sorted(link):
        if engaged and start is None:
            start = utime
        elif not engaged and start is not None:
            out.append((start, utime))
            start = None
    if start is not None:
        out.append((start, max(u for u, _ in link)))
    return [(a, b) for a, b in out if b > a]


def engaged_only(data: FlightData, spans: list[tuple[float, float]]) -> FlightData:
    """The flight while the bridge was engaged (the log holds its link messages)."""
    t0, t1 = float(data.t[0]), float(data.t[-1])
    spans = [(float(max(a, t0)), float(min(b, t1))) for a, b in spans if b > t0 and a < t1]
    data = data.within(spans)
    if len(data.t) < 50 or len(data.u) < 50:
        raise LogError(f"{data.source}: {len(data.t)} states and {len(data.u)} commands while the bridge was "
                       "engaged (mavlink_link_t.engaged): too few to fit")
    data.notes = data.notes + [f"bridge engaged {sum(b - a for a, b in spans):.1f} s of the log's {t1 - t0:.1f} s: "
                               "only those intervals fitted and held out"]
    return data


# ---- ArduPilot dataflash -------------------------------------------------------------------

def _q_from_euler_ned(roll, pitch, yaw):
    cr, sr, cp, sp, cy, sy = (np.cos(roll / 2), np.sin(roll / 2), np.cos(pitch / 2), np.sin(pitch / 2),
                              np.cos(yaw / 2), np.sin(yaw / 2))
    return np.stack([cr * cp * cy + sr * sp * sy, sr * cp * cy - cr * sp * sy,
                     cr * sp * cy + sr * cp * sy, cr * cp * sy - sr * sp * cy], axis=1)


def _dataflash_rows(path) -> dict[str, list[tuple]]:
    """RATE, CTUN, ATT, the first EKF core's XKF1/NKF1 and GUIA rows of a dataflash log, times in s."""
    from pymavlink import DFReader

    log = DFReader.DFReader_binary(str(path), zero_time_base=True)
    rows = {k: [] for k in ("RATE", "CTUN", "ATT", "EKF", "GUIA")}
    while True:
        m = log.recv_match(type=["RATE", "CTUN", "ATT", "XKF1", "NKF1", "GUIA"])
        if m is None:
            return rows
        t = m.TimeUS * 1e-6
        kind = m.get_type()
        if kind == "RATE":
            rows["RATE"].append((t, m.RDes, m.R, m.PDes, m.P, m.YDes, m.Y))
        elif kind == "CTUN":
            rows["CTUN"].append((t, m.ThO, getattr(m, "ThH", float("nan"))))
        elif kind == "ATT":
            rows["ATT"].append((t, m.Roll, m.Pitch, m.Yaw))
        elif kind == "GUIA":
            rows["GUIA"].append((t, m.RollRt, m.PitchRt, m.YawRt, m.Thrust))
        elif getattr(m, "C", 0) == 0:  # the first EKF core
            rows["EKF"].append((t, m.PN, m.PE, m.PD, m.VN, m.VE, m.VD))


def read_dataflash(path: str | Path, mass: float, gravity: float, hover_throttle: float | None) -> FlightData:
    """ArduCopter's log. The input is what mppid asked for through the bridge: GUIA, GUIDED's
    attitude target (body rates in deg/s, FRD; thrust 0..1, with GUID_OPTIONS bit 3), logged
    as each target arrives; without GUIA, RATE's desired rates and CTUN.ThO, which are the rate
    loop's input after ArduCopter's own input shaping (the fit then leaves the shaping out: a
    note says so). The output: RATE's achieved rates, ATT, the first EKF core's position and
    velocity (XKF1, or NKF1 in older logs). Thrust in newtons through the vehicle's mass and
    hover throttle (CTUN.ThH when the vehicle file has none)."""
    from mppi_mavlink import frames

    rows = _dataflash_rows(path)
    counts = {k: len(v) for k, v in rows.items()}
    if min(counts["RATE"], counts["CTUN"], counts["ATT"], counts["EKF"]) < 50:
        raise LogError(f"{path}: RATE/CTUN/ATT/XKF1 messages {counts}: too few to fit")
    rate, ctun, att, ekf = (np.array(rows[k], dtype=np.float64) for k in ("RATE", "CTUN", "ATT", "EKF"))
    if hover_throttle is None:
        hover_throttle = float(np.nanmedian(ctun[:, 2]))
        if not 0.01 < hover_throttle < 0.99:
            raise LogError(f"{path}: no hover throttle (CTUN.ThH) in the log and none in the vehicle file")
    newtons = mass * gravity / hover_throttle
    d2r = np.pi / 180.0
    t = rate[:, 0]
    interp = lambda src, col: np.interp(t, src[:, 0], src[:, col])  # noqa: E731
    q_ned = _q_from_euler_ned(interp(att, 1) * d2r, interp(att, 2) * d2r, interp(att, 3) * d2r)
    q = np.array([frames.q_ned_frd_to_enu_flu(tuple(r)) for r in q_ned])
    p = np.stack(frames.ned_to_enu([interp(ekf, c) for c in (1, 2, 3)]), axis=1)
    v = np.stack(frames.ned_to_enu([interp(ekf, c) for c in (4, 5, 6)]), axis=1)
    w = np.stack(frames.frd_to_flu([rate[:, c] for c in (2, 4, 6)]), axis=1) * d2r
    x = np.concatenate([p, v, q, w], axis=1)
    notes = []
    if counts["GUIA"] >= 50:
        g = np.array(rows["GUIA"], dtype=np.float64)
        tc = g[:, 0]
        u = np.stack([g[:, 4] * newtons, *frames.frd_to_flu([g[:, c] * d2r for c in (1, 2, 3)])], axis=1)
        notes.append("dataflash: GUIDED's attitude targets (GUIA) as the input")
    else:
        tc = t
        u = np.stack([np.interp(t, ctun[:, 0], ctun[:, 1]) * newtons,
                      *frames.frd_to_flu([rate[:, c] * d2r for c in (1, 3, 5)])], axis=1)
        notes.append("dataflash without GUIA: RATE's desired rates and CTUN.ThO as the input, after ArduCopter's "
                     "input shaping (the fit leaves the shaping out)")
    t0 = min(t[0], tc[0])
    return FlightData(t - t0, x, tc - t0, u, str(path), "dataflash", hover_throttle, notes)


# ---- PX4 ULog ------------------------------------------------------------------------------

ULOG_TOPICS = ("vehicle_rates_setpoint", "vehicle_angular_velocity", "vehicle_attitude", "vehicle_local_position",
               "vehicle_status", "hover_thrust_estimate")
NAV_STATE_OFFBOARD = 14   # vehicle_status.nav_state
ULOG_PERIOD_US = 10_000   # the states' grid: vehicle_angular_velocity's logged rate


def _ulog_topics(path) -> tuple[dict, dict]:
    """The topics the fit reads (the first instance of each) and the log's parameters."""
    from pyulog import ULog

    log = ULog(str(path), list(ULOG_TOPICS))
    topics = {}
    for d in log.data_list:
        if d.multi_id == 0:
            topics[d.name] = {k: np.asarray(v, dtype=np.float64) for k, v in d.data.items()}
    return topics, dict(log.initial_parameters)


def _offboard_spans(status: dict | None) -> list[tuple[float, float]] | None:
    """[start, end) of each run of OFFBOARD in vehicle_status [us]."""
    if status is None:
        return None
    t, nav = status["timestamp"], status["nav_state"]
    spans, start = [], None
    for ti, n in zip(t, nav):
        if n == NAV_STATE_OFFBOARD and start is None:
            start = ti
        elif n != NAV_STATE_OFFBOARD and start is not None:
            spans.append((start, ti))
            start = None
    if start is not None:
        spans.append((start, t[-1]))
    return spans


def _ulog_hover(topics: dict, params: dict, hover_throttle: float | None) -> float:
    """The hover throttle: the vehicle file's, else PX4's estimate while it was valid, else MPC_THR_HOVER."""
    if hover_throttle is not None:
        return hover_throttle
    est = topics.get("hover_thrust_estimate")
    if est is not None and (est["valid"] > 0).sum() >= 10:
        return float(np.median(est["hover_thrust"][est["valid"] > 0]))
    return float(params.get("MPC_THR_HOVER", 0.5))


def read_ulog(path: str | Path, mass: float, gravity: float, hover_throttle: float | None) -> FlightData:
    """PX4's log (pyulog). The input is what reached PX4's rate controller: vehicle_rates_setpoint
    (body rates FRD; thrust_body z, normalised and negative up), which in OFFBOARD with body-rate
    setpoints is mppid's SET_ATTITUDE_TARGET as PX4 took it. The output: vehicle_angular_velocity,
    vehicle_attitude, vehicle_local_position (NED/FRD -> ENU/FLU). Thrust in newtons through the
    vehicle's mass and hover throttle (the file's, else hover_thrust_estimate, else MPC_THR_HOVER).
    Only the OFFBOARD intervals (vehicle_status.nav_state) are fitted: outside them PX4's own
    controllers set the rates."""
    from mppi_mavlink import frames

    topics, params = _ulog_topics(path)
    need = ULOG_TOPICS[:4]
    counts = {k: len(topics[k]["timestamp"]) if k in topics else 0 for k in need}
    if min(counts.values()) < 50:
        raise LogError(f"{path}: {counts}: too few to fit")
    rates, w_log, att, lpos = (topics[k] for k in need)
    hover = _ulog_hover(topics, params, hover_throttle)
    newtons = mass * gravity / hover
    # One uniform 100 Hz grid (the logger's samples jitter; the held-out check steps evenly).
    t = np.arange(w_log["timestamp"][0], w_log["timestamp"][-1], ULOG_PERIOD_US)
    interp = lambda src, key: np.interp(t, src["timestamp"], src[key])  # noqa: E731
    q_ned = np.stack([interp(att, f"q[{i}]") for i in range(4)], axis=1)
    q = np.array([frames.q_ned_frd_to_enu_flu(tuple(r / np.linalg.norm(r))) for r in q_ned])
    p = np.stack(frames.ned_to_enu([interp(lpos, k) for k in ("x", "y", "z")]), axis=1)
    v = np.stack(frames.ned_to_enu([interp(lpos, k) for k in ("vx", "vy", "vz")]), axis=1)
    w = np.stack(frames.frd_to_flu([interp(w_log, f"xyz[{i}]") for i in range(3)]), axis=1)
    x = np.concatenate([p, v, q, w], axis=1)
    tc = rates["timestamp"]
    u = np.stack([-rates["thrust_body[2]"] * newtons, *frames.frd_to_flu([rates[k] for k in ("roll", "pitch", "yaw")])],
                 axis=1)
    t0 = min(t[0], tc[0])
    data = FlightData((t - t0) * 1e-6, x, (tc - t0) * 1e-6, u, str(path), "ulog", hover,
                      ["ulog: vehicle_rates_setpoint as the input (in OFFBOARD: the offboard rate setpoints)"])
    spans = _offboard_spans(topics.get("vehicle_status"))
    if spans:
        data = engaged_only(data, [((a - t0) * 1e-6, (b - t0) * 1e-6) for a, b in spans])
    return data
