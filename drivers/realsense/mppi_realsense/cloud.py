"""A depth frame's points, as point_cloud_t carries them (lcmtypes/mppi_lcm/point_cloud_t.lcm):
the camera's optical frame (x right, y down, z along the optical axis: librealsense's
deprojection) turned into the sensor frame of the message (x forward along the optical axis,
y left, z up), range limits, the point budget, and the sensor's pose in the world from the
vehicle's state and the camera's mounting. Pure numpy: no camera, no LCM."""
from __future__ import annotations

import math
from collections import Counter

import numpy as np

from mppi_mavlink.frames import quat_mul  # the project's one quaternion product


def quat_rotate(q, v):
    """v rotated by the unit quaternion q (w, x, y, z)."""
    w, x, y, z = q
    r = np.array([[1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
                  [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
                  [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)]])
    return r @ np.asarray(v, dtype=float)


def mount_quat(rotation_deg):
    """Sensor frame -> body frame of a mounting's roll, pitch, yaw [deg] (yaw, then pitch, then
    roll, each about the body's FLU axes as they stand after the previous one). A positive
    pitch turns x towards -z: the optical axis tilted down."""
    roll, pitch, yaw = (math.radians(a) for a in rotation_deg)
    qz = (math.cos(yaw / 2), 0.0, 0.0, math.sin(yaw / 2))
    qy = (math.cos(pitch / 2), 0.0, math.sin(pitch / 2), 0.0)
    qx = (math.cos(roll / 2), math.sin(roll / 2), 0.0, 0.0)
    return quat_mul(quat_mul(qz, qy), qx)


def sensor_pose(body_p, body_q, offset, mount_q):
    """The sensor's position [m, world] and orientation (sensor -> world) from the body's pose
    (position, quaternion body FLU -> world ENU) and the mounting (offset in the body frame,
    quaternion sensor -> body)."""
    p = np.asarray(body_p, dtype=float) + quat_rotate(body_q, offset)
    q = quat_mul(body_q, mount_q)
    n = math.sqrt(sum(c * c for c in q))
    return p, tuple(c / n for c in q)


class CloudBuilder:
    """Vertices of one deprojected depth frame -> the sensor-frame points and hit flags of a
    point_cloud_t. Pixels with no depth (z = 0: holes, the camera's invalid pixels) are not
    sent; nearer than min_range neither; farther than max_range are sent as misses at max_range
    along their ray (free space up to there). A frame with a non-finite vertex, or without a
    single valid pixel, is refused and counted (`rejected`): no NaN ever leaves."""

    def __init__(self, min_range: float, max_range: float, max_points: int):
        self.min_range, self.max_range, self.max_points = min_range, max_range, max_points
        self.rejected = Counter()
        self.points_cut = 0

    def build(self, vertices: np.ndarray):
        """(x, y, z, hit) float32 / int8 arrays in the sensor frame, or None (refused)."""
        v = np.asarray(vertices, dtype=np.float32).reshape(-1, 3)
        if not np.isfinite(v).all():
            self.rejected["not_finite"] += 1
            return None
        v = v[v[:, 2] > 0.0]
        if len(v) == 0:
            self.rejected["no_depth"] += 1
            return None
        # optical (x right, y down, z forward) -> sensor (x forward, y left, z up)
        pts = np.stack((v[:, 2], -v[:, 0], -v[:, 1]), axis=1)
        r = np.linalg.norm(pts, axis=1)
        keep = r >= self.min_range
        pts, r = pts[keep], r[keep]
        if len(pts) == 0:
            self.rejected["no_depth"] += 1
            return None
        if len(pts) > self.max_points:
            idx = np.linspace(0, len(pts) - 1, self.max_points).astype(np.int64)
            self.points_cut += len(pts) - self.max_points
            pts, r = pts[idx], r[idx]
        far = r > self.max_range
        pts[far] *= (self.max_range / r[far])[:, None]
        hit = (~far).astype(np.int8)
        return pts[:, 0].copy(), pts[:, 1].copy(), pts[:, 2].copy(), hit


def fill_message(msg, utime: int, seq: int, sensor: int, position, orientation, min_range: float,
                 max_range: float, cloud) -> None:
    """point_cloud_t `msg` set from a built cloud (CloudBuilder.build) and the sensor's pose."""
    x, y, z, hit = cloud
    msg.utime, msg.seq, msg.sensor = int(utime), int(seq), sensor
    msg.position = [float(c) for c in position]
    msg.orientation = [float(c) for c in orientation]
    msg.min_range, msg.max_range = float(min_range), float(max_range)
    msg.n = len(x)
    msg.x, msg.y, msg.z, msg.hit = x.tolist(), y.tolist(), z.tolist(), hit.tolist()
