"""The identification manoeuvre asked for through the bridge (`mppid-mavlink-bridge identify`,
docs/sysid.md): refused unless mppid flies the vehicle; then mppid adds its doublets and
thrust steps to the setpoints the autopilot gets, and the vehicle holds its box."""
import pytest

from mavtest import wait_for
from mavchain import MPPID_SETS, Chain

pytestmark = pytest.mark.timeout(120)


def test_identify_through_the_bridge(netns, procs, tmp_path):
    # One repeat of the sequence (5.2 s), to keep the test short.
    c = Chain(procs, tmp_path, world="hold", task="quadrotor_rate_track",
              mppid_sets=MPPID_SETS + ("daemon.identification.repeats=1",)).start()
    r = c.ctl("identify")
    assert not r["ok"] and "not flying the vehicle" in r["message"], r
    c.ok("offboard")
    # Engaging asks mppid to forget what it learnt from setpoints that were not flown.
    wait_for(lambda: "daemon.restart_estimates = 1 applied" in c.procs.log("mppid"), 5,
             "mppid to restart its estimates on offboard\n--- mppid log\n" + c.procs.log("mppid")[-2000:])
    c.ok("arm")
    c.wait_event("mission_done", 30)  # up at the hold point
    n0 = len(c.setpoints())
    assert "started" in c.ok("identify")
    wait_for(lambda: "identification manoeuvre done" in c.procs.log("mppid"), 15,
             "mppid to fly the manoeuvre\n--- mppid log\n" + c.procs.log("mppid")[-2000:])
    window = c.setpoints()[n0:]
    roll = [abs(p["rates"][0]) for p in window if p["finite"]]
    # The largest roll-rate doublet is 0.6 x 1.2 rad/s on top of what mppid asks for.
    assert max(roll) > 0.6, f"largest roll rate on the wire {max(roll):.2f} rad/s"
    s = c.land_and_finish()
    assert not [e for e in s["events"] if e["event"] == "collision"]
    assert s["counters"]["nonfinite_rejected"] == 0
