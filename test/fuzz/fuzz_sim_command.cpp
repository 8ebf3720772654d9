// command_t from the bus as the simulator takes it: the checked decoder, then
// sim::check_command against each kind of plant (motor-speed and rate quadrotors, a team,
// the cart-pole, the race car) and, when accepted, physics steps with the clamped command.
// Input: the message bytes.
#include <cstddef>
#include <cstdint>
#include <memory>
#include <string>
#include <vector>

#include "mppi/transport/lcm_decode.hpp"
#include "sim/command_input.hpp"
#include "sim/plant.hpp"
#include "sim/scenario.hpp"
#include "source_dir.hpp"

namespace {

const std::vector<sim::Scenario>& scenarios() {
  static const std::vector<sim::Scenario> s = [] {
    std::vector<sim::Scenario> out;
    for (const char* name : {"forest_4m", "rate_forest_4m", "rate_forest_4m_body", "team3_fixed", "cartpole_swingup",
                             "racecar_ellipse"})
      out.push_back(sim::load_scenario(mppi::testing::source_dir() + "/config/scenarios/" + name + ".yaml", 1));
    return out;
  }();
  return s;
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  mppi_lcm::command_t msg;
  if (!mppi::transport::decode_message(data, size, &msg)) return 0;
  std::vector<float> u;
  const double wind[3] = {0.0, 0.0, 0.0};
  for (const sim::Scenario& s : scenarios()) {
    const std::unique_ptr<sim::Plant> plant = sim::make_plant(s);
    if (sim::check_command(msg, *plant, &u) != sim::CommandCheck::kAccepted) continue;
    for (int i = 0; i < 5; ++i) plant->step(u.data(), wind, 1.0 / s.physics_hz);
  }
  return 0;
}
