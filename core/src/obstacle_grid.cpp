// ObstacleGrid::build (costs/obstacles.hpp): the per-cycle obstacle culling, laid out by
// ObstacleGridLayout::plan and filled here, hierarchically (region, blocks of cells, cells).
#include <algorithm>
#include <cmath>
#include <cstdint>

#include "mppi/costs/obstacles.hpp"

namespace mppi {
namespace {

using grid_bounds::Box;
using grid_bounds::Swept;

// The members of `in` (n of them) that can be nearest for some point of box b: out, and
// how many.
int candidates(const Box& b, const Swept* swept, const std::uint8_t* in, int n, double slack, std::uint8_t* out) {
  double u = HUGE_VAL;
  for (int m = 0; m < n; ++m) u = std::min(u, grid_bounds::upper(b, swept[in[m]]));
  int k = 0;
  for (int m = 0; m < n; ++m)
    if (grid_bounds::lower(b, swept[in[m]]) <= u + slack) out[k++] = in[m];
  return k;
}

// Lays out the lists of grid g for attempt a of layout L; false if they overflow kMaxRefs.
bool fill(ObstacleGrid& g, const Swept* swept, const ObstacleGridLayout& L, const ObstacleGridLayout::Attempt& a) {
  constexpr int kBlock = ObstacleGrid::kBlock;
  const int n = L.n, cx = a.cx, cy = a.cy;
  const double s = a.side, grow = L.grow, slack = L.slack;
  std::uint8_t all[ObstacleSet::kCapacity];
  for (int i = 0; i < n; ++i) all[i] = static_cast<std::uint8_t>(i);
  const Box region = grid_bounds::cells(L.lox, L.loy, s, 0, 0, cx, cy, grow);
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
      const Box b = grid_bounds::cells(L.lox, L.loy, s, bx * kBlock, by * kBlock, ix1, iy1, grow);
      block_n[bx] = candidates(b, swept, region_list, region_n, slack, block_list[bx]);
    }
    for (int iy = by * kBlock; iy < std::min(cy, (by + 1) * kBlock); ++iy) {
      for (int ix = 0; ix < cx; ++ix) {
        const int bx = ix / kBlock;
        const Box b = grid_bounds::cells(L.lox, L.loy, s, ix, iy, ix + 1, iy + 1, grow);
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

ObstacleGridLayout ObstacleGridLayout::plan(const ObstacleSet& set, const float* points, int n_points, float t_end,
                                            float reach, float cell) {
  ObstacleGridLayout L;
  const int n = std::min(set.count, ObstacleSet::kCapacity);
  if (n <= 0 || !(reach > 0.0f) || !(cell > 0.0f) || !std::isfinite(reach) || !std::isfinite(t_end)) return L;

  double lox = HUGE_VAL, loy = HUGE_VAL, hix = -HUGE_VAL, hiy = -HUGE_VAL;
  for (int i = 0; i < n_points; ++i) {
    const double px = points[2 * i], py = points[2 * i + 1];
    if (!std::isfinite(px) || !std::isfinite(py)) continue;
    lox = std::min(lox, px);
    loy = std::min(loy, py);
    hix = std::max(hix, px);
    hiy = std::max(hiy, py);
  }
  if (!(lox <= hix)) return L;
  // The corner is stored as float: lay the cells out from that float.
  lox = static_cast<float>(lox - reach);
  loy = static_cast<float>(loy - reach);
  hix += reach;
  hiy += reach;

  double magnitude = std::max({std::fabs(lox), std::fabs(loy), std::fabs(hix), std::fabs(hiy)});
  for (int i = 0; i < n; ++i) {
    const Swept o = grid_bounds::swept(set.items[i], t_end);
    // A cylinder with a non-finite field (which the daemon never sends) has no bounds to
    // cull with: no grid, every search scans the set.
    if (!std::isfinite(o.lox + o.hix + o.loy + o.hiy + o.r)) return L;
    magnitude = std::max({magnitude, std::fabs(o.lox), std::fabs(o.hix), std::fabs(o.loy), std::fabs(o.hiy),
                          std::fabs(o.r)});
  }
  const double w = hix - lox, h = hiy - loy;
  // Float rounding: surface_distance is within a few ulp of `magnitude` of the exact value,
  // and the lookup may place a point up to a few ulp of (magnitude + extent) outside its
  // cell. Both slacks are far above that and far below any cylinder spacing.
  L.slack = 1e-4 + 1e-6 * magnitude;
  L.grow = 1e-4 + 1e-6 * (magnitude + std::max(w, h));
  L.n = n;
  L.lox = lox;
  L.loy = loy;
  L.t_end = t_end;

  // Cell side: as asked, or larger to fit kMaxSide per side and kMaxCells in all; if the
  // lists overflow kMaxRefs, larger again (fewer cells: fewer references in all).
  constexpr int kMaxSide = ObstacleGrid::kMaxSide, kMaxCells = ObstacleGrid::kMaxCells;
  double side = std::max({static_cast<double>(cell), w / kMaxSide, h / kMaxSide, std::sqrt(w * h / kMaxCells)});
  for (int a = 0; a < kMaxAttempts; ++a, side *= 1.5) {
    int cx = 0, cy = 0;
    float inv = 0.0f;
    for (int fit = 0; fit < 64; ++fit, side *= 1.1) {
      inv = static_cast<float>(1.0 / side);
      cx = static_cast<int>(std::ceil(w * inv)) + 1;  // + 1: the float lookup may round up at the far edge
      cy = static_cast<int>(std::ceil(h * inv)) + 1;
      if (cx <= kMaxSide && cy <= kMaxSide && cx * cy <= kMaxCells) break;
    }
    if (!(cx <= kMaxSide && cy <= kMaxSide && cx * cy <= kMaxCells)) break;
    // The side is stored as its float reciprocal: lay the cells out from that float, as the
    // search computes them.
    L.attempt[L.attempts++] = Attempt{1.0 / static_cast<double>(inv), inv, cx, cy};
  }
  return L;
}

void ObstacleGrid::build(const ObstacleSet& set, const float* points, int n_points, float t_end, float reach,
                         float cell) {
  nx = ny = 0;
  listed = 0;
  const ObstacleGridLayout L = ObstacleGridLayout::plan(set, points, n_points, t_end, reach, cell);
  if (L.attempts == 0) return;
  Swept swept[ObstacleSet::kCapacity];
  for (int i = 0; i < L.n; ++i) swept[i] = grid_bounds::swept(set.items[i], L.t_end);
  for (int a = 0; a < L.attempts; ++a) {
    if (fill(*this, swept, L, L.attempt[a])) {
      x0 = static_cast<float>(L.lox);
      y0 = static_cast<float>(L.loy);
      inv_cell = L.attempt[a].inv;
      nx = L.attempt[a].cx;
      ny = L.attempt[a].cy;
      return;
    }
  }
}

}  // namespace mppi
