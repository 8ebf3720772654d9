"""The MAVLink connection to the autopilot: open (signed or not), re-open a lost serial or
TCP link, send under one lock (pymavlink's encoder is not thread-safe), and the receive
loop that hands every message to one handler. What the messages mean is not its business."""
from __future__ import annotations

import logging
import os
import threading
import time

os.environ.setdefault("MAVLINK20", "1")  # ODOMETRY and the SET_ATTITUDE_TARGET extensions
from pymavlink import mavutil  # noqa: E402

from . import signing  # noqa: E402

log = logging.getLogger("mppi_mavlink")
DATAGRAM_SCHEMES = ("udpin:", "udp:", "udpout:", "udpbcast:")


class Link:
    def __init__(self, mavlink_settings, dialect: str):
        self.m = mavlink_settings
        self.dialect = dialect
        # MAVLink 2 signing (signing.py): the key is read, and its file's permissions
        # checked, before anything is opened; SigningError says what is wrong.
        self.signing_key = signing.load_key(self.m["signing_key_file"]) if self.m["signing_key_file"] else None
        self.signing_dropped = {"rejected_unsigned": 0, "rejected_bad_signature": 0}  # of closed connections
        self.send_lock = threading.Lock()
        self.mav = None
        self.conn_gen = 0

    def open(self):
        m = self.m
        conn = mavutil.mavlink_connection(m["url"], baud=m["baud"], source_system=m["system_id"],
                                          source_component=m["component_id"],
                                          autoreconnect=False, robust_parsing=True)
        if self.signing_key is not None:
            signing.install(conn.mav, self.signing_key, m["signing_link_id"])
        old = self.mav
        if old is not None and self.signing_key is not None:
            for k, v in signing.counters(old.mav).items():
                self.signing_dropped[k] += v
        self.mav = conn
        self.conn_gen += 1
        log.info("MAVLink connection %s open (%s dialect, %s)", m["url"], self.dialect,
                 "signed" if self.signing_key is not None else "unsigned")

    def reopen(self):
        url = self.m["url"]
        if self.mav is not None and url.startswith(DATAGRAM_SCHEMES):
            return  # a datagram socket stays valid; the autopilot simply talks again
        try:
            old = self.mav
            self.open()
            if old is not None:
                try:
                    old.close()
                except Exception:
                    pass
        except Exception as e:
            log.warning("reconnect to %s failed: %s", url, e)

    def send(self, fn) -> bool:
        """fn(the pymavlink encoder): True when it went out."""
        with self.send_lock:
            if self.mav is None:
                return False
            try:
                fn(self.mav.mav)
                return True
            except OSError as e:
                log.debug("send failed: %s", e)
                return False

    def receive_loop(self, stop: threading.Event, handle):
        while not stop.is_set():
            mav = self.mav
            if mav is None:
                time.sleep(0.05)
                continue
            try:
                msg = mav.recv_match(blocking=True, timeout=0.1)
            except (OSError, ValueError) as e:
                log.debug("receive failed: %s", e)
                time.sleep(0.05)
                continue
            if msg is None:
                continue
            try:
                handle(msg)
            except Exception:
                log.exception("handling %s", msg.get_type())

    def signing_counters(self) -> dict:
        """Messages the signature check dropped, since start (0 on an unsigned link)."""
        out = dict(self.signing_dropped)
        mav = self.mav
        if mav is not None and self.signing_key is not None:
            for k, v in signing.counters(mav.mav).items():
                out[k] += v
        return out

    def close(self):
        if self.mav is not None:
            try:
                self.mav.close()
            except Exception:
                pass
