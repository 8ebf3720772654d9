"""The bridge's control socket: a Unix stream socket, one request line in, one JSON line
out (`{"ok": true, "message": "armed"}`). Requests: arm, disarm, takeoff [m], offboard,
land, hold, rtl, status; for the mission tool (docs/missions.md) segment, resume SEQ,
release and mission .... A file-system socket, so it is reachable across network namespaces
and guarded by file permissions: owner only (0600), since whoever can connect can arm the
vehicle. It is created with that mode (umask 0177 around bind), so it is never open to
others, not even between bind and chmod; requests come from the bridge's own user (or
root)."""
from __future__ import annotations

import json
import logging
import os
import socket
import threading

from . import realtime

log = logging.getLogger("mppi_mavlink")


class ControlServer:
    def __init__(self, path: str, handler):
        self.path, self.handler = path, handler
        os.makedirs(os.path.dirname(os.path.abspath(path)), exist_ok=True)
        try:
            os.unlink(path)
        except FileNotFoundError:
            pass
        self.sock = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
        old_umask = os.umask(0o177)
        try:
            self.sock.bind(path)
        finally:
            os.umask(old_umask)
        os.chmod(path, 0o600)
        self.sock.listen(4)
        self.sock.settimeout(0.2)
        self.stop = threading.Event()
        self.thread = realtime.thread(self._loop, "control")

    def start(self):
        self.thread.start()

    def _loop(self):
        while not self.stop.is_set():
            try:
                conn, _ = self.sock.accept()
            except socket.timeout:
                continue
            except OSError:
                break
            with conn:
                conn.settimeout(2.0)
                try:
                    line = conn.makefile("r").readline().strip()
                    reply = self.handler(line)
                except Exception as e:  # a bad request must never take the bridge down
                    log.exception("control request")
                    reply = {"ok": False, "message": f"internal error: {e!r}"}
                try:
                    conn.sendall((json.dumps(reply) + "\n").encode())
                except OSError:
                    pass

    def close(self):
        self.stop.set()
        self.sock.close()
        self.thread.join(timeout=2)
        try:
            os.unlink(self.path)
        except FileNotFoundError:
            pass


def request(path: str, line: str, timeout: float = 30.0) -> dict:
    with socket.socket(socket.AF_UNIX, socket.SOCK_STREAM) as s:
        s.settimeout(timeout)
        s.connect(path)
        s.sendall((line.strip() + "\n").encode())
        data = s.makefile("r").readline()
    return json.loads(data)
