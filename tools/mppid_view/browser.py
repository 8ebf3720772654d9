"""Headless chromium (Debian's) driven over the DevTools protocol: load a page, take
screenshots. WebGL runs on SwiftShader (no GPU needed), which rerun's viewer accepts."""
from __future__ import annotations

import base64
import json
import os
import shutil
import signal
import socket
import subprocess
import tempfile
import time
import urllib.request

import websocket


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


class HeadlessChromium:
    def __init__(self, width: int = 1280, height: int = 800, binary: str = "chromium", niceness: int = 0):
        """niceness: added to the browser's (a test's browser yields to the flight and the view)."""
        exe = shutil.which(binary)
        if exe is None:
            raise FileNotFoundError(f"{binary} not found (Debian package chromium; tools/setup.sh installs it)")
        self.profile = tempfile.TemporaryDirectory(prefix="mppid-chromium-")
        self.port = free_port()
        self.proc = subprocess.Popen(
            [exe, "--headless=new", "--no-sandbox", "--use-angle=swiftshader", "--enable-unsafe-swiftshader",
             "--no-first-run", "--disable-background-networking", "--disable-component-update",
             f"--remote-debugging-port={self.port}", f"--window-size={width},{height}",
             f"--user-data-dir={self.profile.name}", "about:blank"],
            stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, start_new_session=True,
            preexec_fn=(lambda: os.nice(niceness)) if niceness else None)
        self.ws = None
        self.next_id = 0

    def _new_page(self, url: str, timeout: float = 30.0) -> str:
        """A new tab on url (DevTools' /json/new): the start-up tab may still be replaced."""
        end = time.monotonic() + timeout
        while True:
            try:
                req = urllib.request.Request(f"http://127.0.0.1:{self.port}/json/new?{url}", method="PUT")
                with urllib.request.urlopen(req, timeout=5) as r:
                    return json.load(r)["webSocketDebuggerUrl"]
            except OSError:
                pass
            if self.proc.poll() is not None or time.monotonic() > end:
                raise RuntimeError(f"chromium's DevTools did not come up on port {self.port}")
            time.sleep(0.2)

    def call(self, method: str, **params) -> dict:
        self.next_id += 1
        self.ws.send(json.dumps({"id": self.next_id, "method": method, "params": params}))
        while True:
            reply = json.loads(self.ws.recv())
            if reply.get("id") == self.next_id:
                if "error" in reply:
                    raise RuntimeError(f"{method}: {reply['error']}")
                return reply.get("result", {})

    def open(self, url: str) -> None:
        if self.ws is not None:
            self.ws.close()
        self.ws = websocket.create_connection(self._new_page(url), timeout=60)

    def screenshot(self) -> bytes:
        return base64.b64decode(self.call("Page.captureScreenshot", format="png")["data"])

    def close(self) -> None:
        try:
            if self.ws is not None:
                self.ws.close()
        finally:
            # chromium's own process group (start_new_session): the browser and its helpers.
            os.killpg(self.proc.pid, signal.SIGTERM)
            try:
                self.proc.wait(timeout=10)
            except subprocess.TimeoutExpired:
                os.killpg(self.proc.pid, signal.SIGKILL)
                self.proc.wait()
            self.profile.cleanup()

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()
