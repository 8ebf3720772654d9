"""The live 3D view of a flight (`tools/sitl run --view`, docs/view.md): tools/view live in
the host's network namespace, so the browser reaches its servers, reading the flight's LCM
bus from inside the flight's namespace (--netns-pid). Its own process group: the flight's
killpg must not end it before view_hold."""
from __future__ import annotations

import signal
import subprocess
import sys
import time

from .. import paths
from ..sandbox import Sandbox, SandboxError
from .base import LOGGER_RECV_BUF, FlightSpec, sensor_bus

VIEW_READY_TIMEOUT_S = 60.0    # the view imports rerun and starts its servers (seconds under load)
VIEW_GRPC_OFFSET = 786         # 9090 -> 9876, rerun's default pair
VIEW_ROLLOUTS = ["daemon.rollouts.hz=5", "daemon.rollouts.top=16", "daemon.rollouts.random=16"]


def view_sets(spec: FlightSpec) -> list[str]:
    """The live view's rollout fan, unless the flight sets its own daemon.rollouts."""
    return VIEW_ROLLOUTS if spec.view and not any("daemon.rollouts." in str(s) for s in spec.sets) else []


class FlightView:
    def __init__(self, spec: FlightSpec, sandbox: Sandbox):
        self.spec = spec
        self.sandbox = sandbox
        self.proc: subprocess.Popen | None = None

    def start(self):
        """Starts the view, prints its URL, waits view_wait seconds; raises SandboxError."""
        spec, out = self.spec, self.sandbox.out
        # The logger's receive buffer: a lock-step flight bursts faster than a normal-policy
        # reader drains. What the view still drops shows live only: flight.rrd is converted
        # from the complete log after the flight (fly()).
        cmd = [sys.executable, "-m", "mppid_view", "live", "--lcm-url",
               f"{spec.lcm_url}&recv_buf_size={LOGGER_RECV_BUF}", "--sensor-lcm-url", sensor_bus(spec.lcm_url),
               "--netns-pid", str(self.sandbox.holder.pid),
               "--web-port", str(spec.view_port), "--grpc-port", str(spec.view_port + VIEW_GRPC_OFFSET)]
        self.proc = subprocess.Popen(cmd, stdout=self.sandbox.open_log("view"), stderr=subprocess.STDOUT,
                                     stdin=subprocess.DEVNULL, cwd=paths.ROOT, process_group=0,
                                     preexec_fn=self.sandbox.preexec())
        deadline = time.monotonic() + VIEW_READY_TIMEOUT_S
        path = out / "view.log"
        while "view: http" not in path.read_text(errors="replace"):
            if self.proc.poll() is not None:
                raise SandboxError(f"view exited at start (rc={self.proc.returncode}); see view.log")
            if time.monotonic() > deadline:
                raise SandboxError(f"view not serving after {VIEW_READY_TIMEOUT_S:g} s; see view.log")
            time.sleep(0.05)
        url = next(ln for ln in path.read_text(errors="replace").splitlines() if ln.startswith("view: http"))
        print(url, flush=True)
        if spec.view_wait > 0:
            print(f"view: the flight starts in {spec.view_wait:g} s (time to open the page)", flush=True)
            time.sleep(spec.view_wait)

    def stop(self):
        """After the flight: serves view_hold seconds more (Ctrl-C ends the wait), then stops."""
        view = self.proc
        if view is None or view.poll() is not None:
            return
        if self.spec.view_hold > 0:
            print(f"view: serving {self.spec.view_hold:g} s more (Ctrl-C to stop)", flush=True)
            try:
                view.wait(timeout=self.spec.view_hold)
            except (subprocess.TimeoutExpired, KeyboardInterrupt):
                pass
        try:
            view.send_signal(signal.SIGTERM)
            view.wait(timeout=10)
        except subprocess.TimeoutExpired:
            view.kill()
            view.wait(timeout=5)
