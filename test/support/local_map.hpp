// Local maps (local_map_t) for the tests of the daemon's map intake: a box of cells of one
// distance, and the inbox expectations that take maps.
#pragma once

#include <cstddef>
#include <cstdint>

#include "mppi/transport/inbox.hpp"
#include "mppi_lcm/local_map_t.hpp"

namespace mppi::test {

struct MapBox {
  float origin[3];
  float resolution;  // m per cell
  std::int32_t nx, ny, nz;
};

// Every cell of `box` at `fill_mm`; max_distance 5 m.
inline mppi_lcm::local_map_t local_map_msg(const MapBox& box, std::int64_t seq, std::int64_t utime,
                                           std::int16_t fill_mm) {
  mppi_lcm::local_map_t m{};
  m.utime = utime;
  m.seq = seq;
  for (int i = 0; i < 3; ++i) m.origin[i] = box.origin[i];
  m.resolution = box.resolution;
  m.nx = box.nx;
  m.ny = box.ny;
  m.nz = box.nz;
  m.max_distance = 5.0f;
  m.n_cells = m.nx * m.ny * m.nz;
  m.distance_mm.assign(static_cast<std::size_t>(m.n_cells), fill_mm);
  return m;
}

// A quadrotor's states (16 per vehicle, model 1) and local maps, stale after 0.5 s.
inline transport::Inbox::Expect map_expect() {
  transport::Inbox::Expect e;
  e.nx = 16;
  e.model = 1;
  e.local_map = true;
  e.map_timeout_ns = 500'000'000;
  return e;
}

}  // namespace mppi::test
