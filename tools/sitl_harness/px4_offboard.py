"""PX4's own offboard position control following a mission: the baseline mppid is flown
against through PX4 (`tools/sitl run --autopilot px4 --controller px4`).

The mission tool's runner (mppi_mission.runner) flies the mission as it does for mppid and
for ArduCopter's GUIDED baseline; this link is the PX4 user's way to the same paths: arm,
PX4's take-off (MIS_TAKEOFF_ALT), then a SET_POSITION_TARGET_LOCAL_NED stream at 50 Hz with
the reference's position, velocity and acceleration (PX4's position controller takes the
last two as feed-forward) and its heading, pre-streamed for 1 s at the hover point before
OFFBOARD is asked for (PX4 refuses OFFBOARD without a stream); at the end, PX4's Land.
The heading at the hand-over is the vehicle's own (ATTITUDE_QUATERNION), as mppid's hand-over keeps it.

    python -m sitl_harness.px4_offboard MISSION.yaml --url udpin:127.0.0.1:14540 [--seed N] [--out DIR]
"""
from __future__ import annotations

import argparse
import math
import signal
import sys
import time
from pathlib import Path

from mppi_mavlink import frames
from mppi_mission import plan as plan_mod
from mppi_mission.vehicles import FlightError, GuidedLink, _wait, arm_when_ready

MAIN_OFFBOARD = 6
PRESTREAM_S = 1.0


class Px4OffboardLink(GuidedLink):
    """GuidedLink's setpoint stream, with PX4's arming, take-off and OFFBOARD hand-over."""

    def __init__(self, url: str, state_hz: float = 50.0):
        self.params = {}
        super().__init__(url, state_hz)

    def _from_autopilot(self, msg) -> bool:
        return msg.get_srcSystem() == self.target and msg.get_srcComponent() == 1

    def _on_message(self, t: str, msg):
        if t == "ATTITUDE_QUATERNION":  # the NED heading -> ENU yaw
            w, x, y, z = msg.q1, msg.q2, msg.q3, msg.q4
            self.yaw = frames.yaw_ned_to_enu(math.atan2(2.0 * (w * z + x * y), 1.0 - 2.0 * (y * y + z * z)))
        elif t == "PARAM_VALUE":
            self.params[msg.param_id] = msg.param_value
        else:
            super()._on_message(t, msg)

    def param_set(self, name: str, value: float, timeout: float = 5.0):
        self.params.pop(name, None)
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            self.conn.mav.param_set_send(self.target, 1, name.encode(), value, self.mavlink.MAV_PARAM_TYPE_REAL32)
            end = time.monotonic() + 0.5
            while time.monotonic() < end:
                if abs(self.params.get(name, math.inf) - value) < 1e-4:
                    return
                time.sleep(0.02)
        raise FlightError(f"PX4 did not take {name}={value:g}")

    def offboard(self) -> bool:
        return self.custom_mode is not None and (self.custom_mode >> 16) & 0xFF == MAIN_OFFBOARD

    def start(self, takeoff, hold_here, say):
        ml = self.mavlink

        def arm():  # PX4 refuses until its checks pass (a position estimate, a home)
            self.command(ml.MAV_CMD_COMPONENT_ARM_DISARM, [1], retries=1)
            return "armed"
        if takeoff is not None:
            self.param_set("MIS_TAKEOFF_ALT", float(takeoff))
            arm_when_ready(arm, say)
            self.command(ml.MAV_CMD_NAV_TAKEOFF, [-1.0, 0, 0, math.nan, math.nan, math.nan, math.nan])
            say(f"taking off to {takeoff:g} m")
            _wait(lambda: (self.landed_state == ml.MAV_LANDED_STATE_IN_AIR and self.position() is not None
                           and self.position()[2] > 0.9 * takeoff), 60, "the take-off")
        hold_here()   # the runner streams the hover point from here on
        time.sleep(PRESTREAM_S)
        self.command(ml.MAV_CMD_DO_SET_MODE, [ml.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED, MAIN_OFFBOARD, 0])
        _wait(self.offboard, 5, "OFFBOARD")
        say("OFFBOARD")

    def finish(self, land, say):
        if not land:
            return
        self.command(self.mavlink.MAV_CMD_NAV_LAND, [0, 0, 0, math.nan, math.nan, math.nan, math.nan])
        say("landing")
        _wait(lambda: not self.armed, 90, "the landing (disarmed)")
        say("landed and disarmed")


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(prog="px4_offboard", description=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("mission", type=Path)
    ap.add_argument("--url", default="udpin:127.0.0.1:14540", help="PX4's offboard link")
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--out", type=Path)
    a = ap.parse_args(argv)
    from mppi_mission.runner import Runner
    mission = plan_mod.load(a.mission)
    if a.out:
        a.out.mkdir(parents=True, exist_ok=True)
    signal.signal(signal.SIGTERM, lambda *_: (_ for _ in ()).throw(KeyboardInterrupt()))
    link = Px4OffboardLink(a.url)
    try:
        summary = Runner(mission, link, seed=a.seed, out=a.out,
                         say=lambda s: print(f"{time.strftime('%H:%M:%S')} {s}", flush=True)).run()
    finally:
        link.close()
    return 0 if summary["outcome"] == "done" else 1


if __name__ == "__main__":
    sys.exit(main())
