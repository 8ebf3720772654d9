#include "mapper/local_map.hpp"

#include <algorithm>
#include <cmath>
#include <cstring>
#include <limits>
#include <stdexcept>

namespace mapper {
namespace {

constexpr float kFar = std::numeric_limits<float>::infinity();

// One line of the squared distance transform (Felzenszwalb & Huttenlocher): d[q] =
// min_p (q - p)^2 + f[p], over the finite f[p] only (an all-infinite line stays infinite).
// v, z: scratch of n and n + 1.
void edt_1d(const float* f, int n, float* d, int* v, float* z) {
  int k = -1;
  for (int q = 0; q < n; ++q) {
    if (f[q] == kFar) continue;
    const auto fq = f[q] + static_cast<float>(q) * static_cast<float>(q);
    if (k < 0) {
      k = 0;
      v[0] = q;
      z[0] = -kFar;
      z[1] = kFar;
      continue;
    }
    float s;
    for (;;) {  // z[0] = -inf: ends at k = 0 at the latest
      const int p = v[k];
      s = (fq - (f[p] + static_cast<float>(p) * static_cast<float>(p))) / static_cast<float>(2 * (q - p));
      if (s > z[k]) break;
      --k;
    }
    ++k;
    v[k] = q;
    z[k] = s;
    z[k + 1] = kFar;
  }
  if (k < 0) {
    for (int q = 0; q < n; ++q) d[q] = kFar;
    return;
  }
  int j = 0;
  for (int q = 0; q < n; ++q) {
    while (z[j + 1] < static_cast<float>(q)) ++j;
    const auto dq = static_cast<float>(q - v[j]);
    d[q] = dq * dq + f[v[j]];
  }
}

std::int64_t floor_cell(double x, double res) { return static_cast<std::int64_t>(std::floor(x / res)); }

// A ray's walk through the cells: where it is, and per axis its step, the ray length to the
// next cell boundary and between boundaries.
struct Walk {
  int c[3], step[3];
  double t_max[3], t_delta[3];
};

// The walk of the ray origin + s d (window cells) from s0, where it enters the window.
Walk start_walk(const double* origin, const std::array<int, 3>& n, const double* d, double s0) {
  Walk w{};
  for (int i = 0; i < 3; ++i) {
    const double p0 = origin[i] + s0 * d[i];
    w.c[i] = std::clamp(static_cast<int>(std::floor(p0)), 0, n[static_cast<std::size_t>(i)] - 1);
    w.step[i] = d[i] > 0.0 ? 1 : (d[i] < 0.0 ? -1 : 0);
    w.t_delta[i] = w.step[i] != 0 ? 1.0 / std::fabs(d[i]) : std::numeric_limits<double>::infinity();
    w.t_max[i] = w.step[i] > 0   ? (w.c[i] + 1 - origin[i]) / d[i]
                 : w.step[i] < 0 ? (w.c[i] - origin[i]) / d[i]
                                 : std::numeric_limits<double>::infinity();
  }
  return w;
}

}  // namespace

LocalMap::LocalMap(const MapSettings& s) : s_(s) {
  if (!(s.resolution > 0.0) || !(s.max_distance > 0.0) || s.max_distance > 32.0)
    throw std::invalid_argument("map: resolution > 0, max_distance in (0, 32] m");
  for (int i = 0; i < 3; ++i) {
    n_[static_cast<std::size_t>(i)] = static_cast<int>(std::lround(s.size[static_cast<std::size_t>(i)] / s.resolution));
    if (n_[static_cast<std::size_t>(i)] < 2 || n_[static_cast<std::size_t>(i)] > 4096)
      throw std::invalid_argument("map: every side must be 2..4096 cells");
  }
  const auto total = static_cast<std::size_t>(n_[0]) * static_cast<std::size_t>(n_[1]) * static_cast<std::size_t>(n_[2]);
  if (total > (1u << 24)) throw std::invalid_argument("map: at most 2^24 cells");
  allocate(total);
  build_distance_tables();
  const double zero[3] = {0.0, 0.0, 0.0};
  for (int i = 0; i < 3; ++i) corner_[static_cast<std::size_t>(i)] = -n_[static_cast<std::size_t>(i)] / 2;
  recentre(zero);
}

// Every buffer a frame and a transform use, at its full size once (none grows later).
void LocalMap::allocate(std::size_t total) {
  occ_.assign(total, kUnknown);
  scratch_.assign(total, kUnknown);
  touched_.assign(total, 0);
  ends_seen_.assign(total, 0);
  hits_.assign(total, 0);
  passes_.assign(total, 0);
  weight_.assign(total, 0);
  ends_.reserve(total);
  frame_cells_.reserve(total);
  out_.assign(total, 0.0f);
  const int longest = std::max({n_[0], n_[1], n_[2]});
  block_.assign(static_cast<std::size_t>(n_[0]) * static_cast<std::size_t>(std::max(n_[1], n_[2])), 0.0f);
  line_d_.assign(static_cast<std::size_t>(longest), 0.0f);
  line_z_.assign(static_cast<std::size_t>(longest) + 1, 0.0f);
  line_v_.assign(static_cast<std::size_t>(longest), 0);
}

// The signed field's mm of each squared distance, and the offsets inside an obstacle
// (within kInsideRadius cells) nearest first.
void LocalMap::build_distance_tables() {
  // mm of a squared distance of d2 cells^2 between centres (less half a cell), to saturation.
  const double res = s_.resolution, maxd = s_.max_distance;
  for (int d2 = 0;; ++d2) {
    const double m = std::min(maxd, std::max(0.0, (std::sqrt(static_cast<double>(d2)) - 0.5) * res));
    mm_of_d2_.push_back(static_cast<std::int16_t>(std::lround(1000.0 * m)));
    if (m >= maxd && d2 >= kInsideRadius * kInsideRadius) break;
  }
  for (int z = -kInsideRadius; z <= kInsideRadius; ++z)
    for (int y = -kInsideRadius; y <= kInsideRadius; ++y)
      for (int x = -kInsideRadius; x <= kInsideRadius; ++x)
        if (x * x + y * y + z * z <= kInsideRadius * kInsideRadius && (x | y | z) != 0)
          inside_offsets_.push_back({x, y, z, x * x + y * y + z * z});
  std::stable_sort(inside_offsets_.begin(), inside_offsets_.end(),
                   [](const auto& a, const auto& b) { return a[3] < b[3]; });
}

std::array<double, 3> LocalMap::origin() const {
  return {static_cast<double>(corner_[0]) * s_.resolution, static_cast<double>(corner_[1]) * s_.resolution,
          static_cast<double>(corner_[2]) * s_.resolution};
}

int LocalMap::index_of(const double* p) const {
  int c[3];
  for (int i = 0; i < 3; ++i) {
    const std::int64_t k = floor_cell(p[i], s_.resolution) - corner_[static_cast<std::size_t>(i)];
    if (k < 0 || k >= n_[static_cast<std::size_t>(i)]) return -1;
    c[i] = static_cast<int>(k);
  }
  return c[0] + n_[0] * (c[1] + n_[1] * c[2]);
}

void LocalMap::recentre(const double* centre) {
  std::array<std::int64_t, 3> next{};
  for (int i = 0; i < 3; ++i)
    next[static_cast<std::size_t>(i)] = floor_cell(centre[i], s_.resolution) - n_[static_cast<std::size_t>(i)] / 2;
  if (next == corner_) return;
  ++stats_.shifts;
  std::fill(scratch_.begin(), scratch_.end(), kUnknown);
  const std::int64_t dx = next[0] - corner_[0], dy = next[1] - corner_[1], dz = next[2] - corner_[2];
  // Rows along x: the overlap of the old and new windows, copied row by row.
  const std::int64_t x0 = std::max<std::int64_t>(0, -dx), x1 = std::min<std::int64_t>(n_[0], n_[0] - dx);
  if (x1 > x0) {
    for (int k = 0; k < n_[2]; ++k) {
      const std::int64_t ok = k + dz;
      if (ok < 0 || ok >= n_[2]) continue;
      for (int j = 0; j < n_[1]; ++j) {
        const std::int64_t oj = j + dy;
        if (oj < 0 || oj >= n_[1]) continue;
        const std::int64_t dst = x0 + n_[0] * (j + static_cast<std::int64_t>(n_[1]) * k);
        const std::int64_t src = x0 + dx + n_[0] * (oj + static_cast<std::int64_t>(n_[1]) * ok);
        std::memcpy(&scratch_[static_cast<std::size_t>(dst)], &occ_[static_cast<std::size_t>(src)],
                    static_cast<std::size_t>(x1 - x0));
      }
    }
  }
  occ_.swap(scratch_);
  corner_ = next;
}

void LocalMap::update(std::size_t i, int delta) {
  const int now = occ_[i] == kUnknown ? 0 : occ_[i];
  occ_[i] = static_cast<std::int8_t>(std::clamp(now + delta, s_.min_logodds, s_.max_logodds));
}

void LocalMap::integrate_ray(const double* origin, const double* end, bool hit) {
  begin_frame(origin);
  add_point(end, hit);
  end_frame();
}

void LocalMap::begin_frame(const double* origin) {
  ++frame_;
  ends_.clear();
  for (int i = 0; i < 3; ++i)
    origin_[i] = origin[i] / s_.resolution - static_cast<double>(corner_[static_cast<std::size_t>(i)]);
}

// The part of the segment a + s d, s in [0, 1], inside the window's box [0, n): false if none.
bool LocalMap::clip(const double* a, const double* d, double* s0, double* s1) const {
  *s0 = 0.0;
  *s1 = 1.0;
  for (int i = 0; i < 3; ++i) {
    const double hi = n_[static_cast<std::size_t>(i)];
    if (std::fabs(d[i]) < 1e-12) {
      if (a[i] < 0.0 || a[i] >= hi) return false;
      continue;
    }
    double t_lo = -a[i] / d[i], t_hi = (hi - a[i]) / d[i];
    if (t_lo > t_hi) std::swap(t_lo, t_hi);
    *s0 = std::max(*s0, t_lo);
    *s1 = std::min(*s1, t_hi);
  }
  return *s0 <= *s1;
}

int LocalMap::cell_at(const double* p) const {
  int c[3];
  for (int i = 0; i < 3; ++i) c[i] = std::clamp(static_cast<int>(std::floor(p[i])), 0, n_[static_cast<std::size_t>(i)] - 1);
  return c[0] + n_[0] * (c[1] + n_[1] * c[2]);
}

// This frame's tallies for cell u, started at its first touch.
void LocalMap::touch(std::size_t u) {
  if (touched_[u] == frame_) return;
  touched_[u] = frame_;
  hits_[u] = 0;
  passes_[u] = 0;
  frame_cells_.push_back(static_cast<int>(u));
}

void LocalMap::add_point(const double* end, bool hit) {
  ++stats_.rays;
  double d[3], s0, s1;
  for (int i = 0; i < 3; ++i)
    d[i] = end[i] / s_.resolution - static_cast<double>(corner_[static_cast<std::size_t>(i)]) - origin_[i];
  if (!clip(origin_, d, &s0, &s1)) return;
  const bool inside = s1 >= 1.0;
  double e[3];
  for (int i = 0; i < 3; ++i) e[i] = origin_[i] + s1 * d[i];
  const int cell = cell_at(e);
  const auto u = static_cast<std::size_t>(cell);
  if (hit && inside && end[2] >= s_.floor_z) {  // a surface, not the ground
    touch(u);
    if (hits_[u] < 0xFFFF) ++hits_[u];
  }
  if (ends_seen_[u] != frame_) {  // the first ray to this cell: one trace for all of them
    ends_seen_[u] = frame_;
    weight_[u] = 0;
    // A miss, or a ray leaving the window: free up to and with its last cell; a return: up to it.
    ends_.push_back(hit && inside ? -1 - cell : cell);
  }
  if (weight_[u] < 0xFFFF) ++weight_[u];
}

void LocalMap::end_frame() {
  for (const int entry : ends_) {
    const bool clear_end = entry >= 0;
    const int cell = clear_end ? entry : -1 - entry;
    const int last[3] = {cell % n_[0], (cell / n_[0]) % n_[1], cell / (n_[0] * n_[1])};
    double d[3];
    for (int i = 0; i < 3; ++i) d[i] = last[i] + 0.5 - origin_[i];  // to the end cell's centre
    walk(d, last, clear_end, weight_[static_cast<std::size_t>(cell)]);
  }
  // One update per cell and frame: a return if more rays ended in it than went through it
  // (range noise puts a few returns a cell short of the surface; the rays to the surface
  // outvote them), else a miss.
  for (const int c : frame_cells_) {
    const auto u = static_cast<std::size_t>(c);
    if (hits_[u] > passes_[u]) {
      update(u, s_.hit);
      ++stats_.cells_hit;
    } else {
      update(u, s_.miss);
      ++stats_.cells_cleared;
    }
  }
  frame_cells_.clear();
}

// Counts `weight` rays through every cell from the origin along d up to `last` (with it if
// clear_end) (Amanatides & Woo).
void LocalMap::walk(const double* d, const int* last, bool clear_end, std::uint16_t weight) {
  double s0, s1;
  if (!clip(origin_, d, &s0, &s1)) return;
  Walk w = start_walk(origin_, n_, d, s0);
  int* c = w.c;
  const int* step = w.step;
  double* t_max = w.t_max;
  const double* t_delta = w.t_delta;
  const int budget = std::abs(last[0] - c[0]) + std::abs(last[1] - c[1]) + std::abs(last[2] - c[2]);
  for (int n = 0; n <= budget; ++n) {
    const bool at_end = c[0] == last[0] && c[1] == last[1] && c[2] == last[2];
    if (!at_end || clear_end) {
      const auto idx = static_cast<std::size_t>(c[0] + n_[0] * (c[1] + n_[1] * c[2]));
      touch(idx);
      passes_[idx] = static_cast<std::uint16_t>(std::min(0xFFFF, passes_[idx] + weight));
    }
    if (at_end) return;
    const int ax = t_max[0] < t_max[1] ? (t_max[0] < t_max[2] ? 0 : 2) : (t_max[1] < t_max[2] ? 1 : 2);
    c[ax] += step[ax];
    if (c[ax] < 0 || c[ax] >= n_[static_cast<std::size_t>(ax)]) return;
    t_max[ax] += t_delta[ax];
  }
}

// One line of the transform in place (n cells), unless it has nothing to spread (no finite
// cell) or nothing to lower (all zero).
void LocalMap::edt_line(float* line, int n) {
  bool any_finite = false, any_nonzero = false;
  for (int q = 0; q < n; ++q) {
    any_finite = any_finite || line[q] != kFar;
    any_nonzero = any_nonzero || line[q] != 0.0f;
  }
  if (!any_finite || !any_nonzero) return;
  edt_1d(line, n, line_d_.data(), line_v_.data(), line_z_.data());
  std::copy(line_d_.begin(), line_d_.begin() + n, line);
}

// The transform along y (axis 1) or z (axis 2), in place. For each plane across the axis the
// nx lines are transposed into a block (rows read whole, x fastest: cache-friendly where a
// line walked cell by cell would touch a cache line per cell), transformed, and written back.
void LocalMap::edt_axis(float* f, int axis) {
  const int nx = n_[0], ny = n_[1], nz = n_[2];
  const int n = axis == 1 ? ny : nz;                          // cells per line
  const std::ptrdiff_t step = axis == 1 ? nx : static_cast<std::ptrdiff_t>(nx) * ny;  // between them
  const int planes = axis == 1 ? nz : ny;
  const std::ptrdiff_t plane_step = axis == 1 ? static_cast<std::ptrdiff_t>(nx) * ny : nx;
  float* block = block_.data();
  for (int o = 0; o < planes; ++o) {
    float* base = f + o * plane_step;
    for (int q = 0; q < n; ++q) {
      const float* row = base + q * step;
      for (int i = 0; i < nx; ++i) block[static_cast<std::ptrdiff_t>(i) * n + q] = row[i];
    }
    for (int i = 0; i < nx; ++i) edt_line(block + static_cast<std::ptrdiff_t>(i) * n, n);
    for (int q = 0; q < n; ++q) {
      float* row = base + q * step;
      for (int i = 0; i < nx; ++i) row[i] = block[static_cast<std::ptrdiff_t>(i) * n + q];
    }
  }
}

// Inside an obstacle: the distance to the nearest free cell, searched over the offsets within
// kInsideRadius cells nearest first (trunks are a few cells across: most occupied cells have a
// free neighbour at the first offset tried); deeper cells read the radius.
int LocalMap::inside_d2(int x, int y, int z) const {
  for (const auto& o : inside_offsets_) {
    const int a = x + o[0], b = y + o[1], c = z + o[2];
    if (a < 0 || b < 0 || c < 0 || a >= n_[0] || b >= n_[1] || c >= n_[2]) continue;
    if (occ_[static_cast<std::size_t>(a + n_[0] * (b + n_[1] * c))] <= 0) return o[3];
  }
  return kInsideRadius * kInsideRadius;
}

void LocalMap::compute_distance(std::vector<std::int16_t>* out_mm) {
  const int nx = n_[0], ny = n_[1], nz = n_[2];
  const std::size_t total = occ_.size();
  out_mm->resize(total);
  bool any = false;
  for (std::size_t i = 0; i < total; ++i) {
    const bool occ = occ_[i] > 0;
    any = any || occ;
    out_[i] = occ ? 0.0f : kFar;
  }
  const std::int16_t sat = mm_of_d2_.back();
  if (!any) {
    std::fill(out_mm->begin(), out_mm->end(), sat);
    return;
  }
  for (int r = 0; r < ny * nz; ++r) edt_line(out_.data() + static_cast<std::ptrdiff_t>(r) * nx, nx);  // along x
  edt_axis(out_.data(), 1);
  edt_axis(out_.data(), 2);
  // Squared distances are whole cells^2: a table gives the millimetres (saturated past its end).
  const auto last = static_cast<float>(mm_of_d2_.size() - 1);
  for (std::size_t i = 0; i < total; ++i) {
    if (occ_[i] > 0) continue;
    const float d2 = out_[i];
    (*out_mm)[i] = d2 >= last ? sat : mm_of_d2_[static_cast<std::size_t>(d2 + 0.5f)];
  }
  for (int z = 0; z < nz; ++z)
    for (int y = 0; y < ny; ++y)
      for (int x = 0; x < nx; ++x) {
        const auto i = static_cast<std::size_t>(x + nx * (y + ny * z));
        if (occ_[i] > 0) (*out_mm)[i] = static_cast<std::int16_t>(-mm_of_d2_[static_cast<std::size_t>(inside_d2(x, y, z))]);
      }
}

}  // namespace mapper
