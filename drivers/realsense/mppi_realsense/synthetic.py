"""A synthetic depth recording with no camera: librealsense's software device (a depth sensor and
its z16 stream with pinhole intrinsics) whose frames are pushed by hand, recorded through
rs.recorder into a file mppid-realsense --bag plays back. The scene: a flat wall facing the
camera at `distance` [m] along the optical axis, spanning optical x in [left, right] [m] (x to
the camera's right) over the whole image height; the rest of the image sees `background` [m]
(beyond the driver's max range: free space), and a strip of `near` [m] along the bottom rows
(nearer than its min range). After the wall frames, `empty` frames with no depth at all.

pyrealsense2 2.59's recorder writes ROS 2 bags (SQLite, .db3; a .bag name is refused) and plays
back both its own .db3 and the ROS 1 .bag files older versions and the RealSense Viewer wrote.

  python -m mppi_realsense.synthetic OUT.db3 [--distance 4] [--frames 10] ...
"""
from __future__ import annotations

import argparse
import math

import numpy as np

from .camera import import_rs

DEPTH_UNITS = 0.001  # m per z16 count (a D4xx's default)


def wall_image(width, height, fx, ppx, distance, left, right, background, near_rows, near) -> np.ndarray:
    """z16 depth of the scene (row-major, height x width)."""
    u = np.arange(width)
    x_at_wall = (u - ppx) / fx * distance  # optical x of each column's ray where it meets the wall's plane
    on_wall = (x_at_wall >= left) & (x_at_wall <= right)
    img = np.full((height, width), round(background / DEPTH_UNITS), dtype=np.uint16)
    img[:, on_wall] = round(distance / DEPTH_UNITS)
    if near_rows:
        img[height - near_rows:, :] = round(near / DEPTH_UNITS)
    return img


def record(path, width=424, height=240, fps=30, hfov_deg=87.0, distance=4.0, left=-0.5, right=1.5,
           background=30.0, near_rows=8, near=0.1, frames=10, empty=1) -> dict:
    """Records the scene into `path` (.db3); returns the intrinsics and what was recorded."""
    rs = import_rs()
    fx = (width / 2) / math.tan(math.radians(hfov_deg) / 2)
    ppx, ppy = (width - 1) / 2, (height - 1) / 2
    dev = rs.software_device()
    dev.register_info(rs.camera_info.name, "mppid synthetic depth camera")
    dev.register_info(rs.camera_info.serial_number, "0000000000")
    sensor = dev.add_sensor("Stereo Module")
    intr = rs.intrinsics()
    intr.width, intr.height, intr.ppx, intr.ppy, intr.fx, intr.fy = width, height, ppx, ppy, fx, fx
    intr.model, intr.coeffs = rs.distortion.brown_conrady, [0.0] * 5
    vs = rs.video_stream()
    vs.type, vs.index, vs.uid = rs.stream.depth, 0, 0
    vs.width, vs.height, vs.fps, vs.bpp, vs.fmt, vs.intrinsics = width, height, fps, 2, rs.format.z16, intr
    profile = sensor.add_video_stream(vs).as_video_stream_profile()
    sensor.add_read_only_option(rs.option.depth_units, DEPTH_UNITS)
    recorder = rs.recorder(str(path), dev)
    sensor.open(profile)
    sensor.start(lambda f: None)
    wall = wall_image(width, height, fx, ppx, distance, left, right, background, near_rows, near)
    blank = np.zeros_like(wall)
    for i in range(frames + empty):
        f = rs.software_video_frame()
        f.pixels = (wall if i < frames else blank).tobytes()
        f.bpp, f.stride = 2, 2 * width
        f.timestamp = 1000.0 * i / fps
        f.domain = rs.timestamp_domain.hardware_clock
        f.frame_number = i + 1
        f.profile = profile
        sensor.on_video_frame(f)
    sensor.stop()
    sensor.close()
    del recorder  # closes the file
    return {"width": width, "height": height, "fx": fx, "ppx": ppx, "ppy": ppy, "frames": frames, "empty": empty,
            "wall_pixels": int(np.count_nonzero(wall == round(distance / DEPTH_UNITS)))}


def main(argv=None) -> int:
    p = argparse.ArgumentParser(prog="python -m mppi_realsense.synthetic",
                                description="Record a synthetic wall through librealsense's software device.")
    p.add_argument("out", help="the recording to write (.db3)")
    p.add_argument("--distance", type=float, default=4.0, help="the wall's distance along the optical axis [m]")
    p.add_argument("--left", type=float, default=-0.5, help="the wall's left edge, optical x [m] (x: right)")
    p.add_argument("--right", type=float, default=1.5, help="the wall's right edge, optical x [m]")
    p.add_argument("--width", type=int, default=424)
    p.add_argument("--height", type=int, default=240)
    p.add_argument("--fps", type=int, default=30)
    p.add_argument("--frames", type=int, default=10, help="wall frames")
    p.add_argument("--empty", type=int, default=1, help="frames with no depth after them")
    a = p.parse_args(argv)
    info = record(a.out, width=a.width, height=a.height, fps=a.fps, distance=a.distance, left=a.left,
                  right=a.right, frames=a.frames, empty=a.empty)
    print(info)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
