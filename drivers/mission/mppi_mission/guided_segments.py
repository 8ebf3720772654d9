"""ArduCopter's own hand-off inside an AUTO mission (docs/missions.md, "Guided segments"):
the operator's mission runs in AUTO; a MAV_CMD_NAV_GUIDED_ENABLE item with param1 1 hands the
items after it to mppid, up to a NAV_GUIDED_ENABLE with param1 0 (or the mission's end).

As ArduCopter 4.5/4.6 runs it (mode_auto.cpp): reaching the NAV_GUIDED_ENABLE item, AUTO
enters its guided sub-mode, holding where it is and taking a companion's attitude targets;
the item is over when a guided limit (MAV_CMD_DO_GUIDED_LIMITS: time, altitude, distance
from where it started) is passed, or when the companion sets another current item. Targets
stopping for GUID_TIMEOUT s level the vehicle and hold its altitude, drifting.

So mppid: checks every segment before anything (the items in it as autopilot_plan.py flies
them; a landing or a return inside one refused: AUTO lands once the segment is over); waits
for AUTO to make a NAV_GUIDED_ENABLE item current; engages there without a mode change (the
bridge's `segment`); flies the segment's items, showing each (STATUSTEXT, MISSION_ITEM_REACHED;
the autopilot's current item stays the NAV_GUIDED_ENABLE, as ArduCopter needs); then hands
back: the bridge's `resume SEQ` (forwarding stopped, MISSION_SET_CURRENT to the item that ends
the segment; AUTO goes on by itself), or at the mission's end BRAKE (`hold`). A guided limit
passed while mppid flies: AUTO has gone on, mppid lets go (`release`). mppid's stream lost: the
bridge stops forwarding and leaves the vehicle in AUTO (GUID_TIMEOUT, then the limits, as the
operator set them). The operator's mode switch ends it at once, as in a whole mission.
"""
from __future__ import annotations

import math
import time
from dataclasses import dataclass
from pathlib import Path

from pymavlink import mavutil

from . import autopilot_plan as ap_plan
from .from_autopilot import AutopilotRunner

mavlink = mavutil.mavlink
GUIDED_ENABLE = mavlink.MAV_CMD_NAV_GUIDED_ENABLE
POLL_S = 0.1


@dataclass
class Segment:
    enable: int     # the NAV_GUIDED_ENABLE (param1 1) item's seq
    end: int        # the seq that ends it: a NAV_GUIDED_ENABLE param1 0, or the item count


def find(dl: dict) -> list[Segment]:
    """The mission's guided segments, in order (a second param1 1 ends the one before)."""
    segs, start = [], None
    for it in dl["items"]:
        if it["command"] != GUIDED_ENABLE:
            continue
        if start is not None:
            segs.append(Segment(start, it["seq"]))
        start = it["seq"] if it["param1"] > 0.5 else None
    if start is not None:
        segs.append(Segment(start, len(dl["items"])))
    return segs


def convert(dl: dict, seg: Segment, here, heading_deg=None, speed: float = 2.0) -> ap_plan.Converted:
    """The segment's plan, flown in the air from `here`; Refusal naming the item."""
    if seg.end == seg.enable + 1:
        raise ap_plan.Refusal(seg.enable, "NAV_GUIDED_ENABLE with no item after it for mppid to fly")
    conv = ap_plan.convert(dl, here, heading_deg, True, speed, start_seq=seg.enable + 1, end_seq=seg.end)
    if conv.mission.land:
        seq = conv.leg_items[-1]
        raise ap_plan.Refusal(conv.numbers[seq], f"{conv.names[seq]} inside a guided segment: end the segment "
                                                 f"(NAV_GUIDED_ENABLE 0) before it, and AUTO flies it")
    return conv


def check(dl: dict) -> list[Segment]:
    """Every segment converted from home before anything is flown (Refusal naming the item)."""
    if dl["dialect"] != "ardupilot":
        raise ap_plan.Refusal(None, "NAV_GUIDED_ENABLE segments are ArduPilot's: PX4 has no such item")
    segs = find(dl)
    if dl.get("origin") is None or dl.get("home") is None:
        raise ap_plan.Refusal(None, "the autopilot has no home or origin yet (no position fix)")
    home = ap_plan._Frame(dl["origin"], dl["home"]).home
    for seg in segs:
        convert(dl, seg, home)
    return segs


