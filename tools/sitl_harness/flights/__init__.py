"""One flight class per plant, registered here by autopilot name (`--autopilot`): adding a
plant (PX4 SITL, say) is adding its file and one line below. A plant's module is imported
only when it is flown."""
from __future__ import annotations

import importlib

# --autopilot NAME -> "module:class" of its flight (a subclass of flights.base.Flight).
PLANTS = {
    "sim": "sitl_harness.flights.sim:SimFlight",             # mppid-sim (config/scenarios)
    "ardupilot": "sitl_harness.flights.ardupilot:ArduPilotFlight",  # ArduCopter SITL (config/missions)
    "px4": "sitl_harness.flights.px4:Px4Flight",             # PX4 SITL with SIH (config/missions)
}


def flight_class(autopilot: str):
    """The flight class of a plant; KeyError names the known ones."""
    try:
        module, cls = PLANTS[autopilot].split(":")
    except KeyError:
        raise KeyError(f"no flight for autopilot {autopilot!r} (known: {', '.join(PLANTS)})") from None
    return getattr(importlib.import_module(module), cls)


def flight_for(spec):
    """The flight of `spec` (its plant's class); raises FlightError when it cannot be flown here."""
    return flight_class(spec.autopilot).create(spec)
