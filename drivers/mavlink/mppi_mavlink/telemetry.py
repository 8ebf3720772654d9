"""The telemetry the bridge needs, asked for on every link-up, and the rate it arrives at.

PX4 streams ODOMETRY, ATTITUDE_QUATERNION and LOCAL_POSITION_NED to an offboard link by
itself; ArduPilot sends a message on a link only once a peer asks for it (per link, lost on
reboot). So on every link-up the bridge sends MAV_CMD_SET_MESSAGE_INTERVAL for each message
it builds states from (at `telemetry.state_hz`) and for the slow ones it reads (SYS_STATUS
for the battery, EXTENDED_SYS_STATE for the landed state, at `telemetry.status_hz`).

`StateRate` counts the states the bridge publishes over a sliding window: below
`telemetry.min_state_hz` the bridge refuses to fly and says why (a state stream that slow
would make mppid plan from old states, and its commands go stale at the gate anyway).
"""
from __future__ import annotations

from collections import deque

from pymavlink import mavutil

mavlink = mavutil.mavlink

STATUS_MESSAGES = (mavlink.MAVLINK_MSG_ID_SYS_STATUS, mavlink.MAVLINK_MSG_ID_EXTENDED_SYS_STATE)


def requests(state_messages, state_hz: float, status_hz: float) -> list[tuple[int, str, int]]:
    """(message id, name, interval in us) for MAV_CMD_SET_MESSAGE_INTERVAL, states first;
    `state_messages`: what the autopilot's profile builds states from (autopilots/)."""
    out = []
    for ids, hz in ((state_messages, state_hz), (STATUS_MESSAGES, status_hz)):
        for mid in ids:
            out.append((mid, mavlink.mavlink_map[mid].msgname, int(round(1e6 / hz))))
    return out


class StateRate:
    """States published per second over the last `window_s` (monotonic seconds)."""

    def __init__(self, window_s: float = 1.0):
        self.window = float(window_s)
        self.times: deque[float] = deque()

    def add(self, t: float) -> None:
        self.times.append(t)
        self._trim(t)

    def rate(self, now: float) -> float:
        self._trim(now)
        return len(self.times) / self.window

    def _trim(self, now: float) -> None:
        while self.times and now - self.times[0] > self.window:
            self.times.popleft()


def rate_refusal(rate_hz: float, min_hz: float, since_link_up_s: float, grace_s: float) -> str:
    """Why the bridge refuses to fly for the state rate ('' when it is enough). The first
    `grace_s` after a link-up are the autopilot's time to act on the requests: no verdict."""
    if since_link_up_s < grace_s or rate_hz >= min_hz:
        return ""
    return (f"telemetry: states arrive at {rate_hz:.1f} Hz, below telemetry.min_state_hz {min_hz:g} "
            f"(asked for on link-up; is the autopilot streaming ATTITUDE_QUATERNION and LOCAL_POSITION_NED?); "
            f"refusing to fly")
