// ObstacleGrid::build (costs/obstacles.hpp): the per-cycle obstacle culling.
#include <algorithm>
#include <cmath>
#include <cstdint>

#include "mppi/costs/obstacles.hpp"

namespace mppi {
namespace {

// A cylinder as the build sees it: the segment its axis sweeps over [0, t_end], the
// bounding box of that segment, and its radius. Double precision.
struct Swept {
  double ax, ay, bx, by;          // axis at t = 0 and t = t_end
  double lox, loy, hix, hiy;      // bounding box of the segment
  double r;
};

struct Box {
  double x0, y0, x1, y1;
};

// Largest distance from a point of the box to (px, py).
double max_distance(const Box& b, double px, double py) {
  const double dx = std::max(std::fabs(px - b.x0), std::fabs(px - b.x1));
  const double dy = std::max(std::fabs(py - b.y0), std::fabs(py - b.y1));
  return std::sqrt(dx * dx + dy * dy);
}

// Upper bound of the surface distance from any point of the box, at any time, to s: the
// distance to a point of a segment is convex along it, so its maximum is at an end.
double upper(const Box& b, const Swept& s) {
  return std::max(max_distance(b, s.ax, s.ay), max_distance(b, s.bx, s.by)) - s.r;
}

// Lower bound of the same: the distance between the box and the segment's bounding box.
double lower(const Box& b, const Swept& s) {
  const double dx = std::max({0.0, s.lox - b.x1, b.x0 - s.hix});
  const double dy = std::max({0.0, s.loy - b.y1, b.y0 - s.hiy});
  return std::sqrt(dx * dx + dy * dy) - s.r;
}

// The members of `in` (n of them) that can be nearest for some point of box b: out, and
// how many.
int candidates(const Box& b, const Swept* swept, const std::uint8_t* in, int n, double slack, std::uint8_t* out) {
  double u = HUGE_VAL;
  for (int m = 0; m < n; ++m) u = std::min(u, upper(b, swept[in[m]]));
  int k = 0;
  for (int m = 0; m < n; ++m)
    if (lower(b, swept[in[m]]) <= u + slack) out[k++] = in[m];
  return k;
}

// Lays out the lists of grid g (cx x cy cells of side s from (lox, loy)); false if they
// overflow kMaxRefs.
bool fill(ObstacleGrid& g, const Swept* swept, int n, double lox, double loy, double s, int cx, int cy, double slack,
          double grow) {
  constexpr int kBlock = ObstacleGrid::kBlock;
  std::uint8_t all[ObstacleSet::kCapacity];
  for (int i = 0; i < n; ++i) all[i] = static_cast<std::uint8_t>(i);
  const Box region{lox - grow, loy - grow, lox + cx * s + grow, loy + cy * s + grow};
  std::uint8_t region_list[ObstacleSet::kCapacity];
  const int region_n = candidates(region, swept, all, n, slack, region_list);

  // Blocks of kBlock x kBlock cells filter the region's list; cells filter their block's.
  constexpr int kRowBlocks = (ObstacleGrid::kMaxSide + kBlock - 1) / kBlock;
  std::uint8_t block_list[kRowBlocks][ObstacleSet::kCapacity];
  int block_n[kRowBlocks];
  bool used[ObstacleSet::kCapacity] = {};
  int refs_n = 0;
  const int bx_count = (cx + kBlock - 1) / kBlock;
  for (int by = 0; by * kBlock < cy; ++by) {
    for (int bx = 0; bx < bx_count; ++bx) {
      const int ix1 = std::min(cx, (bx + 1) * kBlock), iy1 = std::min(cy, (by + 1) * kBlock);
      const Box b{lox + bx * kBlock * s - grow, loy + by * kBlock * s - grow, lox + ix1 * s + grow, loy + iy1 * s + grow};
      block_n[bx] = candidates(b, swept, region_list, region_n, slack, block_list[bx]);
    }
    for (int iy = by * kBlock; iy < std::min(cy, (by + 1) * kBlock); ++iy) {
      for (int ix = 0; ix < cx; ++ix) {
        const int bx = ix / kBlock;
        const Box b{lox + ix * s - grow, loy + iy * s - grow, lox + (ix + 1) * s + grow, loy + (iy + 1) * s + grow};
        std::uint8_t list[ObstacleSet::kCapacity];
        const int k = candidates(b, swept, block_list[bx], block_n[bx], slack, list);
        if (refs_n + k > ObstacleGrid::kMaxRefs) return false;
        g.first[iy * cx + ix] = static_cast<std::uint16_t>(refs_n);
        for (int m = 0; m < k; ++m) {
          g.refs[refs_n++] = list[m];
          used[list[m]] = true;
        }
      }
    }
  }
  g.first[cx * cy] = static_cast<std::uint16_t>(refs_n);
  g.listed = 0;
  for (int i = 0; i < n; ++i) g.listed += used[i];
  return true;
}

}  // namespace

void ObstacleGrid::build(const ObstacleSet& set, const float* points, int n_points, float t_end, float reach,
                         float cell) {
  nx = ny = 0;
  listed = 0;
  const int n = std::min(set.count, ObstacleSet::kCapacity);
  if (n <= 0 || !(reach > 0.0f) || !(cell > 0.0f) || !std::isfinite(reach) || !std::isfinite(t_end)) return;

  double lox = HUGE_VAL, loy = HUGE_VAL, hix = -HUGE_VAL, hiy = -HUGE_VAL;
  for (int i = 0; i < n_points; ++i) {
    const double px = points[2 * i], py = points[2 * i + 1];
    if (!std::isfinite(px) || !std::isfinite(py)) continue;
    lox = std::min(lox, px);
    loy = std::min(loy, py);
    hix = std::max(hix, px);
    hiy = std::max(hiy, py);
  }
  if (!(lox <= hix)) return;
  // The corner is stored as float: lay the cells out from that float.
  lox = static_cast<float>(lox - reach);
  loy = static_cast<float>(loy - reach);
  hix += reach;
  hiy += reach;

  Swept swept[ObstacleSet::kCapacity];
  double magnitude = std::max({std::fabs(lox), std::fabs(loy), std::fabs(hix), std::fabs(hiy)});
  for (int i = 0; i < n; ++i) {
    const Cylinder& c = set.items[i];
    Swept& o = swept[i];
    o.ax = c.x;
    o.ay = c.y;
    o.bx = static_cast<double>(c.x) + static_cast<double>(c.vx) * t_end;
    o.by = static_cast<double>(c.y) + static_cast<double>(c.vy) * t_end;
    o.lox = std::min(o.ax, o.bx);
    o.hix = std::max(o.ax, o.bx);
    o.loy = std::min(o.ay, o.by);
    o.hiy = std::max(o.ay, o.by);
    o.r = c.radius;
    // A cylinder with a non-finite field (which the daemon never sends) has no bounds to
    // cull with: no grid, every search scans the set.
    if (!std::isfinite(o.lox + o.hix + o.loy + o.hiy + o.r)) return;
    magnitude = std::max({magnitude, std::fabs(o.lox), std::fabs(o.hix), std::fabs(o.loy), std::fabs(o.hiy),
                          std::fabs(o.r)});
  }
  const double w = hix - lox, h = hiy - loy;
  // Float rounding: surface_distance is within a few ulp of `magnitude` of the exact value,
  // and the lookup may place a point up to a few ulp of (magnitude + extent) outside its
  // cell. Both slacks are far above that and far below any cylinder spacing.
  const double slack = 1e-4 + 1e-6 * magnitude;
  const double grow = 1e-4 + 1e-6 * (magnitude + std::max(w, h));

  // Cell side: as asked, or larger to fit kMaxSide per side and kMaxCells in all; if the
  // lists overflow kMaxRefs, larger again (fewer cells: fewer references in all).
  double side = std::max({static_cast<double>(cell), w / kMaxSide, h / kMaxSide, std::sqrt(w * h / kMaxCells)});
  for (int attempt = 0; attempt < 8; ++attempt, side *= 1.5) {
    int cx = 0, cy = 0;
    float inv = 0.0f;
    for (int fit = 0; fit < 64; ++fit, side *= 1.1) {
      inv = static_cast<float>(1.0 / side);
      cx = static_cast<int>(std::ceil(w * inv)) + 1;  // + 1: the float lookup may round up at the far edge
      cy = static_cast<int>(std::ceil(h * inv)) + 1;
      if (cx <= kMaxSide && cy <= kMaxSide && cx * cy <= kMaxCells) break;
    }
    if (!(cx <= kMaxSide && cy <= kMaxSide && cx * cy <= kMaxCells)) return;
    // The side is stored as its float reciprocal: lay the cells out from that float, as the
    // search computes them.
    if (fill(*this, swept, n, lox, loy, 1.0 / static_cast<double>(inv), cx, cy, slack, grow)) {
      x0 = static_cast<float>(lox);
      y0 = static_cast<float>(loy);
      inv_cell = inv;
      nx = cx;
      ny = cy;
      return;
    }
  }
}

}  // namespace mppi
