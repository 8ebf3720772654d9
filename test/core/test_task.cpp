// A team task (core/include/mppi/task.hpp): each vehicle advances alone; a crashed one is
// frozen.
#include <gtest/gtest.h>

#include <cstdint>
#include <vector>

#include "fixtures.hpp"
#include "mppi/models/quadrotor.hpp"

namespace mppi {
namespace {

using testing::quad_hover_state;
using Q = Quadrotor;
using Team = testing::QuadrotorTeam3;

std::vector<float> team_state() {
  const Q::Params p;
  std::vector<float> x;
  for (int j = 0; j < 3; ++j) {
    auto v = quad_hover_state(p);
    v[Q::PX] = 2.0f * static_cast<float>(j);
    v[Q::VY] = 0.5f * static_cast<float>(j);
    v[Q::ROLL] = 0.05f * static_cast<float>(j + 1);
    v[Q::WZ] = -0.2f * static_cast<float>(j);
    x.insert(x.end(), v.begin(), v.end());
  }
  return x;
}

TEST(Team, AdvanceMovesEachVehicleAlone) {
  Team::Params p{};
  const float h = Q::hover_speed(p.vehicle);
  const std::vector<float> u = {h + 50, h, h - 50, h, h, h + 80, h, h - 20, h + 10, h + 10, h + 10, h + 10};
  const float dt = 0.02f;
  const int substeps = 4;
  auto team = team_state();
  const auto start = team;
  Team::advance(p, team.data(), u.data(), dt, substeps, 0u);
  for (int j = 0; j < 3; ++j) {
    std::vector<float> alone(start.begin() + j * 16, start.begin() + (j + 1) * 16);
    for (int s = 0; s < substeps; ++s) Q::step(p.vehicle, alone.data(), u.data() + 4 * j, dt / substeps);
    for (int i = 0; i < 16; ++i) EXPECT_EQ(team[j * 16 + i], alone[i]) << "vehicle " << j << " state " << i;
    EXPECT_NE(team[j * 16 + Q::PZ], start[j * 16 + Q::PZ]) << "it moved";
  }
  // Vehicle 1 crashed: frozen; the others move as before.
  auto team2 = start;
  Team::advance(p, team2.data(), u.data(), dt, substeps, 0b010u);
  for (int i = 0; i < 16; ++i) EXPECT_EQ(team2[16 + i], start[16 + i]) << "frozen state " << i;
  for (int i = 0; i < 16; ++i) {
    EXPECT_EQ(team2[i], team[i]);
    EXPECT_EQ(team2[32 + i], team[32 + i]);
  }
}

}  // namespace
}  // namespace mppi
