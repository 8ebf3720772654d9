"""mppid-realsense: an Intel RealSense D4xx's depth frames as point_cloud_t (docs/sensing.md)."""
