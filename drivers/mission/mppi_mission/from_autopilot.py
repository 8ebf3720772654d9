"""`mppid-mission from-autopilot`: the mission the operator uploaded to the autopilot, flown
by mppid (docs/missions.md, "Missions planned in a ground station").

Read through the bridge (`mission download`: its one link to the autopilot), converted
(autopilot_plan.py) and checked before anything is armed or taken over: a refusal names the
item and why, on the ground station (STATUSTEXT) and here, and nothing is flown. Then the
runner flies it as any mission (arm, the autopilot's take-off, `offboard`: ArduPilot GUIDED,
PX4 OFFBOARD), the ground station following: the autopilot's current item set to the item
flown (MISSION_SET_CURRENT), MISSION_ITEM_REACHED when it is done, a STATUSTEXT at each.

The mission changed from the ground station in flight (the bridge's `mission status`): at the
end of the leg being flown, the mission is read again and flown from the autopilot's current
item; refused, mppid holds where the vehicle is and the tool ends (the operator takes the
vehicle back with a mode switch). The operator's mode switch in flight (the bridge disengages)
ends the mission at once, nothing landed by the tool. `--wait-armed`: the tool waits for the
operator to arm the vehicle from the ground station, then reads the mission and flies it.
Exit status: 0 done, 1 refused, failed or taken back, 2 bad arguments.
"""
from __future__ import annotations

import math
import time

import numpy as np

from . import autopilot_plan as ap_plan
from . import reference
from .runner import Runner
from .vehicles import FlightError

IN_AIR = 2          # MAV_LANDED_STATE_IN_AIR
REREAD_TRIES = 3    # a mission changed while read again: read again, this many times


class MissionRequests:
    """The bridge's `mission ...` requests (through the link's control socket)."""

    def __init__(self, link):
        self.link = link

    def ask(self, line: str, timeout=30.0) -> dict:
        from mppi_mavlink import control
        return control.request(self.link.socket, line, timeout)

    def download(self) -> dict:
        r = self.ask("mission download", timeout=120.0)
        if not r.get("ok"):
            raise ap_plan.Refusal(None, r.get("message", "the mission could not be read"))
        return r["mission"]

    def refuse(self, text: str):
        self.ask(f"mission refuse mppid refuses the mission: {text}")


def _airborne(link) -> bool:
    st = link.bridge_status()
    return bool(st.get("armed")) and st.get("landed_state") in (None, IN_AIR)


def read_and_convert(link, bridge: MissionRequests, speed: float, here=None, start_from_current=False, dl=None):
    """The autopilot's mission (`dl`, else read now) as a plan, flown from `here` (default:
    where the vehicle is)."""
    dl = bridge.download() if dl is None else dl
    h = link.heading()
    start = dl.get("current") if start_from_current else None
    return ap_plan.convert(dl, link.position() if here is None else here,
                           None if h is None else math.degrees(h), _airborne(link), speed, start)


