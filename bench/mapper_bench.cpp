// mppid-mapper-bench: what a sensor frame costs the local map, mppid-mapper's own dense
// rolling grid against OctoMap (+ DynamicEDT3D for the distance field, when built with them),
// on the same frames: the simulator's depth camera and LiDAR flying through forest_4m
// (seed 1) along y = 0 at 7 m/s. One JSON line per (map, sensor, stage) on stdout:
// {"map", "sensor", "stage", "n", "cpu_p50_ms", "cpu_p99_ms", "wall_p50_ms", "wall_p99_ms"}: the
// thread's CPU time (what the work costs) and the wall time (what the machine's load adds).
//   mppid-mapper-bench [--frames N] [--scenario FILE] [--seed S] [--grid-only]
#include <algorithm>
#include <chrono>
#include <ctime>
#include <cstdio>
#include <cstdlib>
#include <string>
#include <vector>

#include "mapper/local_map.hpp"
#include "sim/rng.hpp"
#include "sim/scenario.hpp"
#include "sim/sensors.hpp"
#include "source_dir.hpp"

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

// This thread's CPU time [ms]: what the work costs, whatever else the machine runs (wall
// time on a shared 2-core machine is mostly the others').
double cpu_ms() {
  timespec ts{};
  clock_gettime(CLOCK_THREAD_CPUTIME_ID, &ts);
  return 1e3 * static_cast<double>(ts.tv_sec) + 1e-6 * static_cast<double>(ts.tv_nsec);
}

struct Timer {
  Clock::time_point wall = Clock::now();
  double cpu = cpu_ms();
};

void stop(const Timer& t, std::vector<double>* wall, std::vector<double>* cpu) {
  cpu->push_back(cpu_ms() - t.cpu);
  wall->push_back(std::chrono::duration<double, std::milli>(Clock::now() - t.wall).count());
}

struct Times {
  std::vector<double> wall, cpu;
};

void report(const char* map, const char* sensor, const char* stage, Times t) {
  const auto summary = [](std::vector<double>& v, double* p50, double* p99) {
    std::sort(v.begin(), v.end());
    *p50 = v[v.size() / 2];
    *p99 = v[std::min(v.size() - 1, static_cast<std::size_t>(0.99 * static_cast<double>(v.size())))];
  };
  double w50, w99, c50, c99;
  summary(t.wall, &w50, &w99);
  summary(t.cpu, &c50, &c99);
  std::printf("{\"map\":\"%s\",\"sensor\":\"%s\",\"stage\":\"%s\",\"n\":%zu,\"cpu_p50_ms\":%.3f,\"cpu_p99_ms\":%.3f,"
              "\"wall_p50_ms\":%.3f,\"wall_p99_ms\":%.3f}\n",
              map, sensor, stage, t.wall.size(), c50, c99, w50, w99);
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
  Times integrate, distance;
  for (const auto& f : fr.frames) {
    const Timer t0;
    map.recentre(f.pose.p.data());
    map.begin_frame(f.pose.p.data());
    for (std::size_t i = 0; i < f.x.size(); ++i) {
      const double e[3] = {f.pose.p[0] + f.x[i], f.pose.p[1] + f.y[i], f.pose.p[2] + f.z[i]};
      map.add_point(e, f.hit[i] != 0);
    }
    map.end_frame();
    stop(t0, &integrate.wall, &integrate.cpu);
    const Timer t1;
    map.compute_distance(&mm);
    stop(t1, &distance.wall, &distance.cpu);
  }
  report("dense_grid", fr.sensor, "integrate_frame", integrate);
  report("dense_grid", fr.sensor, "distance_field", distance);
}

#ifdef MPPID_WITH_OCTOMAP
void bench_octomap(const Frames& fr, double max_range) {
  octomap::OcTree tree(0.25);
  Times integrate, edt_new, edt_incremental;
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
    const Timer t0;
    tree.insertPointCloud(cloud, origin, max_range);
    stop(t0, &integrate.wall, &integrate.cpu);
    // DynamicEDT3D keeps a dense box: a window that moves with the vehicle is a new box.
    const octomap::point3d lo = origin - octomap::point3d(16, 16, 4), hi = origin + octomap::point3d(16, 16, 4);
    const Timer t1;
    DynamicEDTOctomap edt(5.0f, &tree, lo, hi, false);
    edt.update();
    stop(t1, &edt_new.wall, &edt_new.cpu);
    tree.insertPointCloud(cloud, origin, max_range);  // the same frame again: the box's incremental update
    const Timer t2;
    edt.update();
    stop(t2, &edt_incremental.wall, &edt_incremental.cpu);
  }
  report("octomap", fr.sensor, "integrate_frame", integrate);
  report("octomap+dynamicedt3d", fr.sensor, "distance_field_new_window", edt_new);
  report("octomap+dynamicedt3d", fr.sensor, "distance_field_incremental", edt_incremental);
}
#endif

}  // namespace

int main(int argc, char** argv) {
  int frames = 60;
  bool grid_only = false;
  std::string scenario = mppi::testing::source_dir() + "/config/scenarios/forest_4m.yaml";
  unsigned long long seed = 1;
  for (int i = 1; i < argc; i += 2) {
    const std::string k = argv[i];
    if (k == "--grid-only") {
      grid_only = true;
      --i;
      continue;
    }
    if (i + 1 >= argc) return std::fprintf(stderr, "mppid-mapper-bench: %s needs a value\n", argv[i]), 2;
    if (k == "--frames")
      frames = std::atoi(argv[i + 1]);
    else if (k == "--scenario")
      scenario = argv[i + 1];
    else if (k == "--seed")
      seed = std::strtoull(argv[i + 1], nullptr, 10);
    else
      return std::fprintf(stderr, "usage: mppid-mapper-bench [--frames N] [--scenario FILE] [--seed S] [--grid-only]\n"), 2;
  }
  if (frames < 2) return std::fprintf(stderr, "mppid-mapper-bench: --frames must be >= 2\n"), 2;
  const sim::Scenario s = sim::load_scenario(scenario, seed);
  for (bool lidar : {false, true}) {
    const Frames fr = capture(s, lidar, frames);
    bench_own(fr);
#ifdef MPPID_WITH_OCTOMAP
    // OctoMap has no window: its rays are cut at 16 m (the grid's box reaches 16-22 m) so it
    // does not pay for the 30-m LiDAR rays the grid clips.
    if (!grid_only) bench_octomap(fr, lidar ? 16.0 : sim::DepthCameraSpec{}.max_range);
#endif
  }
  return 0;
}
