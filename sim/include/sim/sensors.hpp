// The simulator's sensors: a depth camera and a spinning LiDAR, ray-cast against the
// scenario's world (trees: vertical cylinders of finite height standing on the ground; the
// ground: the plane z = ground_z). No LCM here: a frame is points in the sensor's frame, a
// hit flag per ray, and the sensor's pose; the simulator publishes it (point_cloud_t).
//
// Cost: a frame culls and bins the trees once by their azimuth from the sensor, so a ray
// tests only the one to three trees its azimuth can meet (docs/sensing.md has the numbers).
#pragma once

#include <array>
#include <cstdint>
#include <vector>

#include "sim/rng.hpp"
#include "sim/scenario.hpp"

namespace sim {

// Where the first hit of the ray o + t d (d a unit vector) is, t in (0, max_t]; +inf none.
double ray_ground(const double* o, const double* d, double ground_z, double max_t);
// The cylinder stands on ground_z, its top at ground_z + c.height; side and top both count.
// A ray starting inside it hits at t = 0.
double ray_cylinder(const double* o, const double* d, const Obstacle& c, double ground_z, double max_t);

// The trees and the ground, as a ray sees them from one origin (prepare() per frame).
class RayWorld {
 public:
  RayWorld(const std::vector<Obstacle>* obstacles, double ground_z);
  // Trees within max_range of `origin` (horizontally), binned by azimuth.
  void prepare(const double* origin, double max_range);
  // Distance to the first surface along the unit ray from the prepared origin; +inf none.
  double cast(const double* d, double max_t) const;
  int candidates() const { return static_cast<int>(near_.size()); }

 private:
  static constexpr int kBins = 720;
  const std::vector<Obstacle>* obstacles_;
  double ground_z_;
  double origin_[3] = {0, 0, 0};
  std::vector<int> near_;                       // trees within range
  std::array<std::vector<int>, kBins> bins_;    // indices into *obstacles_, per azimuth bin
};

// A pose: position [m, world] and orientation (unit quaternion w, x, y, z: frame -> world).
struct Pose {
  std::array<double, 3> p{0.0, 0.0, 0.0};
  std::array<double, 4> q{1.0, 0.0, 0.0, 0.0};
  void rotate(const double* v, double* out) const;  // frame vector -> world
};
// The sensor's pose from the vehicle's and the mount's (offset in the body frame, a pitch
// down: positive tilts the optical axis toward the ground).
Pose mounted(const Pose& body, const Vec3& offset, double pitch_down_rad);

struct Frame {
  double t = 0.0;  // capture time [s, simulated]
  Pose pose;
  std::vector<float> x, y, z;  // sensor frame [m]
  std::vector<std::int8_t> hit;
  void clear();
};

class DepthCamera {
 public:
  explicit DepthCamera(const DepthCameraSpec& spec);
  // One frame from `pose`; noise and dropouts from `rng`.
  void capture(RayWorld& world, const Pose& pose, Rng& rng, Frame* out) const;
  const DepthCameraSpec& spec() const { return spec_; }

 private:
  DepthCameraSpec spec_;
  std::vector<std::array<double, 3>> rays_;  // unit, sensor frame, row-major pixels
};

class Lidar {
 public:
  explicit Lidar(const LidarSpec& spec);
  void capture(RayWorld& world, const Pose& pose, Rng& rng, Frame* out) const;
  const LidarSpec& spec() const { return spec_; }

 private:
  LidarSpec spec_;
  std::vector<std::array<double, 3>> rays_;
};

}  // namespace sim
