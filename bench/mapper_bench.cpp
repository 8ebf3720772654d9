// mppid-mapper-bench: what a sensor frame costs the local map, mppid-mapper's own dense
// rolling grid against OctoMap (+ DynamicEDT3D for the distance field, when built with them),
// on the same frames: the simulator's depth camera and LiDAR flying through forest_4m
// (seed 1) along y = 0 at 7 m/s. One JSON line per (map, sensor, stage) on stdout:
// {"map", "sensor", "stage", "n", "p50_ms", "p99_ms", "mean_ms"}.
//   mppid-mapper-bench [--frames N] [--scenario FILE] [--seed S]
#include <algorithm>
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <string>
#include <vector>

#include "mapper/local_map.hpp"
#include "sim/rng.hpp"
#include "sim/scenario.hpp"
#include "sim/sensors.hpp"

#ifdef MPPID_WITH_OCTOMAP
#include <dynamicEDT3D/dynamicEDTOctomap.h>
#include <octomap/octomap.h>
#endif

namespace {

using Clock = std::chrono::steady_clock;

struct Frames {
  const char* sensor;
  std::vector<sim::Frame> frames;
};

double ms_since(Clock::time_point t0) { return std::chrono::duration<double, std::milli>(Clock::now() - t0).count(); }

void report(const char* map, const char* sensor, const char* stage, std::vector<double> v) {
  std::sort(v.begin(), v.end());
  double sum = 0.0;
  for (double x : v) sum += x;
  const auto at = [&](double p) { return v[std::min(v.size() - 1, static_cast<std::size_t>(p * static_cast<double>(v.size())))]; };
  std::printf("{\"map\":\"%s\",\"sensor\":\"%s\",\"stage\":\"%s\",\"n\":%zu,\"p50_ms\":%.3f,\"p99_ms\":%.3f,\"mean_ms\":%.3f}\n",
              map, sensor, stage, v.size(), at(0.5), at(0.99), sum / static_cast<double>(v.size()));
  std::fflush(stdout);
}

// Frames along the corridor, 7 m/s: the camera's at 30 Hz, the LiDAR's at 10 Hz.
Frames capture(const sim::Scenario& s, bool lidar, int n) {
  Frames out{lidar ? "lidar" : "depth_camera", {}};
  sim::RayWorld world(&s.obstacles, s.ground_z);
  sim::Rng rng(s.seed, 5);
  const sim::DepthCamera cam(sim::DepthCameraSpec{});
  const sim::Lidar lid(sim::LidarSpec{});
  for (int k = 0; k < n; ++k) {
    sim::Pose pose;
    pose.p = {1.0 + 7.0 * k / (lidar ? 10.0 : 30.0), 0.0, 2.0};
    sim::Frame f;
    if (lidar)
      lid.capture(world, pose, rng, &f);
    else
      cam.capture(world, pose, rng, &f);
    out.frames.push_back(std::move(f));
  }
  return out;
}

void bench_own(const Frames& fr) {
  mapper::LocalMap map(mapper::MapSettings{});
  std::vector<std::int16_t> mm;
  std::vector<double> integrate, distance;
  for (const auto& f : fr.frames) {
    const auto t0 = Clock::now();
    map.recentre(f.pose.p.data());
    map.begin_frame(f.pose.p.data());
    for (std::size_t i = 0; i < f.x.size(); ++i) {
      const double e[3] = {f.pose.p[0] + f.x[i], f.pose.p[1] + f.y[i], f.pose.p[2] + f.z[i]};
      map.add_point(e, f.hit[i] != 0);
    }
    map.end_frame();
    integrate.push_back(ms_since(t0));
    const auto t1 = Clock::now();
    map.compute_distance(&mm);
    distance.push_back(ms_since(t1));
  }
  report("dense_grid", fr.sensor, "integrate_frame", integrate);
  report("dense_grid", fr.sensor, "distance_field", distance);
}

#ifdef MPPID_WITH_OCTOMAP
void bench_octomap(const Frames& fr, double max_range) {
  octomap::OcTree tree(0.25);
  std::vector<double> integrate, edt_new, edt_incremental;
  for (const auto& f : fr.frames) {
    octomap::Pointcloud cloud;
    cloud.reserve(f.x.size());
    for (std::size_t i = 0; i < f.x.size(); ++i) {
      // A miss: beyond max_range, so OctoMap clears the ray up to it and marks nothing.
      const float k = f.hit[i] != 0 ? 1.0f : 1.01f;
      cloud.push_back(static_cast<float>(f.pose.p[0]) + k * f.x[i], static_cast<float>(f.pose.p[1]) + k * f.y[i],
                      static_cast<float>(f.pose.p[2]) + k * f.z[i]);
    }
    const octomap::point3d origin(static_cast<float>(f.pose.p[0]), static_cast<float>(f.pose.p[1]),
                                  static_cast<float>(f.pose.p[2]));
    const auto t0 = Clock::now();
    tree.insertPointCloud(cloud, origin, max_range);
    integrate.push_back(ms_since(t0));
    // DynamicEDT3D keeps a dense box: a window that moves with the vehicle is a new box.
    const octomap::point3d lo = origin - octomap::point3d(16, 16, 4), hi = origin + octomap::point3d(16, 16, 4);
    const auto t1 = Clock::now();
    DynamicEDTOctomap edt(5.0f, &tree, lo, hi, false);
    edt.update();
    edt_new.push_back(ms_since(t1));
    tree.insertPointCloud(cloud, origin, max_range);  // the same frame again: the box's incremental update
    const auto t2 = Clock::now();
    edt.update();
    edt_incremental.push_back(ms_since(t2));
  }
  report("octomap", fr.sensor, "integrate_frame", integrate);
  report("octomap+dynamicedt3d", fr.sensor, "distance_field_new_window", edt_new);
  report("octomap+dynamicedt3d", fr.sensor, "distance_field_incremental", edt_incremental);
}
#endif

}  // namespace

int main(int argc, char** argv) {
  int frames = 60;
  std::string scenario = MPPID_SOURCE_DIR "/config/scenarios/forest_4m.yaml";
  unsigned long long seed = 1;
  for (int i = 1; i + 1 < argc; i += 2) {
    const std::string k = argv[i];
    if (k == "--frames")
      frames = std::atoi(argv[i + 1]);
    else if (k == "--scenario")
      scenario = argv[i + 1];
    else if (k == "--seed")
      seed = std::strtoull(argv[i + 1], nullptr, 10);
    else
      return std::fprintf(stderr, "usage: mppid-mapper-bench [--frames N] [--scenario FILE] [--seed S]\n"), 2;
  }
  if (frames < 2) return std::fprintf(stderr, "mppid-mapper-bench: --frames must be >= 2\n"), 2;
  const sim::Scenario s = sim::load_scenario(scenario, seed);
  for (bool lidar : {false, true}) {
    const Frames fr = capture(s, lidar, frames);
    bench_own(fr);
#ifdef MPPID_WITH_OCTOMAP
    bench_octomap(fr, lidar ? sim::LidarSpec{}.max_range : sim::DepthCameraSpec{}.max_range);
#endif
  }
  return 0;
}
