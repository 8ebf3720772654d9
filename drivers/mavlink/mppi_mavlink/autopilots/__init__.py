"""Autopilot profiles (base.py): one file per autopilot, each defining `PROFILE`; the
settings' `mavlink.dialect` names the file."""
from __future__ import annotations

import importlib
import pkgutil

from .base import AutopilotProfile, mavlink


def available() -> list[str]:
    """The dialects there is a profile for (px4.py -> "px4")."""
    return sorted(m.name for m in pkgutil.iter_modules(__path__) if m.name != "base")


def load(dialect: str) -> AutopilotProfile:
    if dialect not in available():
        raise ValueError(f"no autopilot profile {dialect!r} (have: {', '.join(available())})")
    return importlib.import_module(f".{dialect}", __name__).PROFILE


def decode_param(msg, autopilot: int) -> float:
    """PARAM_VALUE's value as the autopilot that sent it (its HEARTBEAT's MAV_AUTOPILOT_*)
    encodes it; a number cast to float for one without a profile."""
    for name in available():
        p = load(name)
        if p.mav_autopilot == autopilot:
            return p.decode_param(msg)
    return float(msg.param_value)
