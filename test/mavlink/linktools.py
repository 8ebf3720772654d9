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
