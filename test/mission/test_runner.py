"""The runner's reference thread: what the runner decides reaches mppid, the last step too."""
import threading
from types import SimpleNamespace

from mppi_mission import plan
from mppi_mission.runner import Runner


class _Link:
    """Records what the runner sends; a tick so slow that only the stop can publish."""
    tick_hz = 0.01

    def __init__(self):
        self.sent = []

    def send(self, ref, t0, trees):
        self.sent.append((ref, t0))

    def sampled(self):
        return None


def test_a_step_set_just_before_the_stop_is_still_published():
    """A refused mission ends with a hold set moments before the tool exits: the thread that
    publishes at the link's rate sends it once more at the stop instead of dropping it."""
    link = _Link()
    r = Runner(SimpleNamespace(name="m"), link)
    pub = threading.Thread(target=r._publisher)
    pub.start()
    hold = {"kind": "hold", "center": [2.0, 0.0, 2.0], "yaw": 0.0}
    r._set(plan.Step(-1, "hold", hold, None), 123)
    r.stop.set()
    pub.join(5)
    assert not pub.is_alive()
    assert link.sent == [(hold, 123)]
