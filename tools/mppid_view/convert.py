"""An LCM flight log (lcm-logger's format: tools/record, the harness's flight.lcmlog) into a
rerun .rrd file with the view's layout, through the same Scene as the live view."""
from __future__ import annotations

from collections import Counter
from pathlib import Path

import lcm
import rerun as rr

from .blueprint import blueprint
from .scene import Scene, lcm_types


def convert(log_path: Path, rrd_path: Path, name: str | None = None) -> Counter:
    """Writes rrd_path; returns {channel: messages drawn}. Undecodable messages are skipped
    and counted under "<channel>:undecodable"."""
    types = lcm_types()
    rec = rr.RecordingStream("mppid", recording_id=name or Path(log_path).stem)
    rec.save(str(rrd_path), default_blueprint=blueprint())
    scene = Scene(rec)
    counts: Counter = Counter()
    log = lcm.EventLog(str(log_path), "r")
    try:
        for ev in log:
            t = types.get(ev.channel)
            if t is None:
                continue
            try:
                msg = t.decode(ev.data)
            except ValueError:
                counts[ev.channel + ":undecodable"] += 1
                continue
            if scene.log(ev.channel, msg):
                counts[ev.channel] += 1
    finally:
        log.close()
        rec.flush()
        rec.disconnect()
    return counts
