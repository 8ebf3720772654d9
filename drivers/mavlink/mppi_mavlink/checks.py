"""The checks that refuse flight, and the thrust map they yield: on every link-up the
autopilot's parameters (its profile's flight check, e.g. ArduPilot's GUID_OPTIONS bit 3; the
hover thrust unless the settings give it), and all the time the rate states arrive at."""
from __future__ import annotations

import logging

from . import telemetry
from .autopilot import CommandError
from .thrust import ThrustMap

log = logging.getLogger("mppi_mavlink")
NOT_READ = "autopilot parameters not read yet"


class FlightChecks:
    def __init__(self, settings, profile):
        self.vehicle, self.telemetry, self.profile = settings["vehicle"], settings["telemetry"], profile
        vh = self.vehicle
        self.thrust = None
        self.hover_source = ""
        if vh["hover_thrust"] is not None:
            self.thrust = ThrustMap(vh["mass"], vh["gravity"], float(vh["hover_thrust"]))
            self.hover_source = "settings"
        self.param_refusal = NOT_READ
        self.rate_refusal = ""

    @property
    def refusal(self) -> str:
        """Why the bridge will not fly ('' when it may): the parameter checks, then the
        telemetry rate."""
        return self.param_refusal or self.rate_refusal

    def check_params(self, read_param) -> None:
        """On every link-up: the profile's flight check and the hover thrust (unless set in the
        settings). Sets param_refusal to the reason the bridge will not fly, or ''."""
        vh, name = self.vehicle, self.profile.hover_param
        refusal = ""
        try:
            refusal = self.profile.flight_check(read_param)
            if vh["hover_thrust"] is None:
                h = read_param(name)
                if not (0.01 <= h <= 0.99):
                    refusal = refusal or f"{name}={h} is not a usable hover-thrust fraction (0.01..0.99); refusing to fly"
                else:
                    self.thrust = ThrustMap(vh["mass"], vh["gravity"], h)
                    self.hover_source = f"param {name}"
                    log.info("hover thrust %.3f from %s: %.2f N at full thrust", h, name, self.thrust.max_thrust)
        except CommandError as e:
            refusal = f"{e}; refusing to fly (set vehicle.hover_thrust to fly without it)" if not refusal else refusal
        if refusal:
            log.error("%s", refusal)
        elif self.param_refusal:
            log.info("flight checks passed")
        self.param_refusal = refusal

    def check_state_rate(self, rate_hz: float, link_up: bool, since_link_up_s: float) -> bool:
        """The telemetry rate's verdict; True when it changed."""
        t = self.telemetry
        why = "" if not link_up else telemetry.rate_refusal(rate_hz, t["min_state_hz"], since_link_up_s, t["grace_s"])
        changed = bool(why) != bool(self.rate_refusal)
        self.rate_refusal = why  # the text follows the rate; the log and the link message the verdict
        if changed:
            if why:
                log.error("%s", why)
            else:
                log.info("telemetry: states at %.1f Hz", rate_hz)
        return changed
