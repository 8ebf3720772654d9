"""Test instruments: a UDP tap that carries (and can cut) the MAVLink link and keeps every
datagram it carried, and a stand-in controller on LCM that answers each state."""
from __future__ import annotations

import math
import os
import select
import socket
import threading
import time

os.environ.setdefault("MAVLINK20", "1")
from pymavlink import mavutil  # noqa: E402

from mavtest import LCM_URL  # noqa: E402
from mppi_mavlink import lcm_types  # noqa: E402

# The simulated autopilot as an ArduCopter that lets mppid fly (GUID_OPTIONS bit 3: attitude
# targets in GUIDED) with the hover thrust mppid's vehicle file says.
ARDUPILOT = dict(autopilot="ardupilot", vehicle_params=["GUID_OPTIONS=8", "MOT_THST_HOVER=0.4"])


class UdpTap:
    """vehicle --udp--> 127.0.0.1:listen  [tap]  --udp--> 127.0.0.1:forward (the bridge).
    Keeps (monotonic us, direction, bytes) of everything it carried; `cut` drops all."""

    def __init__(self, listen: int, forward: int):
        self.a = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.a.bind(("127.0.0.1", listen))
        self.b = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.b.bind(("127.0.0.1", 0))
        self.fwd = ("127.0.0.1", forward)
        self.vehicle = None
        self.cut = False
        self.log = []
        self.stop = threading.Event()
        self.t = threading.Thread(target=self._run, daemon=True)
        self.t.start()

    def _run(self):
        while not self.stop.is_set():
            r, _, _ = select.select([self.a, self.b], [], [], 0.05)
            for s in r:
                data, addr = s.recvfrom(65536)
                now = time.monotonic_ns() // 1000
                if s is self.a:
                    self.vehicle = addr
                    if not self.cut:
                        self.log.append((now, "up", data))
                        self.b.sendto(data, self.fwd)
                elif self.vehicle is not None and not self.cut:
                    self.log.append((now, "down", data))
                    self.a.sendto(data, self.vehicle)

    def close(self):
        self.stop.set()
        self.t.join(2)
        self.a.close()
        self.b.close()

    def decoded(self, direction="down"):
        """(monotonic us, message) of every MAVLink message carried that way, parsed afresh."""
        mav = mavutil.mavlink.MAVLink(None)
        mav.robust_parsing = True
        out = []
        for t, d, data in list(self.log):
            if d != direction:
                continue
            for m in mav.parse_buffer(data) or []:
                out.append((t, m))
        return out

    def setpoints(self):
        return [(t, m) for t, m in self.decoded("down") if m.get_type() == "SET_ATTITUDE_TARGET"]

    def recent(self, direction, kind, window_us=500_000):
        """(monotonic us, message) of the `kind` messages carried `direction` in the last
        `window_us` of what was carried that way (empty until that much has been)."""
        mav = mavutil.mavlink.MAVLink(None)
        mav.robust_parsing = True
        carried = [(t, data) for t, d, data in self.log[-1200:] if d == direction]
        if not carried or carried[-1][0] - carried[0][0] < window_us:
            return []
        since = carried[-1][0] - window_us
        return [(t, m) for t, data in carried if t >= since
                for m in mav.parse_buffer(data) or [] if m.get_type() == kind]