class AutopilotRunner(Runner):
    def __init__(self, conv: ap_plan.Converted, link, bridge: MissionRequests, speed: float, **kw):
        super().__init__(conv.mission, link, **kw)
        self.conv, self.bridge, self.speed = conv, bridge, speed
        self.current = None
        self.summary["items"] = []

    def _fly_legs(self, here, origin) -> str:
        if self.conv.takeoff_item is not None:
            self._reached(self.conv.takeoff_item)
        i = 0
        while i < len(self.m.legs):
            seq = self.conv.leg_items[i]
            if seq != self.current:
                self.current = seq
                self._show_item(seq, f"mppid: item {self.conv.numbers[seq]} {self.conv.names[seq]}")
            ok, here = self._fly_leg(i, here, origin)
            if not ok:
                return self._stopped(seq)
            if i + 1 == len(self.m.legs) or self.conv.leg_items[i + 1] != seq:
                self._reached(seq)
            i += 1
            if self.bridge.ask("mission status").get("mission_status", {}).get("changed"):
                if not self._reload(here):
                    return "refused in flight: holding"
                i = 0
        return self._finished()

    def reached_early(self, step, i, t, p) -> bool:
        """A NAV_WAYPOINT's line ends where the autopilot counts the waypoint reached, within its
        acceptance radius of the end (its goal leg, next), when the vehicle gets there ahead of
        the line's reference: a goal-seeking task (the forest's) flies ahead of it, a tracking
        task follows it to its end."""
        legs, items = self.m.legs, self.conv.leg_items
        if step.kind != "line" or i + 1 >= len(legs) or "goal" not in legs[i + 1] or items[i + 1] != items[i]:
            return False
        end, radius = np.asarray(step.end, float), float(legs[i + 1]["goal"]["radius"])
        ref = reference.evaluate(step.ref, [t])[0][0]
        return float(np.linalg.norm(p - end)) <= radius < float(np.linalg.norm(ref - end))

    def _show_item(self, seq, text):
        """The item flown now: the autopilot's current item follows (MISSION_SET_CURRENT)."""
        self.bridge.ask(f"mission current {seq} {text}")

    def _finished(self) -> str:
        """The mission's end (docs/missions.md): a landing is the bridge's `land` (the runner's);
        a NAV_RETURN_TO_LAUNCH the autopilot's own (ArduPilot: AUTO from that item, PX4:
        AUTO.RTL); no landing: the autopilot's hold (PX4 Hold, ArduPilot BRAKE)."""
        seq = self.conv.handback_item
        if seq is not None:
            n = self.conv.numbers[seq]
            self.bridge.ask(f"mission say mppid: mission flown to item {n} NAV_RETURN_TO_LAUNCH: the autopilot's own")
            r = self.bridge.ask(f"resume {seq}" if self.conv.dialect == "ardupilot" else "rtl")
        elif not self.m.land:
            self.bridge.ask("mission say mppid: mission done, the autopilot holds")
            r = self.bridge.ask("hold")
        else:
            self.bridge.ask("mission say mppid: mission done, landing")
            return "done"
        self.say(r.get("message", ""))
        return "done" if r.get("ok") else f"hand-back failed: {r.get('message')}"

    def interrupted(self) -> str:
        """The operator took the vehicle back (a mode switch: the bridge disengaged)."""
        st = self.link.bridge_status()
        if st.get("engagement") == "disengaged":
            return f"mppid disengaged ({st.get('disengaged_why')})"
        return ""

    def _stopped(self, seq) -> str:
        """A leg not done: nothing lands by itself. Taken back: the autopilot has the vehicle;
        else mppid holds where it is."""
        n, why = self.conv.numbers[seq], self.summary["legs"][-1].get("why", "")
        self.m.land = False
        if not why.startswith("mppid disengaged"):
            self.hold_here()
            why += ", holding"
        self.bridge.ask(f"mission say mppid: mission stopped at item {n}: {why}")
        return f"stopped at item {n}: {why}"

    def _reached(self, seq):
        self.bridge.ask(f"mission reached {seq}")
        self.summary["items"].append(seq)

    def _reload(self, here) -> bool:
        """The changed mission read again and flown from the autopilot's current item (True),
        or refused: mppid holds where the vehicle is (False)."""
        self.say("the mission changed on the autopilot: reading it again")
        for attempt in range(REREAD_TRIES):
            try:
                conv = read_and_convert(self.link, self.bridge, self.speed, here=np.asarray(here, float),
                                        start_from_current=True)
                break
            except ap_plan.Refusal as e:
                if "changed while it was read" in str(e) and attempt + 1 < REREAD_TRIES:
                    continue
                self.hold_here()
                self.m.land = False
                self.bridge.refuse(f"{e}; holding")
                self.say(f"new mission refused: {e}; mppid holds where the vehicle is")
                self.summary["refused"] = str(e)
                return False
        self.conv, self.m, self.current = conv, conv.mission, None
        self.summary.setdefault("reloads", 0)
        self.summary["reloads"] += 1
        self.say(f"new mission: {len(self.m.legs)} legs from item {conv.numbers[conv.leg_items[0]]}")
        return True


def wait_armed(link, say, poll_s=0.2):
    """Until the operator arms the vehicle from the ground station (disarmed, then armed)."""
    say("waiting for the vehicle to be armed from the ground station")
    seen_disarmed = False
    while True:
        armed = bool(link.bridge_status().get("armed"))
        if armed and seen_disarmed:
            say("armed from the ground station: reading the mission")
            return
        seen_disarmed = seen_disarmed or not armed
        time.sleep(poll_s)


def run(link, speed: float, seed: int, out, say, wait_for_arming=False) -> int:
    """Reads, checks and flies the autopilot's mission (ArduPilot, with NAV_GUIDED_ENABLE
    items: only its guided segments, guided_segments.py); the exit status."""
    from . import guided_segments
    if link.socket is None:
        say("from-autopilot needs the bridge (--bridge SOCKET)")
        return 2
    bridge = MissionRequests(link)
    try:
        link.wait_state()
        if wait_for_arming:
            wait_armed(link, say)
        dl = bridge.download()
        segments = guided_segments.check(dl) if guided_segments.find(dl) else None
        conv = None if segments else read_and_convert(link, bridge, speed, dl=dl)
    except ap_plan.Refusal as e:
        bridge.refuse(str(e))
        say(f"mppid refuses the mission: {e}")
        return 1
    except FlightError as e:
        say(f"mission not started: {e}")
        return 1
    if segments:
        say(f"the autopilot's mission: {len(dl['items'])} items, {len(segments)} guided segments for mppid "
            f"(NAV_GUIDED_ENABLE at items {', '.join(str(g.enable) for g in segments)}); AUTO flies the rest")
        return guided_segments.fly(link, bridge, dl, segments, speed, seed, out, say)
    say(f"the autopilot's mission: {conv.count} items, {len(conv.mission.legs)} legs"
        + (f", take-off to {conv.mission.takeoff:g} m" if conv.mission.takeoff else ""))
    summary = AutopilotRunner(conv, link, bridge, speed, seed=seed, out=out, say=say).run()
    return 0 if summary["outcome"] == "done" else 1
