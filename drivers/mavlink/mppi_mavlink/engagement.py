"""Engagement: whether mppid's setpoints may go to the autopilot, behind one lock, every
transition logged.

States: `disengaged` (nothing is forwarded; `why` says since when), `prestream` (PX4: the
stream runs before OFFBOARD is entered, which PX4 needs, and setpoints outside OFFBOARD are
ignored by it), `engaged` (after `offboard`, in the custom mode it confirmed; leaving that
mode, or a disarm, made by someone else ends it, and so does mppid's stream stopping:
failsafe.py). Apart, `takeoff_in_progress`: ArduPilot's own take-off, which `offboard` waits
for. The receive thread, the LCM thread, housekeeping and the control socket all change it,
only through these methods; `on_change(why, changed)` runs after each, outside the lock.

One rule before and after a disengage (docs/failsafes.md): nothing engages by itself. On an
autopilot that is pre-streamed (PX4), the pre-stream runs whenever the bridge is not engaged
and the vehicle is out of its offboard mode, from the start and after any disengage alike, so
the operator's own switch into OFFBOARD (RC or ground station) engages, seen as the mode
changing into OFFBOARD; a vehicle found in OFFBOARD without that change (the bridge started,
or disengaged, while it was there) gets nothing until it leaves OFFBOARD or `offboard` is sent.
But after the bridge's own failsafe (mppid's stream stopped, mppid restarted, the link lost:
`disengage(latch=True)`) on an autopilot whose offboard-loss failsafe is a fallback that ends
when setpoints return (PX4: OFFBOARD stays the intended mode), the pre-stream stays off until
`offboard` is sent: it would take the vehicle back into OFFBOARD by itself.
"""
from __future__ import annotations

import logging
import threading
import time
from collections import deque
from dataclasses import dataclass

from .autopilot import CommandError

log = logging.getLogger("mppi_mavlink")
DISENGAGED, PRESTREAM, ENGAGED = "disengaged", "prestream", "engaged"


@dataclass(frozen=True)
class Snapshot:
    state: str
    mode: int | None          # the custom mode `offboard` confirmed (engaged only)
    why: str                  # why disengaged ('' otherwise)
    takeoff_in_progress: bool

    @property
    def forwarding(self) -> bool:
        return self.state != DISENGAGED


class Engagement:
    def __init__(self, prestream: bool, on_change=None):
        self.lock = threading.Condition()
        self.on_change = on_change or (lambda why, changed: None)
        self.prestreamed = prestream
        self._expecting = False         # `offboard` in progress: it, not a HEARTBEAT, engages
        self.since = time.monotonic()   # of the latest state change
        self._state = PRESTREAM if prestream else DISENGAGED
        self._mode = None
        self._why = "" if prestream else "waiting for `offboard`"
        self._takeoff = False
        self._latched = False           # no pre-stream until `offboard` (the module doc)
        self.transitions = deque(maxlen=64)   # (monotonic s, from, to, why): the log's record
        log.info("engagement: %s (%s)", self._state, self._why or "pre-streamed until `offboard`")

    def snapshot(self) -> Snapshot:
        with self.lock:
            return Snapshot(self._state, self._mode, self._why, self._takeoff)

    @property
    def forwarding(self) -> bool:
        with self.lock:
            return self._state != DISENGAGED

    def _to(self, state: str, mode, why: str) -> bool:
        """Under the lock: the transition, logged; True when the state changed."""
        old = self._state
        self._state, self._mode = state, mode
        self._why = why if state == DISENGAGED else ""
        if old == state:
            return False
        self.since = time.monotonic()
        self.transitions.append((time.monotonic(), old, state, why))
        if state == DISENGAGED:
            log.warning("forwarding stopped: %s; nothing goes to the autopilot until the next `offboard`", why)
        log.info("engagement: %s -> %s (%s)", old, state, why)
        return True

    def prestream(self, why: str) -> bool:
        """PX4's `offboard`: stream again before OFFBOARD is asked for."""
        with self.lock:
            if self._state == ENGAGED:
                return False
            self._latched = False
            changed = self._to(PRESTREAM, None, why)
        self.on_change(why, changed)
        return changed

    def engage(self, custom_mode, mode_name: str, by: str = "`offboard`") -> bool:
        why = f"{mode_name} entered: {by}"
        with self.lock:
            changed = self._to(ENGAGED, custom_mode, why)
        log.info("engaged in mode %s: mppid's setpoints go to the autopilot", mode_name)
        self.on_change(why, changed)
        return changed

    def disengage(self, why: str, latch: bool = False) -> bool:
        """Ends any engagement (and a take-off wait); True when something was forwarded until
        now. `latch`: no pre-stream until `offboard` (the module doc)."""
        with self.lock:
            changed = self._to(DISENGAGED, None, why)
            self._why = why
            self._takeoff = False
            self._latched = latch
            if latch:
                log.warning("no pre-stream until `offboard`: the autopilot would resume OFFBOARD on it by itself")
        self.on_change(why, changed)
        return changed

    def watch(self, custom_mode, mode_name: str, armed: bool, was_armed: bool, in_offboard: bool,
              was_in_offboard) -> bool:
        """A HEARTBEAT. Engaged: a mode change or a disarm that the bridge did not ask for ends
        the engagement (the operator, a failsafe or the RC took over). Pre-streamed autopilots:
        the rule in the module doc (`was_in_offboard` None: the first HEARTBEAT)."""
        with self.lock:
            state, mode, latched = self._state, self._mode, self._latched
        if state == ENGAGED:
            if custom_mode != mode:
                return self.disengage(f"mode changed to {mode_name} by someone else")
            if was_armed and not armed:
                return self.disengage("the autopilot disarmed")
            return False
        if not self.prestreamed:
            return False
        if state == PRESTREAM and in_offboard and not self._expecting:
            if was_in_offboard is False:
                return self.engage(custom_mode, mode_name, "the operator switched it (RC or ground station)")
            return self.disengage(f"the vehicle is in {mode_name}, not switched there while the bridge watched")
        if state == DISENGAGED and not in_offboard and not latched:
            return self.prestream(f"the vehicle is in {mode_name}: pre-streamed for the next switch")
        return False

    def expect_offboard(self, on: bool) -> None:
        """While `offboard` runs, the autopilot entering its offboard mode is the bridge's doing."""
        with self.lock:
            self._expecting = on

    def takeoff_started(self) -> None:
        with self.lock:
            self._takeoff = True
            log.info("engagement: the autopilot's take-off started; `offboard` waits for it")

    def on_landed_state(self, landed_state: int, in_progress_states) -> None:
        """EXTENDED_SYS_STATE: a landed state outside `in_progress_states` ends the take-off."""
        with self.lock:
            if self._takeoff and landed_state not in in_progress_states:
                self._takeoff = False
                log.info("engagement: the take-off is over (landed state %d)", landed_state)
            self.lock.notify_all()

    def wait_takeoff_done(self, timeout_s: float) -> None:
        """ArduPilot: `offboard` right after `takeoff` waits for the take-off to end (landed
        state IN_AIR), or mppid's first setpoint would take it over."""
        deadline = time.monotonic() + timeout_s
        with self.lock:
            while self._takeoff and time.monotonic() < deadline:
                self.lock.wait(max(0.0, deadline - time.monotonic()))
            if self._takeoff:
                raise CommandError(f"offboard refused: the take-off is not complete after {timeout_s:g} s")