class StandInController:
    """Answers every vehicle_state_t with one command_t (hover thrust, zero rates, or what
    `make_u(seq)` returns) and publishes a controller_status_t at 5 Hz with `healthy`."""

    def __init__(self, make_u=None):
        import lcm
        self.mppi_lcm = lcm_types.import_mppi_lcm()
        self.lc = lcm.LCM(LCM_URL)
        self.lc.subscribe("MPPI_STATE", self._on_state)
        self.make_u = make_u or (lambda seq: [9.81, 0.0, 0.0, 0.0])
        self.healthy = True
        self.answer = True
        self.seq = 0
        self.sent = []       # (seq, u)
        self.states = 0
        self.last_state_seq = 0
        self.last_x = None   # the newest state's x (position first, ENU)
        self.stop = threading.Event()
        self.t = threading.Thread(target=self._run, daemon=True)
        self.t.start()

    def command(self, state_seq, u, seq=None, mode=0):
        c = self.mppi_lcm.command_t()
        if seq is None:
            self.seq += 1
            seq = self.seq
        c.utime, c.seq, c.state_seq, c.mode = time.time_ns() // 1000, seq, state_seq, mode
        c.kind = self.mppi_lcm.command_t.KIND_THRUST_RATES
        c.n, c.u = 4, [float(x) for x in u]
        self.lc.publish("MPPI_COMMAND", c.encode())
        self.sent.append((seq, list(u)))

    def _on_state(self, ch, data):
        st = self.mppi_lcm.vehicle_state_t.decode(data)
        self.states += 1
        self.last_state_seq = st.seq
        self.last_x = list(st.x)
        if self.answer:
            self.command(st.seq, self.make_u(self.seq + 1))

    def _status(self):
        s = self.mppi_lcm.controller_status_t()
        s.utime = time.time_ns() // 1000
        s.backend, s.task = "standin", "quadrotor_rate_track"
        s.healthy = int(self.healthy)
        s.mode = 0 if self.healthy else 2
        self.lc.publish("MPPI_STATUS", s.encode())

    def _run(self):
        next_status = 0.0
        while not self.stop.is_set():
            if time.monotonic() >= next_status:
                next_status = time.monotonic() + 0.2
                self._status()
            self.lc.handle_timeout(20)

    def close(self):
        self.stop.set()
        self.t.join(2)


def all_finite(m) -> bool:
    return all(math.isfinite(v) for v in (m.thrust, m.body_roll_rate, m.body_pitch_rate, m.body_yaw_rate))


class TrackingController(StandInController):
    """Stands in for mppid on a mission: follows the reference on MPPI_REFERENCE (hold and
    line, evaluated as mppid does: mppi_mission.reference) with a PD position loop to thrust
    (N, a 1 kg vehicle) and body rates (FLU), answering each state as mppid does."""

    def __init__(self):
        self.ref = None
        super().__init__()
        self.lc.subscribe("MPPI_REFERENCE", self._on_reference)

    def _on_reference(self, ch, data):
        m = self.mppi_lcm.reference_t.decode(data)
        kinds = {m.KIND_HOLD: "hold", m.KIND_LINE: "line"}
        self.ref = ({"kind": kinds.get(m.kind, "hold"), "center": list(m.center), "speed": m.speed, "ramp": m.ramp_s,
                     "yaw": m.yaw, "end": list(m.goals[0]) if m.vehicle_count else list(m.center)}, m.t0_utime)

    def _on_state(self, ch, data):
        st = self.mppi_lcm.vehicle_state_t.decode(data)
        self.states += 1
        self.last_state_seq, self.last_x = st.seq, list(st.x)
        if self.answer:
            self.command(st.seq, self.track(st))

    def track(self, st):
        from mppi_mission import reference
        x = st.x
        if self.ref is None:
            return [9.81, 0.0, 0.0, 0.0]
        ref, t0 = self.ref
        p, v, a = (c[0] for c in reference.evaluate(ref, [(st.sample_utime - t0) * 1e-6]))
        acc = [max(-4.0, min(4.0, a[i] + 2.0 * (p[i] - x[i]) + 3.0 * (v[i] - x[3 + i]))) for i in range(3)]
        f = [acc[0], acc[1], acc[2] + 9.81]
        w, qx, qy, qz = x[6:10]
        bz = [2 * (qx * qz + w * qy), 2 * (qy * qz - w * qx), 1 - 2 * (qx * qx + qy * qy)]   # body z in ENU
        fn = math.sqrt(sum(c * c for c in f))
        e = [bz[1] * f[2] - bz[2] * f[1], bz[2] * f[0] - bz[0] * f[2], bz[0] * f[1] - bz[1] * f[0]]
        e = [c / fn for c in e]
        bx = [1 - 2 * (qy * qy + qz * qz), 2 * (qx * qy + w * qz), 2 * (qx * qz - w * qy)]
        by = [2 * (qx * qy - w * qz), 1 - 2 * (qx * qx + qz * qz), 2 * (qy * qz + w * qx)]
        yaw = math.atan2(bx[1], bx[0])
        dyaw = math.remainder(ref["yaw"] - yaw, math.tau)
        thrust = max(0.0, sum(fi * bi for fi, bi in zip(f, bz)))
        return [thrust, 6.0 * sum(a_ * b_ for a_, b_ in zip(bx, e)), 6.0 * sum(a_ * b_ for a_, b_ in zip(by, e)),
                2.0 * dyaw]
