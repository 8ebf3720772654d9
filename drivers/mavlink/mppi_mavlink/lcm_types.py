"""LCM message types for the bridge.

Both packages come from the distribution mppid-lcm-types (lcmtypes/), generated from the
.lcm files when it is built: mppi_lcm (mppid's messages) and mppi_mavlink_lcm (the bridge's
link status, mavlink_link_t). tools/setup.sh installs it into .venv; elsewhere
`pip install ./lcmtypes`.
"""
from __future__ import annotations

from types import ModuleType

_MISSING = "{}: not installed (mppid-lcm-types: tools/setup.sh, or pip install ./lcmtypes)"


def import_mppi_lcm() -> ModuleType:
    try:
        import mppi_lcm
    except ModuleNotFoundError as e:
        raise ModuleNotFoundError(_MISSING.format("mppi_lcm"), name=e.name) from e
    return mppi_lcm


def import_link_type() -> type:
    """mppi_mavlink_lcm.mavlink_link_t."""
    try:
        from mppi_mavlink_lcm import mavlink_link_t
    except ModuleNotFoundError as e:
        raise ModuleNotFoundError(_MISSING.format("mppi_mavlink_lcm"), name=e.name) from e
    return mavlink_link_t
