#include "sim/sensors.hpp"

#include <algorithm>
#include <cmath>
#include <limits>

namespace sim {
namespace {

constexpr double kInf = std::numeric_limits<double>::infinity();
constexpr double kPi = 3.14159265358979323846;

double deg(double d) { return d * kPi / 180.0; }

std::array<double, 3> unit(double x, double y, double z) {
  const double n = std::sqrt(x * x + y * y + z * z);
  return {x / n, y / n, z / n};
}

// The ray's point at t lies within the cylinder's circle (xy).
bool inside_circle(const double* o, const double* d, double t, const Obstacle& c) {
  const double x = o[0] + t * d[0] - c.x, y = o[1] + t * d[1] - c.y;
  return x * x + y * y <= c.radius * c.radius;
}

// Where a ray from over the cylinder comes down through its top cap (at height `top`), or kInf.
double ray_cap(const double* o, const double* d, const Obstacle& c, double top, double max_t) {
  if (d[2] >= 0.0) return kInf;
  const double t = (top - o[2]) / d[2];
  return (t <= max_t && inside_circle(o, d, t, c)) ? t : kInf;
}

}  // namespace

double ray_ground(const double* o, const double* d, double ground_z, double max_t) {
  if (o[2] <= ground_z) return 0.0;
  if (d[2] >= 0.0) return kInf;
  const double t = (ground_z - o[2]) / d[2];
  return t <= max_t ? t : kInf;
}

double ray_cylinder(const double* o, const double* d, const Obstacle& c, double ground_z, double max_t) {
  const double top = ground_z + c.height;
  const double ox = o[0] - c.x, oy = o[1] - c.y;
  const double cc = ox * ox + oy * oy - c.radius * c.radius;
  if (cc <= 0.0) {
    // Above (or in) the trunk's circle: inside it, or over its top looking down at the cap.
    if (o[2] >= ground_z && o[2] <= top) return 0.0;
    return o[2] > top ? ray_cap(o, d, c, top, max_t) : kInf;
  }
  const double a = d[0] * d[0] + d[1] * d[1];
  if (a < 1e-12) return kInf;  // vertical, outside the circle
  const double b = ox * d[0] + oy * d[1];
  const double disc = b * b - a * cc;
  if (b >= 0.0 || disc < 0.0) return kInf;  // moving away, or passing by
  const double t0 = (-b - std::sqrt(disc)) / a;
  if (t0 > max_t) return kInf;
  const double z0 = o[2] + t0 * d[2];
  if (z0 >= ground_z && z0 <= top) return t0;
  // Over the top where it meets the side: it may still come down through the cap.
  return z0 > top ? ray_cap(o, d, c, top, max_t) : kInf;
}

RayWorld::RayWorld(const std::vector<Obstacle>* obstacles, double ground_z)
    : obstacles_(obstacles), ground_z_(ground_z) {
  for (auto& b : bins_) b.reserve(16);
  near_.reserve(obstacles->size());
}

void RayWorld::prepare(const double* origin, double max_range) {
  for (int i = 0; i < 3; ++i) origin_[i] = origin[i];
  for (auto& b : bins_) b.clear();
  near_.clear();
  const double width = 2.0 * kPi / kBins;
  for (std::size_t i = 0; i < obstacles_->size(); ++i) {
    const Obstacle& c = (*obstacles_)[i];
    const double dx = c.x - origin[0], dy = c.y - origin[1];
    const double dist = std::hypot(dx, dy);
    if (dist - c.radius > max_range) continue;
    near_.push_back(static_cast<int>(i));
    if (dist <= c.radius * 1.0001) {  // around the origin: every direction can meet it
      for (auto& b : bins_) b.push_back(static_cast<int>(i));
      continue;
    }
    const double centre = std::atan2(dy, dx) + kPi;  // [0, 2 pi]
    const double half = std::asin(c.radius / dist);
    const int lo = static_cast<int>(std::floor((centre - half) / width));
    const int hi = static_cast<int>(std::floor((centre + half) / width));
    for (int k = lo; k <= hi; ++k) bins_[static_cast<std::size_t>(((k % kBins) + kBins) % kBins)].push_back(static_cast<int>(i));
  }
}

double RayWorld::cast(const double* d, double max_t) const {
  double best = ray_ground(origin_, d, ground_z_, max_t);
  const double h = d[0] * d[0] + d[1] * d[1];
  const auto test = [&](int i) {
    best = std::min(best, ray_cylinder(origin_, d, (*obstacles_)[static_cast<std::size_t>(i)], ground_z_,
                                       std::min(best, max_t)));
  };
  if (h < 1e-12) {
    for (int i : near_) test(i);  // straight up or down: no azimuth
    return best;
  }
  const double az = std::atan2(d[1], d[0]) + kPi;
  const int k = std::min(kBins - 1, static_cast<int>(az / (2.0 * kPi / kBins)));
  for (int i : bins_[static_cast<std::size_t>(k)]) test(i);
  return best;
}

void Pose::rotate(const double* v, double* out) const {
  const double w = q[0], x = q[1], y = q[2], z = q[3];
  // v + 2 w (u x v) + 2 u x (u x v), u = (x, y, z).
  const double cx = y * v[2] - z * v[1], cy = z * v[0] - x * v[2], cz = x * v[1] - y * v[0];
  out[0] = v[0] + 2.0 * (w * cx + y * cz - z * cy);
  out[1] = v[1] + 2.0 * (w * cy + z * cx - x * cz);
  out[2] = v[2] + 2.0 * (w * cz + x * cy - y * cx);
}

Pose mounted(const Pose& body, const Vec3& offset, double pitch_down_rad) {
  Pose s;
  double off[3];
  body.rotate(offset.data(), off);
  for (int i = 0; i < 3; ++i) s.p[static_cast<std::size_t>(i)] = body.p[static_cast<std::size_t>(i)] + off[i];
  // A pitch down about the body's y axis (y left: a positive rotation about y tilts x down).
  const double c = std::cos(0.5 * pitch_down_rad), sn = std::sin(0.5 * pitch_down_rad);
  const auto& a = body.q;
  s.q = {a[0] * c - a[2] * sn, a[1] * c - a[3] * sn, a[2] * c + a[0] * sn, a[3] * c + a[1] * sn};
  return s;
}

void Frame::clear() {
  x.clear();
  y.clear();
  z.clear();
  hit.clear();
}

namespace {

// Every ray of `rays` from `pose`, through `world`; `range_of` turns the true range into the
// measured one (noise) or NaN (dropped).
template <class Measure>
void cast_rays(const std::vector<std::array<double, 3>>& rays, RayWorld& world, const Pose& pose, double min_range,
               double max_range, Measure measure, Frame* out) {
  out->pose = pose;
  out->clear();
  world.prepare(pose.p.data(), max_range);
  for (const auto& r : rays) {
    double d[3];
    pose.rotate(r.data(), d);
    double range = measure(world.cast(d, max_range));
    if (std::isnan(range) || range < min_range) continue;  // dropped, or too near to measure
    const bool hit = range <= max_range;
    range = std::min(range, max_range);
    out->x.push_back(static_cast<float>(range * r[0]));
    out->y.push_back(static_cast<float>(range * r[1]));
    out->z.push_back(static_cast<float>(range * r[2]));
    out->hit.push_back(hit ? 1 : 0);
  }
}

}  // namespace

DepthCamera::DepthCamera(const DepthCameraSpec& spec) : spec_(spec) {
  // Pinhole: x forward (optical axis), y left, z up; pixel (u, v) from the top left.
  const double fx = 0.5 * spec.width / std::tan(0.5 * deg(spec.hfov_deg));
  const double fy = 0.5 * spec.height / std::tan(0.5 * deg(spec.vfov_deg));
  for (int v = 0; v < spec.height; ++v)
    for (int u = 0; u < spec.width; ++u)
      rays_.push_back(unit(1.0, -(u + 0.5 - 0.5 * spec.width) / fx, -(v + 0.5 - 0.5 * spec.height) / fy));
}

void DepthCamera::capture(RayWorld& world, const Pose& pose, Rng& rng, Frame* out) const {
  const DepthCameraSpec& s = spec_;
  cast_rays(rays_, world, pose, s.min_range, s.max_range,
            [&](double range) {
              if (s.dropout > 0.0 && rng.uniform() < s.dropout) return std::numeric_limits<double>::quiet_NaN();
              if (!std::isfinite(range)) return kInf;
              return s.noise > 0.0 ? range + s.noise * range * range * rng.normal() : range;
            },
            out);
}

Lidar::Lidar(const LidarSpec& spec) : spec_(spec) {
  for (int b = 0; b < spec.beams; ++b) {
    const double el = spec.beams == 1 ? deg(spec.min_elevation_deg)
                                      : deg(spec.min_elevation_deg + (spec.max_elevation_deg - spec.min_elevation_deg) *
                                                                         b / (spec.beams - 1));
    for (int a = 0; a < spec.azimuth_steps; ++a) {
      const double az = 2.0 * kPi * a / spec.azimuth_steps;
      rays_.push_back({std::cos(el) * std::cos(az), std::cos(el) * std::sin(az), std::sin(el)});
    }
  }
}

void Lidar::capture(RayWorld& world, const Pose& pose, Rng& rng, Frame* out) const {
  const LidarSpec& s = spec_;
  cast_rays(rays_, world, pose, s.min_range, s.max_range,
            [&](double range) {
              if (!std::isfinite(range)) return kInf;
              return s.noise > 0.0 ? range + s.noise * rng.normal() : range;
            },
            out);
}

}  // namespace sim
