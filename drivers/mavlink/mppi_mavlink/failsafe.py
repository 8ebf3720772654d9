"""The bridge's own failsafe: an engagement never outlives mppid's stream. Engaged, and no
setpoint forwarded for `forwarding.disengage_after_s` (mppid dead, hung or restarting, the
states stopped, the link lost), or mppid seen restarting, or the link lost: the bridge
disengages, tells the operator, and nothing is forwarded again until a new `offboard`. Then
the vehicle is handed back (the profile's `hand_back`: ArduPilot's GUIDED would only level
and drift, so BRAKE (LOITER would read the throttle stick as a climb rate); PX4's own offboard-loss failsafe acts, as COM_OBL_RC_ACT says), once
the link is up and while the vehicle is still in the offboard mode (engaged in ArduCopter's
AUTO guided sub-mode, `segment`, it is not: AUTO keeps it, GUID_TIMEOUT levelling it until a
guided limit ends the segment, docs/missions.md). Engaged and outside the
geofence (fence.py, `fence` settings): disengaged and held (the profile's `hold`: PX4 HOLD,
ArduPilot BRAKE), the operator told; `offboard` outside it is refused."""
from __future__ import annotations

import logging
import time

from . import fence as fence_mod, realtime
from .autopilot import CommandError
from .engagement import ENGAGED
from .notices import WARNING
from .state import mono_us

log = logging.getLogger("mppi_mavlink")


class Failsafe:
    def __init__(self, settings, engagement, fwd, ap, profile, notices, states):
        self.after_us = int(settings["forwarding"]["disengage_after_s"] * 1e6)
        self.fence = fence_mod.parse({k: v for k, v in settings["fence"].items() if v is not None})
        self.states = states
        self.engagement, self.fwd, self.ap, self.profile, self.notices = engagement, fwd, ap, profile, notices
        self.handback_pending = False
        self.hold_pending = False
        self.busy = False
        self.next_try = 0.0

    def stream_lost(self, why: str) -> None:
        latch = self.profile.offboard_loss_resumes  # PX4: no pre-stream until `offboard` (engagement.py)
        if self.engagement.snapshot().state == ENGAGED and self.engagement.disengage(why, latch=latch):
            self.handback_pending = True

    def fence_breach(self) -> str:
        """Why the latest state is outside the fence ('' inside, or no fence)."""
        if self.fence is None:
            return ""
        p = self.states.last_p
        why = "no position yet" if p is None else self.fence.breach(p)
        return f"geofence: {why}" if why else ""

    def check(self, now: float) -> None:
        """Housekeeping, every 20 ms: the stream's age and the fence while engaged, and a
        pending hand-back."""
        e = self.engagement
        if e.snapshot().state == ENGAGED:
            last = max(self.fwd.last_forward_mono or 0, int(e.since * 1e6))
            breach = self.fence_breach()
            if breach and e.disengage(breach):
                self.hold_pending = self.handback_pending = True
            elif mono_us() - last > self.after_us:
                self.stream_lost(f"mppid's setpoints stopped for {self.after_us / 1e6:g} s "
                                 f"({self.fwd.last_drop or 'none came'})")
        if self.handback_pending and self.ap.link_up and not self.busy and now >= self.next_try:
            self.busy = True
            realtime.thread(self._hand_back, "hand-back").start()

    def _hand_back(self):
        try:
            if self.engagement.snapshot().state == ENGAGED or not self.profile.offboard_mode(self.ap.custom_mode):
                self.handback_pending = False  # engaged again, or the vehicle left the mode already
                return
            if self.hold_pending:
                self.profile.hold(self.ap)
                mode = "the autopilot's hold"
            else:
                mode = self.profile.hand_back(self.ap)
            self.handback_pending = self.hold_pending = False
            if mode:
                log.warning("the vehicle handed back to the autopilot: %s", mode)
                self.notices.tell(WARNING, f"mppid: vehicle handed to {mode}")
        except CommandError as e:
            log.error("hand-back failed: %s; trying again", e)
            self.next_try = time.monotonic() + 1.0
        finally:
            self.busy = False
