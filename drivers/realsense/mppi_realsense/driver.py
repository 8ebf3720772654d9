"""The driver between the camera and the buses: states in (vehicle_state_t on mppid's bus),
frames out (point_cloud_t, SENSOR_DEPTH_CAMERA, on the sensors' bus), each frame stamped,
paired with the vehicle's pose at its time and the camera's mounting, and counted."""
from __future__ import annotations

import json
import sys
import threading
import time
from collections import Counter

from .cloud import CloudBuilder, fill_message, mount_quat, sensor_pose
from .states import StateHistory


def host_us() -> int:
    return time.time_ns() // 1000


class Driver:
    def __init__(self, settings, types, publish):
        """`types`: the mppi_lcm module; `publish(channel, bytes)`: the sensors' bus."""
        self.s, self.t, self.publish = settings, types, publish
        self.states = StateHistory(types.vehicle_state_t.MODEL_QUADROTOR_RATE, settings.vehicle, settings.max_state_age)
        self.clouds = CloudBuilder(settings.min_range, settings.max_range, settings.max_points)
        self.mount_q = mount_quat(settings.mount_rotation_deg)
        self.msg = types.point_cloud_t()
        self.seq = 0
        self.n = Counter()
        self.last_size = (0, 0)
        self.max_cloud = 0
        self.errors: list[str] = []
        self._lock = threading.Lock()

    def on_state_bytes(self, data: bytes) -> None:
        try:
            m = self.t.vehicle_state_t.decode(data)
        except Exception:  # noqa: BLE001  (LCM raises ValueError, struct.error, ...)
            self.states.refused["undecodable"] += 1
            return
        self.states.on_state(m)

    def frame_utime(self, frame) -> int:
        """The frame's time on the state clock [us]: its own timestamp when the camera stamps it
        on the host clock (global time) and timestamps is camera, else its arrival here."""
        if self.s.timestamps == "camera" and frame.host_clock:
            return int(round(frame.timestamp_ms * 1000.0))
        if self.s.timestamps == "camera":
            self.n["host_stamped"] += 1
        return host_us()

    def on_frame(self, frame) -> bool:
        """One DepthFrame (camera.py): published, or refused and counted."""
        with self._lock:
            self.n["frames"] += 1
            self.last_size = (frame.width, frame.height)
            utime = self.frame_utime(frame)
            cloud = self.clouds.build(frame.vertices)
            if cloud is None:
                return False
            pose = self.states.pose_at(utime)
            if pose is None:
                self.n["no_state"] += 1
                return False
            position, orientation = sensor_pose(pose[0], pose[1], self.s.mount_offset, self.mount_q)
            fill_message(self.msg, utime, self.seq, self.t.point_cloud_t.SENSOR_DEPTH_CAMERA, position, orientation,
                         self.s.min_range, self.s.max_range, cloud)
            self.publish(self.s.channel, self.msg.encode())
            self.seq += 1
            self.n["published"] += 1
            self.n["points"] += self.msg.n
            self.n["returns"] += int(cloud[3].sum())
            self.max_cloud = max(self.max_cloud, self.msg.n)
            return True

    def on_frame_safe(self, frame) -> None:
        """on_frame for librealsense's thread: an exception there is reported, not lost."""
        try:
            self.on_frame(frame)
        except Exception as e:  # noqa: BLE001
            self.n["errors"] += 1
            if len(self.errors) < 10:
                self.errors.append(repr(e))
                print(f"mppid-realsense: frame refused: {e!r}", file=sys.stderr, flush=True)

    def stats(self) -> dict:
        with self._lock:
            rejected = dict(self.clouds.rejected)
            rejected["no_state"] = self.n["no_state"]
            return {
                "frames": self.n["frames"], "published": self.n["published"], "rejected": rejected,
                "errors": self.n["errors"], "points": self.n["points"], "returns": self.n["returns"],
                "points_cut": self.clouds.points_cut, "max_points_in_a_cloud": self.max_cloud,
                "host_stamped": self.n["host_stamped"], "width": self.last_size[0], "height": self.last_size[1],
                "states": {"taken": self.states.taken, **dict(self.states.refused)},
            }

    def write_stats(self, path: str) -> None:
        with open(path, "w") as f:
            json.dump(self.stats(), f, indent=1)
            f.write("\n")
