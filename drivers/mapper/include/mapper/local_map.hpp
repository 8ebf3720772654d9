// mppid-mapper's map: a rolling occupancy grid around the vehicle, fed by sensor rays, and
// its signed distance field (what local_map_t carries). Dense and fixed in size: every
// buffer is allocated once, at construction; an update allocates nothing.
//
// Occupancy: per cell a log-odds in tenths (OctoMap's defaults: a hit +0.85, a miss -0.4,
// clamped to [-2, 3.5], occupied above 0) or "unknown" (never touched by a ray). A ray
// clears the cells it crosses and marks the cell its return falls in; a ray with no return
// clears up to its end. Unknown space is free for the distance field (docs/sensing.md says
// why). The window is centred on the sensor and rolls by whole cells, so a cell keeps its
// place in the world and what was seen stays while it is inside the window.
//
// Distance: the exact Euclidean distance transform (Felzenszwalb & Huttenlocher 2012, three
// separable 1-D passes, O(cells)) of the occupied cells; a free cell holds the distance from
// its centre to the nearest occupied cell's centre less half a cell (so the cell next to an
// obstacle reads half a cell, the face between them), saturated at max_distance. An occupied
// cell holds minus its distance to the nearest free cell less half a cell, searched within
// kInsideRadius cells (exact there; trunks are a few cells across).
#pragma once

#include <array>
#include <cstdint>
#include <vector>

namespace mapper {

struct MapSettings {
  double resolution = 0.25;                 // m, cell side
  std::array<double, 3> size{32.0, 32.0, 8.0};  // m, the window (rounded to whole cells)
  double max_distance = 5.0;                // m, where distances saturate
  // Returns below this height (world z) are the ground, not obstacles: they clear the ray
  // but mark nothing (the controller keeps off the ground with its own altitude cost).
  double floor_z = 0.3;
  // The window's centre is this far ahead of the sensor along its horizontal motion [m]
  // (0: centred on the sensor); what lies ahead matters more than what is behind.
  double lead = 0.0;
  // Log-odds in tenths.
  int hit = 8, miss = -4, min_logodds = -20, max_logodds = 35;
};

struct Stats {
  std::int64_t rays = 0, cells_cleared = 0, cells_hit = 0, shifts = 0;
};

class LocalMap {
 public:
  static constexpr std::int8_t kUnknown = -128;

  explicit LocalMap(const MapSettings& s);

  // Moves the window so that it is centred on `centre` (whole cells; cells leaving it are
  // forgotten, cells entering it are unknown).
  void recentre(const double* centre);
  // A frame: begin_frame(sensor origin), add_point(end, hit) for each of its rays (world
  // frame; `hit`: the end is a surface), end_frame(). Within a frame a cell is updated once:
  // a return if more of the frame's rays ended in it than went through it, else a miss; one
  // ray is traced per distinct end cell, counting for all the rays that end there (OctoMap's
  // insertPointCloud with discretize, in effect): near the sensor hundreds of rays cross the
  // same cells.
  void begin_frame(const double* origin);
  void add_point(const double* end, bool hit);
  void end_frame();
  // A frame of one ray.
  void integrate_ray(const double* origin, const double* end, bool hit);
  // The signed distance field of the current occupancy, in mm, saturated (x fastest).
  void compute_distance(std::vector<std::int16_t>* out_mm);

  int nx() const { return n_[0]; }
  int ny() const { return n_[1]; }
  int nz() const { return n_[2]; }
  int cells() const { return n_[0] * n_[1] * n_[2]; }
  double resolution() const { return s_.resolution; }
  const MapSettings& settings() const { return s_; }
  // World position of cell (0, 0, 0)'s corner.
  std::array<double, 3> origin() const;
  // The window's first cell in world cells (origin() / resolution).
  const std::array<std::int64_t, 3>& corner() const { return corner_; }
  // Cell index of a world point, -1 outside.
  int index_of(const double* p) const;
  bool occupied(int index) const { return occ_[static_cast<std::size_t>(index)] > 0; }
  bool known(int index) const { return occ_[static_cast<std::size_t>(index)] != kUnknown; }
  const Stats& stats() const { return stats_; }

 private:
  void allocate(std::size_t total);
  void build_distance_tables();
  void update(std::size_t i, int delta);
  bool clip(const double* a, const double* d, double* s0, double* s1) const;
  int cell_at(const double* p) const;
  void walk(const double* d, const int* last, bool clear_end, std::uint16_t weight);
  void touch(std::size_t u);
  int inside_d2(int x, int y, int z) const;
  void edt_line(float* line, int n);
  void edt_axis(float* f, int axis);

  MapSettings s_;
  std::array<int, 3> n_{};
  std::array<std::int64_t, 3> corner_{};  // the window's first cell, in world cells
  std::vector<std::int8_t> occ_, scratch_;
  std::vector<std::uint32_t> touched_, ends_seen_;  // the frame that last tallied / queued a cell
  std::vector<std::uint16_t> hits_, passes_;        // this frame's returns in / rays through a cell
  std::vector<std::uint16_t> weight_;               // this frame's rays ending in a cell
  std::vector<int> ends_;                           // this frame's end cells (-1 - cell: keep it)
  std::vector<int> frame_cells_;                    // the cells tallied this frame
  std::uint32_t frame_ = 0;
  double origin_[3] = {0, 0, 0};                    // this frame's sensor, in window cells
  static constexpr int kInsideRadius = 4;  // cells: how deep inside an obstacle distances go
  std::vector<float> out_;                // squared distances, cells^2
  std::vector<std::int16_t> mm_of_d2_;    // signed-field mm of a squared distance, saturated
  std::vector<std::array<int, 4>> inside_offsets_;  // x, y, z, x^2 + y^2 + z^2, nearest first
  std::vector<float> block_, line_z_, line_d_;
  std::vector<int> line_v_;
  Stats stats_;
};

}  // namespace mapper
