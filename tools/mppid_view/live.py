"""The live view: subscribes to the daemon's and the simulator's LCM channels, draws them
through Scene into a recording served over gRPC, and serves rerun's web viewer (shipped in the
rerun-sdk wheel: nothing is fetched) connected to it. Open http://127.0.0.1:<web_port>."""
from __future__ import annotations

import ctypes
import os
import select
import signal
import time
from collections import Counter
from urllib.parse import quote

import lcm
import rerun as rr

from .blueprint import blueprint
from .scene import CHANNELS, DECODE_EVERY_S, SENSOR_CHANNELS, Scene, lcm_types


def viewer_url(web_port: int, grpc_port: int, host: str = "127.0.0.1") -> str:
    return f"http://{host}:{web_port}/?url=" + quote(f"rerun+http://{host}:{grpc_port}/proxy", safe="")


CLONE_NEWNET = 0x40000000


def join_network_namespace(pid: int) -> None:
    """Moves this thread into process pid's network namespace. Sockets opened before (the
    viewer's servers) stay where they were: a harness flight's bus is read from inside its
    private namespace while the browser reaches the viewer from the host's."""
    libc = ctypes.CDLL("libc.so.6", use_errno=True)
    fd = os.open(f"/proc/{pid}/ns/net", os.O_RDONLY)
    try:
        if libc.setns(fd, CLONE_NEWNET) != 0:
            e = ctypes.get_errno()
            raise OSError(e, f"setns into the network namespace of pid {pid}: {os.strerror(e)} (needs root)")
    finally:
        os.close(fd)


class LiveView:
    def __init__(self, lcm_url: str, grpc_port: int, web_port: int, save: str | None = None, netns_pid: int = 0,
                 sensor_lcm_url: str | None = None):
        self.types = lcm_types()
        self.rec = rr.RecordingStream("mppid", recording_id=f"live-{int(time.time())}")
        # The gRPC server on loopback only; with --save, the same stream to a file too.
        sinks = [rr.GrpcServerSink(bind_ip="127.0.0.1", port=grpc_port)] + ([rr.FileSink(save)] if save else [])
        self.rec.set_sinks(*sinks, default_blueprint=blueprint())
        self.grpc_uri = f"rerun+http://127.0.0.1:{grpc_port}/proxy"
        rr.serve_web_viewer(web_port=web_port, open_browser=False, connect_to=self.grpc_uri)
        self.url = viewer_url(web_port, grpc_port)
        self.scene = Scene(self.rec)
        self.counts: Counter = Counter()
        if netns_pid:
            join_network_namespace(netns_pid)
        self.decoded_at: dict[str, float] = {}
        self.lc = lcm.LCM(lcm_url)
        for ch in CHANNELS + SENSOR_CHANNELS:
            self.lc.subscribe(ch, self.on_message)
        # A sensed flight's frames are on a bus of their own (tools/sitl: the next UDP port).
        self.sensor_lc = lcm.LCM(sensor_lcm_url) if sensor_lcm_url else None
        if self.sensor_lc is not None:
            for ch in SENSOR_CHANNELS:
                self.sensor_lc.subscribe(ch, self.on_message)

    def on_message(self, channel: str, data: bytes) -> None:
        every = DECODE_EVERY_S.get(channel)
        if every is not None:  # a map or a frame: only those the scene will draw are decoded
            now = time.monotonic()
            if now - self.decoded_at.get(channel, -1e9) < every:
                return
            self.decoded_at[channel] = now
        try:
            msg = self.types[channel].decode(data)
        except ValueError:
            self.counts[channel + ":undecodable"] += 1
            return
        if self.scene.log(channel, msg):
            self.counts[channel] += 1

    def run(self, seconds: float | None = None) -> Counter:
        stop = []
        for sig in (signal.SIGINT, signal.SIGTERM):
            signal.signal(sig, lambda *_: stop.append(1))
        end = None if seconds is None else time.monotonic() + seconds
        buses = [self.lc] + ([self.sensor_lc] if self.sensor_lc is not None else [])
        while not stop and (end is None or time.monotonic() < end):
            if len(buses) == 1:
                self.lc.handle_timeout(100)
                continue
            ready, _, _ = select.select([b.fileno() for b in buses], [], [], 0.1)
            for b in buses:
                if b.fileno() in ready:
                    b.handle()
        self.rec.flush()
        return self.counts
