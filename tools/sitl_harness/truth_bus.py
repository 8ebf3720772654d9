"""An autopilot SITL's truth on the sensors' bus, for a sensed mission (flights/sensed.py): the
referee of the flight (ap_truth.py for ArduCopter, px4_truth.py for PX4 with SIH) publishes
each true state as vehicle_state_t on SIM_TRUTH, from which mppid-sensors ray-casts the world
(sim/sensor_node.hpp). One message for both autopilots: the rate quadrotor's 13 states,
position and velocity ENU in the bridge's local frame (the estimator's origin: mppid's states'
and the mission's trees' frame), attitude body FLU -> ENU by the bridge's own conversion
(mppi_mavlink.frames), body rates FLU; `sample_utime` the truth's time on this host's wall
clock, the clock of mppid's states (each referee maps its autopilot's clock as it must:
`TruthPublisher.clock` for ArduCopter, mppi_mavlink.clock_sync for PX4's drifting SIH).
"""
from __future__ import annotations

import time


class TruthPublisher:
    """True states as vehicle_state_t on SIM_TRUTH (the module's docstring)."""
    CHANNEL = "SIM_TRUTH"

    def __init__(self, lcm_url: str):
        import lcm
        from mppi_mavlink import lcm_types
        self.t = lcm_types.import_mppi_lcm()
        self.lc = lcm.LCM(lcm_url)
        self.seq = 0
        self.offset_us = None  # wall - boot: the smallest receipt delay seen

    def clock(self, boot_us: int, wall_us: int) -> int:
        """A boot time on this host's wall clock: boot time + the smallest receipt delay seen so
        far (an autopilot whose clock keeps the wall clock's rate: ArduPilot's SITL)."""
        d = wall_us - boot_us
        self.offset_us = d if self.offset_us is None else min(self.offset_us, d)
        return boot_us + self.offset_us

    def publish(self, x_enu, v_enu, q_ned_frd, rates_frd, sample_us: int):
        """One true state: position and velocity ENU (m, m/s), the attitude (w, x, y, z) body FRD
        -> NED as MAVLink gives it, the body rates FRD (rad/s), its time on the wall clock (us)."""
        from mppi_mavlink import frames
        st = self.t.vehicle_state_t()
        self.seq += 1
        st.utime, st.seq, st.sample_utime = time.time_ns() // 1000, self.seq, int(sample_us)
        st.model, st.vehicle_count, st.nx, st.n = st.MODEL_QUADROTOR_RATE, 1, 13, 13
        q = frames.q_ned_frd_to_enu_flu(tuple(q_ned_frd))
        st.x = [*map(float, x_enu), *map(float, v_enu), *q, *frames.frd_to_flu(tuple(rates_frd))]
        self.lc.publish(self.CHANNEL, st.encode())
