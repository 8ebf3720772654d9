"""Engagement transitions (mppi_mavlink/engagement.py) from a table: a start (PX4's pre-stream
or ArduPilot's wait for `offboard`), a sequence of events, the state and reason it must end
in; every change logged and reported once through on_change. Pure: no process, no network."""
import logging
import threading

import pytest

from mppi_mavlink.autopilot import CommandError
from mppi_mavlink.engagement import DISENGAGED, ENGAGED, PRESTREAM, Engagement

GUIDED, LOITER, OFFBOARD = 4, 5, 6 << 16
TAKING_OFF = (3, 1)  # MAV_LANDED_STATE_TAKEOFF, _ON_GROUND


def run(e, events):
    for ev in events:
        name, *args = ev
        getattr(e, name)(*args)


ROWS = [
    # (what, pre-streamed, events, state, why)
    ("PX4 starts pre-streamed", True, [], PRESTREAM, ""),
    ("ArduPilot waits for offboard", False, [], DISENGAGED, "waiting for `offboard`"),
    ("offboard engages", False, [("engage", GUIDED, "GUIDED")], ENGAGED, ""),
    ("PX4 offboard engages", True, [("prestream", "offboard requested"), ("engage", OFFBOARD, "OFFBOARD")],
     ENGAGED, ""),
    ("land disengages", False, [("engage", GUIDED, "GUIDED"), ("disengage", "land requested")], DISENGAGED,
     "land requested"),
    ("someone else's mode change disengages", False,
     [("engage", GUIDED, "GUIDED"), ("watch", LOITER, "LOITER", True, True, False, True)], DISENGAGED,
     "mode changed to LOITER by someone else"),
    ("a disarm disengages", False,
     [("engage", GUIDED, "GUIDED"), ("watch", GUIDED, "GUIDED", False, True, True, True)],
     DISENGAGED, "the autopilot disarmed"),
    ("the same mode keeps it", False,
     [("engage", GUIDED, "GUIDED"), ("watch", GUIDED, "GUIDED", True, True, True, True)], ENGAGED, ""),
    ("a mode change before offboard changes nothing", True, [("watch", LOITER, "LOITER", True, True, False, False)],
     PRESTREAM, ""),
    ("a mode change while disengaged keeps the reason", False,
     [("disengage", "hold requested"), ("watch", GUIDED, "GUIDED", True, True, True, False)], DISENGAGED,
     "hold requested"),
    # One rule before and after a disengage (issue 29 4b): PX4 pre-streams whenever the
    # vehicle is out of OFFBOARD, so the operator's own switch engages, before and after.
    ("PX4: the operator's switch into OFFBOARD engages", True,
     [("watch", OFFBOARD, "OFFBOARD", True, True, True, False)], ENGAGED, ""),
    ("PX4: pre-streamed again once out of OFFBOARD after a disengage", True,
     [("engage", OFFBOARD, "OFFBOARD"), ("watch", LOITER, "LOITER", True, True, False, True),
      ("watch", LOITER, "LOITER", True, True, False, False)], PRESTREAM, ""),
    ("PX4: ... and the switch engages again", True,
     [("engage", OFFBOARD, "OFFBOARD"), ("watch", LOITER, "LOITER", True, True, False, True),
      ("watch", LOITER, "LOITER", True, True, False, False), ("watch", OFFBOARD, "OFFBOARD", True, True, True, False)],
     ENGAGED, ""),
    ("PX4: disengaged while still in OFFBOARD stays so", True,
     [("engage", OFFBOARD, "OFFBOARD"), ("disengage", "mppid's setpoints stopped"),
      ("watch", OFFBOARD, "OFFBOARD", True, True, True, True)], DISENGAGED, "mppid's setpoints stopped"),
    ("PX4: found in OFFBOARD at the first HEARTBEAT: nothing", True,
     [("watch", OFFBOARD, "OFFBOARD", True, None, True, None)], DISENGAGED,
     "the vehicle is in OFFBOARD, not switched there while the bridge watched"),
    ("PX4: the bridge's own `offboard` engages, not the HEARTBEAT", True,
     [("expect_offboard", True), ("watch", OFFBOARD, "OFFBOARD", True, True, True, False)], PRESTREAM, ""),
    ("ArduPilot: GUIDED entered by someone else engages nothing", False,
     [("watch", GUIDED, "GUIDED", True, True, True, False)], DISENGAGED, "waiting for `offboard`"),
    ("PX4 offboard after a disengage pre-streams again", True,
     [("engage", OFFBOARD, "OFFBOARD"), ("disengage", "hold requested"), ("prestream", "offboard requested")],
     PRESTREAM, ""),
    ("prestream never demotes an engagement", True,
     [("engage", OFFBOARD, "OFFBOARD"), ("prestream", "offboard requested")], ENGAGED, ""),
    ("the latest reason is kept", False, [("disengage", "a"), ("disengage", "b")], DISENGAGED, "b"),
]