class SegmentRunner(AutopilotRunner):
    """One segment: engaged with `segment`, items shown without moving the autopilot's
    current item, handed back at the end."""

    def __init__(self, conv, link, bridge, speed, seg: Segment, **kw):
        super().__init__(conv, link, bridge, speed, **kw)
        self.seg = seg
        self.start_kw = {"engage": "segment"}
        self.summary["segment"] = seg.enable

    def _show_item(self, seq, text):
        self.bridge.ask(f"mission say {text}")

    def _finished(self) -> str:
        if self.seg.end < self.conv.count:
            r = self.bridge.ask(f"resume {self.seg.end}")
            self.say(r.get("message", ""))
            return "done" if r.get("ok") else f"hand-back failed: {r.get('message')}"
        self.bridge.ask("mission say mppid: guided segment done, the mission's end: BRAKE")
        self.say(self.bridge.ask("hold").get("message", ""))
        return "done"

    def interrupted(self) -> str:
        why = super().interrupted()
        if why:
            return why
        current = self.bridge.ask("mission status").get("mission_status", {}).get("current")
        if current != self.seg.enable:
            return f"the autopilot ended the segment (item {current} current: a guided limit, or the ground station)"
        return ""

    def _stopped(self, seq) -> str:
        why = self.summary["legs"][-1].get("why", "")
        if why.startswith("the autopilot ended the segment"):
            self.bridge.ask("release")
            self.bridge.ask(f"mission say mppid: {why}")
            return f"stopped at item {self.conv.numbers[seq]}: {why}"
        return super()._stopped(seq)

    def _reload(self, here) -> bool:
        """A mission changed in a segment: mppid holds where the vehicle is, the tool ends."""
        self.hold_here()
        self.summary["refused"] = "the mission changed during a guided segment"
        self.bridge.refuse("the mission changed during a guided segment; holding")
        return False


def wait_segment(link, bridge, seg: Segment, say) -> str:
    """Until AUTO makes the segment's NAV_GUIDED_ENABLE current ('' then), or why it never will."""
    say(f"waiting for AUTO to reach item {seg.enable} (NAV_GUIDED_ENABLE)")
    was_armed = False
    while True:
        st = link.bridge_status()
        ms = bridge.ask("mission status").get("mission_status", {})
        armed, current = bool(st.get("armed")), ms.get("current")
        if ms.get("changed"):
            return f"the mission changed: {ms['changed']}"
        if st.get("mode") == "AUTO" and current == seg.enable:
            return ""
        if st.get("mode") == "AUTO" and current is not None and current > seg.enable:
            return f"AUTO is past item {seg.enable} (item {current} current)"
        if was_armed and not armed:
            return "the vehicle disarmed"
        was_armed = was_armed or armed
        time.sleep(POLL_S)


def fly(link, bridge, dl, segs, speed, seed, out, say) -> int:
    """Each segment in turn; the exit status (0: every segment flown and handed back)."""
    for seg in segs:
        why = wait_segment(link, bridge, seg, say)
        if why:
            say(f"guided segment at item {seg.enable} not flown: {why}")
            return 1
        h = link.heading()
        try:
            conv = convert(dl, seg, link.position(), None if h is None else math.degrees(h), speed)
        except ap_plan.Refusal as e:
            bridge.refuse(str(e))
            say(f"mppid refuses the segment: {e}; AUTO holds in its guided sub-mode until its limits")
            return 1
        sub = Path(out) / f"segment_{seg.enable}" if out else None
        if sub:
            sub.mkdir(parents=True, exist_ok=True)
        say(f"guided segment at item {seg.enable}: {len(conv.mission.legs)} legs, back to AUTO at item {seg.end}")
        summary = SegmentRunner(conv, link, bridge, speed, seg, seed=seed, out=sub, say=say).run()
        if summary["outcome"] != "done":
            return 1
    return 0
