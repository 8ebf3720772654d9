"""What the mission tool flies through. The runner needs a clock, a position, a way to
hand over the reference each tick, and the start and end of the flight:

* `MppidLink`: mppid over LCM, the same against mppid-sim and a real autopilot. The clock
  and the position are the vehicle_state_t stream's (so it also works in a lock-step
  simulation, whose time is simulated); the reference and the virtual trees go to mppid as
  reference_t and obstacles_t (mppid's tracking and forest costs evaluate the path
  themselves). With the bridge's control socket the tool also arms, takes off with the
  autopilot, hands over (`offboard`) and lands; without one (mppid-sim) the simulator flies.
* `GuidedLink`: ArduCopter's own GUIDED position controller, the baseline a user would pick
  instead of mppid: SET_POSITION_TARGET_LOCAL_NED with the reference's position, velocity
  and acceleration at every tick, straight to the autopilot over MAVLink.
"""
from __future__ import annotations

import math
import os
import threading
import time

import numpy as np
from mppi_mavlink import frames
from mppi_mavlink.layout import QuadrotorRate as Q

from . import reference

os.environ.setdefault("MAVLINK20", "1")


IN_AIR = 2  # MAV_LANDED_STATE_IN_AIR


class FlightError(RuntimeError):
    pass


def _wait(pred, timeout, what):
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        if pred():
            return
        time.sleep(0.05)
    raise FlightError(f"timed out after {timeout:g} s waiting for {what}")


def arm_when_ready(arm, say, timeout=120.0):
    """An autopilot refuses to arm until its pre-arm checks pass (a SITL's EKF takes ~20 s
    after boot): ask once a second until it arms."""
    deadline = time.monotonic() + timeout
    while True:
        try:
            return say(arm())
        except FlightError as e:
            if time.monotonic() > deadline:
                raise FlightError(f"not armed after {timeout:g} s: {e}") from e
            time.sleep(1.0)


class StateClock:
    """The vehicle's newest state, and the clock it sets: (sample time us, position ENU,
    monotonic receipt), written by the link's receive thread."""
    what = "a vehicle state"

    def __init__(self):
        self.lock = threading.Lock()
        self.state = None
        self.yaw = None

    def _set_state(self, t_us: int, p, yaw=None):
        with self.lock:
            self.state = (t_us, p, time.monotonic())
            self.yaw = yaw if yaw is not None else self.yaw

    def heading(self):
        """The vehicle's yaw (rad, ENU: 0 east, counter-clockwise), or None when not known."""
        with self.lock:
            return self.yaw

    def check_task(self, task):
        """Whether the controller flies the task the mission was written for (mppid: below)."""

    def now_us(self) -> int | None:
        """The state stream's clock: the newest sample time plus the wall time since it came."""
        with self.lock:
            if self.state is None:
                return None
            t, _, recv = self.state
        return int(t + (time.monotonic() - recv) * 1e6)

    def sampled(self):
        """(sample time us, position) of the newest state, or None."""
        with self.lock:
            return None if self.state is None else (self.state[0], self.state[1].copy())

    def position(self):
        s = self.sampled()
        return None if s is None else s[1]

    def wait_state(self, timeout=120.0):  # a SITL's EKF takes ~30 s to a position
        _wait(lambda: self.state is not None, timeout, self.what)