@pytest.mark.parametrize("what,pre,events,state,why", ROWS, ids=[r[0] for r in ROWS])
def test_transition(what, pre, events, state, why):
    changes = []
    e = Engagement(pre, lambda why, changed: changes.append(changed))
    run(e, events)
    s = e.snapshot()
    assert (s.state, s.why) == (state, why)
    assert s.forwarding == (state != DISENGAGED) == e.forwarding
    # every state change is in the record, in order, and was reported
    states = [PRESTREAM if pre else DISENGAGED] + [to for _, _, to, _ in e.transitions]
    assert states[-1] == state and all(a != b for a, b in zip(states, states[1:]))
    assert changes.count(True) == len(e.transitions)


def test_every_change_is_logged(caplog):
    caplog.set_level(logging.INFO, logger="mppi_mavlink")
    e = Engagement(False)
    e.engage(GUIDED, "GUIDED")
    e.watch(LOITER, "LOITER", True, True, False, True)
    text = caplog.text
    assert "disengaged -> engaged" in text and "engaged -> disengaged (mode changed to LOITER" in text
    assert "forwarding stopped: mode changed to LOITER by someone else" in text


def test_takeoff_wait_ends_with_the_takeoff():
    e = Engagement(False)
    e.takeoff_started()
    assert e.snapshot().takeoff_in_progress
    e.on_landed_state(3, TAKING_OFF)          # still taking off
    assert e.snapshot().takeoff_in_progress
    t = threading.Timer(0.05, e.on_landed_state, (2, TAKING_OFF))  # IN_AIR
    t.start()
    e.wait_takeoff_done(5.0)
    t.join()
    assert not e.snapshot().takeoff_in_progress


def test_takeoff_wait_times_out_and_a_disengage_ends_it():
    e = Engagement(False)
    e.takeoff_started()
    with pytest.raises(CommandError, match="take-off is not complete"):
        e.wait_takeoff_done(0.0)
    e.disengage("land requested")
    assert not e.snapshot().takeoff_in_progress
    e.wait_takeoff_done(0.0)  # no take-off: no wait


def test_concurrent_changes_end_in_a_state_the_record_agrees_with():
    e = Engagement(True)

    def churn(i):
        for k in range(200):
            if (i + k) % 3 == 0:
                e.engage(OFFBOARD, "OFFBOARD")
            elif (i + k) % 3 == 1:
                e.disengage(f"t{i}")
            else:
                e.prestream("offboard requested")
    ts = [threading.Thread(target=churn, args=(i,)) for i in range(4)]
    for t in ts:
        t.start()
    for t in ts:
        t.join()
    recs = list(e.transitions)
    assert recs[-1][2] == e.snapshot().state
    assert all(a[2] == b[1] for a, b in zip(recs, recs[1:]))  # each starts where the last ended
