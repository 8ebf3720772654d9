"""The view's layout, shipped with the live view and inside every .rrd: the 3D scene on the
left, the timing plots on the right (compute, state -> command, misses, effective sample size)."""
from __future__ import annotations

import rerun.blueprint as rrb


def blueprint() -> rrb.Blueprint:
    plots = rrb.Vertical(
        rrb.TimeSeriesView(name="compute and state -> command [ms]", origin="/timing",
                           contents=["/timing/compute_ms", "/timing/state_to_command_ms"]),
        rrb.TimeSeriesView(name="deadline misses", origin="/timing", contents=["/timing/misses"]),
        rrb.TimeSeriesView(name="effective sample size", origin="/optimizer", contents=["/optimizer/ess"]),
    )
    scene = rrb.Spatial3DView(name="mppid", origin="/world")
    return rrb.Blueprint(rrb.Horizontal(scene, plots, column_shares=[3, 1]), collapse_panels=True)