class MppidLink(StateClock):
    tick_hz = 10.0  # references are paths: mppid evaluates them; 10 Hz keeps them fresh
    clock = "state"  # vehicle_state_t.sample_utime: this host's wall clock (or a simulator's)

    def __init__(self, lcm_url: str, bridge_socket: str | None = None, channels=None):
        import lcm
        from mppi_mavlink import lcm_types
        super().__init__()
        self.t = lcm_types.import_mppi_lcm()
        self.ch = {"state": "MPPI_STATE", "reference": "MPPI_REFERENCE", "obstacles": "MPPI_OBSTACLES",
                   "status": "MPPI_STATUS", **(channels or {})}
        self.lc = lcm.LCM(lcm_url)
        self.lc.subscribe(self.ch["state"], self._on_state)
        self.lc.subscribe(self.ch["status"], self._on_status)
        self.task = None
        self.socket = bridge_socket
        self.what = f"a vehicle state on {self.ch['state']}"
        self.seq = 0
        self.stop = threading.Event()
        self.thread = threading.Thread(target=self._loop, name="mission-lcm", daemon=True)
        self.thread.start()

    def _loop(self):
        while not self.stop.is_set():
            self.lc.handle_timeout(50)

    def _on_state(self, ch, data):
        try:
            m = self.t.vehicle_state_t.decode(data)
        except ValueError:
            return
        if m.n <= Q.PZ or not all(math.isfinite(c) for c in m.x[Q.POS]):
            return
        yaw = None
        if m.n > Q.QZ and all(math.isfinite(c) for c in m.x[Q.QUAT]):
            w, x, y, z = m.x[Q.QUAT]  # ENU/FLU attitude: the heading of the body x axis
            yaw = math.atan2(2.0 * (w * z + x * y), 1.0 - 2.0 * (y * y + z * z))
        self._set_state(m.sample_utime, np.array(m.x[Q.POS], float), yaw)

    def _on_status(self, ch, data):
        try:
            self.task = self.t.controller_status_t.decode(data).task
        except ValueError:
            pass

    def check_task(self, task, timeout=10.0):
        """Refuses a mppid that runs another task than the mission's (its controller_status_t
        says which): a forest mission flown by the tracking task is a straight line through its
        trees. A mission that names no task flies with any."""
        if task is None:
            return
        _wait(lambda: self.task is not None, timeout, f"mppid's status on {self.ch['status']} (is mppid running?)")
        if self.task != task:
            raise FlightError(f"mppid runs the task {self.task!r}, the mission is written for {task!r}: refusing to "
                              f"fly it (start mppid with config/tasks/{task}.yaml)")

    # ---- the flight, through the bridge ---------------------------------------------------
    def request(self, line: str, timeout=60.0) -> str:
        from mppi_mavlink import control
        r = control.request(self.socket, line, timeout)
        if not r.get("ok"):
            raise FlightError(f"bridge `{line}`: {r.get('message')}")
        return r["message"]

    def bridge_status(self) -> dict:
        from mppi_mavlink import control
        return control.request(self.socket, "status", 5.0).get("status", {})

    def start(self, takeoff: float | None, hold_here, say, engage="offboard"):
        """Arm, the autopilot's take-off, then `offboard` (or `engage`: the bridge's `segment`)
        with mppid asked to hold where the vehicle is (mppid's hold point would otherwise be
        its first state: the ground)."""
        if self.socket is None:
            return
        _wait(lambda: not self.bridge_status().get("refusal"), 60, "the bridge's flight checks")
        if takeoff is not None:
            arm_when_ready(lambda: self.request("arm"), say)
            say(self.request(f"takeoff {takeoff:g}"))
            # Up, and the autopilot's take-off over (landed state IN_AIR, where it reports one).
            _wait(lambda: (self.position() is not None and self.position()[2] > 0.9 * takeoff
                           and self.bridge_status().get("landed_state") in (None, IN_AIR)), 60,
                  f"the take-off to {takeoff:g} m")
        hold_here()
        say(self.request(engage, timeout=90.0))

    def finish(self, land: bool, say):
        if self.socket is None or not land:
            return
        say(self.request("land"))
        _wait(lambda: not self.bridge_status().get("armed", True), 90, "the landing (disarmed)")
        say("landed and disarmed")

    # ---- the reference ------------------------------------------------------------------
    def send(self, ref: dict, t0_us: int, trees, vehicle_count=1):
        m = self.t.reference_t()
        self.seq += 1
        m.utime, m.seq = self.now_us() or 0, self.seq
        kinds = {"hold": m.KIND_HOLD, "circle": m.KIND_CIRCLE, "figure_eight": m.KIND_FIGURE_EIGHT,
                 "line": m.KIND_LINE}
        m.kind = kinds[ref["kind"]]
        m.center = [float(c) for c in ref["center"]]
        m.radius, m.speed, m.yaw = float(ref.get("radius", 0.0)), float(ref.get("speed", 0.0)), float(ref.get("yaw", 0.0))
        m.ramp_s, m.phase = float(ref.get("ramp", 0.0)), float(ref.get("phase", 0.0))
        m.end_s = float(ref.get("end_s", 0.0))
        m.t0_utime = int(t0_us)
        goal = ref.get("end", ref["center"])
        m.vehicle_count = vehicle_count
        m.goals = [[float(c) for c in goal] for _ in range(vehicle_count)]
        self.lc.publish(self.ch["reference"], m.encode())
        self.lc.publish(self.ch["obstacles"], obstacles_message(self.t, trees, m.utime, self.seq).encode())

    def close(self):
        self.stop.set()
        self.thread.join(2)


def obstacles_message(types, trees, utime: int, seq: int):
    """obstacles_t of standing trees (x, y, radius), `types` the mppi_lcm module."""
    o = types.obstacles_t()
    o.utime, o.seq = int(utime), int(seq)
    cyl = []
    for x, y, r in trees:
        c = types.cylinder_t()
        c.x, c.y, c.radius, c.vx, c.vy = x, y, r, 0.0, 0.0
        cyl.append(c)
    o.n, o.cylinders = len(cyl), cyl
    return o


