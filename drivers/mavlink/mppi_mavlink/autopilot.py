"""The autopilot as the bridge sees it (its HEARTBEAT: system, mode, armed; battery; the
landed state; COMMAND_ACKs, PARAM_VALUEs and STATUSTEXTs) and the requests the bridge makes
of it (COMMAND_LONG with retries, PARAM_REQUEST_READ, PARAM_SET, a mode confirmed by the
HEARTBEAT). One condition guards what the receive thread writes and the requests wait for."""
from __future__ import annotations

import logging
import time

from . import autopilots
from .autopilots.base import mavlink, mavutil

log = logging.getLogger("mppi_mavlink")


class CommandError(RuntimeError):
    pass


def _text(v) -> str:
    return (v if isinstance(v, str) else v.decode(errors="replace")).rstrip("\x00")


class Autopilot:
    def __init__(self, mavlink_settings, link, profile, cond):
        self.m, self.link, self.profile = mavlink_settings, link, profile
        self.cond = cond
        self.target_system = 0
        self.autopilot_type = profile.mav_autopilot
        self.last_hb_mono = None
        self.hb_period = 1.0      # the autopilot's HEARTBEAT interval, measured (PX4, ArduPilot: 1 s)
        self.link_up = False
        self.link_losses = 0
        self.armed = False
        self.custom_mode = None
        self.base_mode = 0
        self.mode = "unknown"
        self.battery_voltage = -1.0
        self.battery_remaining = -1
        self.landed_state = None
        self.acks = {}
        self.params = {}
        self.statustexts = []

    # ---- what it tells us (receive thread) ----------------------------------------------
    def on_heartbeat(self, msg):
        """The autopilot's HEARTBEAT: (armed, custom mode) before it, or None (not the autopilot's)."""
        src = msg.get_srcSystem()
        if msg.autopilot == mavlink.MAV_AUTOPILOT_INVALID or msg.type in (
                mavlink.MAV_TYPE_GCS, mavlink.MAV_TYPE_ONBOARD_CONTROLLER):
            return None  # ground stations, companions (ourselves through a router)
        if self.target_system and src != self.target_system:
            return None
        with self.cond:
            if not self.target_system:
                self.target_system = src
                log.info("autopilot found: system %d, autopilot type %d", src, msg.autopilot)
            self.autopilot_type = msg.autopilot
            now = time.monotonic()
            if self.last_hb_mono is not None and now - self.last_hb_mono < 5.0:
                self.hb_period += 0.2 * (min(now - self.last_hb_mono, 2.0) - self.hb_period)
            self.last_hb_mono = now
            before = (self.armed, self.custom_mode)
            self.armed = bool(msg.base_mode & mavlink.MAV_MODE_FLAG_SAFETY_ARMED)
            self.base_mode, self.custom_mode = msg.base_mode, msg.custom_mode
            self.mode = mavutil.mode_string_v10(msg)
            self.cond.notify_all()
        return before

    def from_target(self, msg) -> bool:
        return not self.target_system or msg.get_srcSystem() == self.target_system

    def on_message(self, t: str, msg) -> None:
        """SYS_STATUS, EXTENDED_SYS_STATE, COMMAND_ACK, PARAM_VALUE, STATUSTEXT."""
        if t == "SYS_STATUS":
            self.battery_voltage = msg.voltage_battery / 1000.0 if msg.voltage_battery != 65535 else -1.0
            self.battery_remaining = msg.battery_remaining
            return
        if t == "STATUSTEXT":
            text = _text(msg.text)
            log.info("autopilot: %s", text)
        with self.cond:
            if t == "EXTENDED_SYS_STATE":
                self.landed_state = msg.landed_state
            elif t == "COMMAND_ACK":
                self.acks[msg.command] = msg.result
            elif t == "PARAM_VALUE":
                self.params[_text(msg.param_id)] = autopilots.decode_param(msg, self.autopilot_type)
            elif t == "STATUSTEXT":
                self.statustexts = [(tt, x) for tt, x in self.statustexts if time.monotonic() - tt < 2.0]
                self.statustexts.append((time.monotonic(), text))
                return
            self.cond.notify_all()

    def heartbeat_age(self):
        hb = self.last_hb_mono
        return None if hb is None else time.monotonic() - hb

    # ---- requests (control socket and link-up threads) ----------------------------------
    def read_param(self, name: str) -> float:
        m = self.m
        for _ in range(int(m["param_retries"])):
            with self.cond:
                self.params.pop(name, None)
            self.link.send(lambda mv: mv.param_request_read_send(self.target_system, m["target_component"],
                                                                 name.encode(), -1))
            deadline = time.monotonic() + m["param_timeout_s"]
            with self.cond:
                while name not in self.params and time.monotonic() < deadline:
                    self.cond.wait(deadline - time.monotonic())
                if name in self.params:
                    return self.params[name]
        raise CommandError(f"parameter {name}: no PARAM_VALUE after {m['param_retries']} requests")

    def param_set(self, name: str, value: float) -> None:
        self.link.send(lambda mv: mv.param_set_send(self.target_system, self.m["target_component"], name.encode(),
                                                    value, mavlink.MAV_PARAM_TYPE_REAL32))

    def command_long(self, command: int, params, name: str) -> None:
        m = self.m
        if not self.link_up:
            raise CommandError(f"{name}: link to the autopilot is down")
        for attempt in range(int(m["command_retries"])):
            with self.cond:
                self.acks.pop(command, None)
            p = list(params) + [0.0] * (7 - len(params))
            self.link.send(lambda mv: mv.command_long_send(self.target_system, m["target_component"], command,
                                                           attempt, *p))
            deadline = time.monotonic() + m["command_timeout_s"]
            with self.cond:
                while command not in self.acks and time.monotonic() < deadline:
                    self.cond.wait(deadline - time.monotonic())
                result = self.acks.get(command)
            if result is None or result == mavlink.MAV_RESULT_IN_PROGRESS:
                continue
            if result == mavlink.MAV_RESULT_ACCEPTED:
                return
            raise CommandError(f"{name}: autopilot answered {self._refusal_text(result)}")
        raise CommandError(f"{name}: no COMMAND_ACK after {m['command_retries']} attempts "
                           f"of {m['command_timeout_s']} s")

    def _refusal_text(self, result: int) -> str:
        rname = mavlink.enums["MAV_RESULT"][result].name if result in mavlink.enums["MAV_RESULT"] else str(result)
        time.sleep(0.05)  # the STATUSTEXT saying why comes right after the ACK
        with self.cond:
            why = "; ".join(x for tt, x in self.statustexts if time.monotonic() - tt < 1.0)
        return rname + (f" ({why})" if why else "")

    def wait_mode(self, predicate, what: str) -> None:
        deadline = time.monotonic() + self.m["mode_confirm_timeout_s"]
        with self.cond:
            while not predicate() and time.monotonic() < deadline:
                self.cond.wait(max(0.0, deadline - time.monotonic()))
            if not predicate():
                raise CommandError(f"{what}: accepted, but the autopilot's HEARTBEAT still reports {self.mode}")
