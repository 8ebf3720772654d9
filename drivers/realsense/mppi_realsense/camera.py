"""The camera side: a RealSense D4xx (by serial, or the first found) or a recorded file (.bag /
.db3, played back not in real time: each frame waits for the previous one's processing, so a
replay loses none), its depth sensor started at the settings' stream, and per frame the
decimation filter and librealsense's deprojection (rs.pointcloud: the stream's intrinsics and
distortion model) to vertices in the camera's optical frame."""
from __future__ import annotations

import threading

import numpy as np

INSTALL_HINT = ("pyrealsense2 is not installed: pip install pyrealsense2==2.59.1.11053 "
                "(docs/sensing.md, 'A RealSense camera')")


def import_rs():
    try:
        import pyrealsense2 as rs
    except ImportError as e:
        raise RuntimeError(f"{INSTALL_HINT} ({e})") from e
    return rs


class DepthFrame:
    """One processed frame: vertices (N x 3, optical frame, m; z = 0 where no depth), the
    frame's timestamp [ms], whether that is on the host's clock, its size after decimation."""
    __slots__ = ("vertices", "timestamp_ms", "host_clock", "width", "height", "number")

    def __init__(self, vertices, timestamp_ms, host_clock, width, height, number):
        self.vertices, self.timestamp_ms, self.host_clock = vertices, timestamp_ms, host_clock
        self.width, self.height, self.number = width, height, number


class Camera:
    def __init__(self, settings, bag: str | None = None, device=None):
        """The camera of `settings` (device.serial, stream), or the recording `bag`, or `device`
        (a librealsense device already at hand, e.g. a software device) taken as a camera."""
        self.rs = rs = import_rs()
        self.s, self.bag = settings, bag
        self.ctx = rs.context()
        self.ended = threading.Event()  # a recording played to its end
        self.playback = None
        if bag:
            self.device = self.ctx.load_device(bag)
            self.playback = self.device.as_playback()
            self.playback.set_real_time(False)
            self.playback.set_status_changed_callback(self._on_status)
        else:
            self.device = device if device is not None else self._find_device()
        self.sensor, self.profile = self._depth_profile()
        self.decimate = None
        if settings.decimation > 1:
            self.decimate = rs.decimation_filter()
            self.decimate.set_option(rs.option.filter_magnitude, float(settings.decimation))
        self.pc = rs.pointcloud()
        host = (rs.timestamp_domain.global_time, rs.timestamp_domain.system_time)
        self._host_domains = set(host)

    def _find_device(self):
        devices = list(self.ctx.query_devices())
        if not devices:
            raise RuntimeError("no RealSense camera found (USB, udev rules: docs/sensing.md)")
        if not self.s.serial:
            return devices[0]
        serials = [d.get_info(self.rs.camera_info.serial_number) for d in devices]
        if self.s.serial not in serials:
            raise RuntimeError(f"device.serial: no camera {self.s.serial!r} (found: {', '.join(serials)})")
        return devices[serials.index(self.s.serial)]

    def _depth_profile(self):
        """The depth sensor and its z16 profile: the settings' stream live, the recorded one from
        a file (its size and rate are what was recorded)."""
        rs = self.rs
        for sensor in self.device.query_sensors():
            profiles = [p.as_video_stream_profile() for p in sensor.get_stream_profiles()
                        if p.stream_type() == rs.stream.depth and p.format() == rs.format.z16]
            if not profiles:
                continue
            if self.bag:
                return sensor, profiles[0]
            for p in profiles:
                if (p.width(), p.height(), p.fps()) == (self.s.width, self.s.height, self.s.fps):
                    return sensor, p
            have = sorted({f"{p.width()}x{p.height()}@{p.fps()}" for p in profiles})
            raise RuntimeError(f"stream: {self.s.width}x{self.s.height}@{self.s.fps} is not one of the camera's "
                               f"depth modes ({', '.join(have)})")
        raise RuntimeError(f"{self.bag or 'the camera'}: no depth stream (z16)")

    def _on_status(self, status):
        if status == self.rs.playback_status.stopped:
            self.ended.set()

    def process(self, frame) -> DepthFrame:
        """A depth frame from the sensor, decimated and deprojected (copied out of the frame)."""
        depth = frame.as_depth_frame()
        if self.decimate is not None:
            depth = self.decimate.process(depth).as_depth_frame()
        points = self.pc.calculate(depth)
        vertices = np.asanyarray(points.get_vertices()).view(np.float32).reshape(-1, 3).copy()
        host = depth.get_frame_timestamp_domain() in self._host_domains
        return DepthFrame(vertices, depth.get_timestamp(), host, depth.get_width(), depth.get_height(),
                          depth.get_frame_number())

    def start(self, on_frame) -> None:
        """Streams, calling on_frame(DepthFrame) on librealsense's thread for each frame."""
        self.sensor.open(self.profile)
        self.sensor.start(lambda f: on_frame(self.process(f)))

    def stop(self) -> None:
        try:
            self.sensor.stop()
            self.sensor.close()
        except RuntimeError:
            pass  # not streaming (a playback that ended stops its sensors itself)