class GuidedLink(StateClock):
    """ArduCopter's GUIDED position controller following the reference (the baseline)."""
    tick_hz = 50.0
    clock = "boot"  # the autopilot's time since boot (LOCAL_POSITION_NED)
    what = "LOCAL_POSITION_NED"

    def __init__(self, url: str, state_hz: float = 50.0):
        from pymavlink import mavutil
        self.mavlink = mavutil.mavlink
        deadline = time.monotonic() + 60.0
        while True:  # a SITL still starting is not listening yet
            try:
                self.conn = mavutil.mavlink_connection(url, source_system=254, source_component=190,
                                                       autoreconnect=True)
                break
            except OSError:
                if time.monotonic() > deadline:
                    raise
                time.sleep(0.2)
        super().__init__()
        self.state_hz = state_hz
        self.armed = False
        self.custom_mode = None
        self.landed_state = None
        self.acks = {}
        self.stop = threading.Event()
        self.thread = threading.Thread(target=self._loop, name="mission-mavlink", daemon=True)
        self.conn.wait_heartbeat(timeout=60)
        self.target = self.conn.target_system
        self.thread.start()
        ml = self.mavlink
        for mid, hz in ((ml.MAVLINK_MSG_ID_LOCAL_POSITION_NED, state_hz), (ml.MAVLINK_MSG_ID_EXTENDED_SYS_STATE, 2)):
            self.command(ml.MAV_CMD_SET_MESSAGE_INTERVAL, [mid, 1e6 / hz])

    def _loop(self):
        while not self.stop.is_set():
            msg = self.conn.recv_match(blocking=True, timeout=0.1)
            if msg is not None:
                self._on_message(msg.get_type(), msg)

    def _from_autopilot(self, msg) -> bool:
        """A heartbeat of the autopilot's, not of a ground station on the same link."""
        return msg.get_srcSystem() == self.target and msg.type != self.mavlink.MAV_TYPE_GCS

    def _on_message(self, t: str, msg):
        if t == "LOCAL_POSITION_NED":
            self._set_state(msg.time_boot_ms * 1000, np.array(frames.ned_to_enu((msg.x, msg.y, msg.z))))
        elif t == "HEARTBEAT" and self._from_autopilot(msg):
            self.armed = bool(msg.base_mode & self.mavlink.MAV_MODE_FLAG_SAFETY_ARMED)
            self.custom_mode = msg.custom_mode
        elif t == "EXTENDED_SYS_STATE":
            self.landed_state = msg.landed_state
        elif t == "COMMAND_ACK":
            self.acks[msg.command] = msg.result

    def command(self, cmd, params, timeout=3.0, retries=3):
        for _ in range(retries):
            self.acks.pop(cmd, None)
            self.conn.mav.command_long_send(self.target, 1, cmd, 0, *(list(params) + [0] * (7 - len(params))))
            deadline = time.monotonic() + timeout
            while cmd not in self.acks and time.monotonic() < deadline:
                time.sleep(0.02)
            if self.acks.get(cmd) == self.mavlink.MAV_RESULT_ACCEPTED:
                return
        raise FlightError(f"MAVLink command {cmd}: {self.acks.get(cmd, 'no COMMAND_ACK')}")

    def _mode(self, mode: int):
        self.command(self.mavlink.MAV_CMD_DO_SET_MODE, [self.mavlink.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED, mode])

    def start(self, takeoff, hold_here, say):
        ml = self.mavlink
        def guided_and_arm():  # GUIDED needs a position estimate, arming the pre-arm checks
            self._mode(4)
            self.command(ml.MAV_CMD_COMPONENT_ARM_DISARM, [1], retries=1)
            return "GUIDED, armed"
        arm_when_ready(guided_and_arm, say)
        if takeoff is not None:
            self.command(ml.MAV_CMD_NAV_TAKEOFF, [0, 0, 0, 0, 0, 0, takeoff])
            say(f"taking off to {takeoff:g} m")
            _wait(lambda: self.landed_state == ml.MAV_LANDED_STATE_IN_AIR, 60, "the take-off")
        hold_here()

    def finish(self, land, say):
        if not land:
            return
        self._mode(9)  # LAND
        say("landing")
        _wait(lambda: not self.armed, 90, "the landing (disarmed)")
        say("landed and disarmed")

    def send(self, ref: dict, t0_us: int, trees, vehicle_count=1):
        now = self.now_us()
        if now is None:
            return
        p, v, a = (x[0] for x in reference.evaluate(ref, [(now - t0_us) * 1e-6]))
        ml = self.mavlink
        mask = (ml.POSITION_TARGET_TYPEMASK_YAW_RATE_IGNORE)
        # ENU -> NED; the heading as mppid's (ENU yaw 0: east, NED yaw pi/2).
        self.conn.mav.set_position_target_local_ned_send(
            0, self.target, 1, ml.MAV_FRAME_LOCAL_NED, mask, *frames.enu_to_ned(p), *frames.enu_to_ned(v),
            *frames.enu_to_ned(a), frames.yaw_enu_to_ned(float(ref.get("yaw", 0.0))), 0.0)

    def close(self):
        self.stop.set()
        self.thread.join(2)
        self.conn.close()
