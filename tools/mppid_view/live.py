"""The live view: subscribes to the daemon's and the simulator's LCM channels, draws them
through Scene into a recording served over gRPC, and serves rerun's web viewer (shipped in the
rerun-sdk wheel: nothing is fetched) connected to it. Open http://127.0.0.1:<web_port>.

Keeping up (docs/view.md, "Delay"): the bus is drained as fast as it comes, but the scene is
drawn DRAW_HZ times a second from the newest message of each channel (the scalars: every one;
the world only when it changed), then flushed to the viewer's server at once. Each draw measures its delay: from the newest
state's publish on the bus (the host's wall clock) to the end of the flush."""
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
from .delay import DelayStats, bus_wall_time
from .scene import CHANNELS, DECODE_EVERY_S, SENSOR_CHANNELS, Scene, lcm_types

# Draws a second: the 3D view and the plots at most this often. Each draw is a chunk per entity
# drawn for the viewer to ingest (~50 a second of flight at 10 Hz, ~90 at 25 Hz); the newest
# state is at most one state period (20 ms at 50 Hz) old when drawn, whatever this rate.
DRAW_HZ = 10.0
REPORT_EVERY_S = 2.0       # the delay so far, printed this often while states come
CLOCK_CHANNEL = "MPPI_SIM_CLOCK"   # a lock-step simulator's tick: its utime is the state's publish
EVERY_MESSAGE = ("MPPI_COMMAND", "MPPI_STATUS")   # plotted: every message is drawn
# Republished unchanged (the simulator's world at 10 Hz): drawn again only when it changes. Their
# encoding: the type's 8-byte fingerprint, utime, seq, then the content.
ONLY_CHANGES = ("MPPI_OBSTACLES", "MPPI_REFERENCE")
CONTENT_AT = 24
# Between draws the SDK's batcher would only add delay: the draw flushes; the tick is a backstop.
BATCHER = dict(flush_tick=0.05, flush_num_bytes=1 << 20)


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
        from mppi_lcm import sim_clock_t
        self.clock_t = sim_clock_t
        self.rec = rr.RecordingStream("mppid", recording_id=f"live-{int(time.time())}",
                                      batcher_config=rr.ChunkBatcherConfig(**BATCHER))
        # The gRPC server on loopback only; with --save, the same stream to a file too.
        sinks = [rr.GrpcServerSink(bind_ip="127.0.0.1", port=grpc_port)] + ([rr.FileSink(save)] if save else [])
        self.rec.set_sinks(*sinks, default_blueprint=blueprint())
        self.grpc_uri = f"rerun+http://127.0.0.1:{grpc_port}/proxy"
        rr.serve_web_viewer(web_port=web_port, open_browser=False, connect_to=self.grpc_uri)
        self.url = viewer_url(web_port, grpc_port)
        self.scene = Scene(self.rec)
        self.counts: Counter = Counter()
        self.delay = DelayStats()
        if netns_pid:
            join_network_namespace(netns_pid)
        self.decoded_at: dict[str, float] = {}
        self.pending: list[tuple[str, bytes]] = []   # since the last draw, in arrival order
        self.state_rx_wall = 0.0                      # the newest state's receipt (wall clock)
        self.ticks: dict[int, int] = {}               # sim_utime -> the tick's wall utime
        self.drawn_content: dict[str, bytes] = {}     # ONLY_CHANGES: the content last drawn
        self.lc = lcm.LCM(lcm_url)
        for ch in CHANNELS + SENSOR_CHANNELS:
            self.lc.subscribe(ch, self.on_message)
        self.lc.subscribe(CLOCK_CHANNEL, self.on_clock)
        # A sensed flight's frames are on a bus of their own (tools/sitl: the next UDP port).
        self.sensor_lc = lcm.LCM(sensor_lcm_url) if sensor_lcm_url else None
        if self.sensor_lc is not None:
            for ch in SENSOR_CHANNELS:
                self.sensor_lc.subscribe(ch, self.on_message)

    def on_message(self, channel: str, data: bytes) -> None:
        every = DECODE_EVERY_S.get(channel)
        if every is not None:  # a map or a frame: only those the scene will draw are kept
            now = time.monotonic()
            if now - self.decoded_at.get(channel, -1e9) < every:
                return
            self.decoded_at[channel] = now
        if channel == "MPPI_STATE":
            self.state_rx_wall = time.time()
        self.pending.append((channel, data))

    def on_clock(self, channel: str, data: bytes) -> None:
        try:
            tick = self.clock_t.decode(data)
        except ValueError:
            return
        if len(self.ticks) > 64:
            self.ticks.clear()
        self.ticks[tick.sim_utime] = tick.utime

    def decode(self, channel: str, data: bytes):
        try:
            return self.types[channel].decode(data)
        except ValueError:
            self.counts[channel + ":undecodable"] += 1
            return None

    def draw(self) -> None:
        """The pending messages into the scene: the newest of each channel, every scalar, the
        flight's clock advanced by every state; then one flush and the delay of the newest state."""
        pending, self.pending = self.pending, []
        last = {ch: i for i, (ch, _) in enumerate(pending)}
        newest_state = None
        for i, (ch, data) in enumerate(pending):
            drawn = ch in EVERY_MESSAGE or last[ch] == i
            if not drawn and ch != "MPPI_STATE":
                continue
            if ch in ONLY_CHANGES:
                if self.drawn_content.get(ch) == data[CONTENT_AT:]:
                    continue
                self.drawn_content[ch] = data[CONTENT_AT:]
            msg = self.decode(ch, data)
            if msg is None:
                continue
            if not drawn:
                self.scene.advance(msg)
                continue
            if ch == "MPPI_STATE":
                newest_state = msg
            if self.scene.log(ch, msg):
                self.counts[ch] += 1
        self.rec.flush()
        if newest_state is not None:
            bus = bus_wall_time(newest_state, self.ticks, self.state_rx_wall)
            self.delay.add(time.time() - bus)

    def read(self, buses: list, deadline: float) -> None:
        """Handles the messages waiting on the buses until none is left or the deadline
        (time.monotonic()) passes, waiting for the first until the deadline (at most 0.1 s)."""
        fds = {b.fileno(): b for b in buses}
        wait = min(deadline - time.monotonic(), 0.1)
        ready, _, _ = select.select(list(fds), [], [], max(0.0, wait))
        while ready:
            for fd in ready:
                fds[fd].handle()
            if time.monotonic() >= deadline:
                return
            ready, _, _ = select.select(list(fds), [], [], 0.0)

    def run(self, seconds: float | None = None) -> Counter:
        stop = []
        for sig in (signal.SIGINT, signal.SIGTERM):
            signal.signal(sig, lambda *_: stop.append(1))
        end = None if seconds is None else time.monotonic() + seconds
        buses = [self.lc] + ([self.sensor_lc] if self.sensor_lc is not None else [])
        period = 1.0 / DRAW_HZ
        next_draw = time.monotonic()
        next_report, reported = next_draw + REPORT_EVERY_S, 0
        while not stop and (end is None or time.monotonic() < end):
            self.read(buses, next_draw)
            now = time.monotonic()
            if now >= next_draw:
                if self.pending:
                    self.draw()
                next_draw = max(next_draw + period, now)
            if self.delay.delays and now >= next_report and len(self.delay.delays) != reported:
                print(self.delay.line(), flush=True)
                next_report, reported = now + REPORT_EVERY_S, len(self.delay.delays)
        if self.pending:
            self.draw()
        self.rec.flush()
        return self.counts
