// What the simulator makes of one command_t from the bus: decoded with the project's
// checked decoder (mppi::transport::decode_message), then checked against the plant (its
// vehicles x nu values, the plant's command kind or KIND_GENERIC, every value finite) and
// clamped to the plant's limits. Pure, so the fuzz target drives the same code as the run.
#pragma once

#include <cstddef>
#include <vector>

#include "mppi_lcm/command_t.hpp"
#include "sim/plant.hpp"

namespace sim {

enum class CommandCheck { kAccepted, kWrongShape, kNonFinite };
const char* to_string(CommandCheck c);

// On kAccepted, *u holds the saturated command (nu x vehicles).
CommandCheck check_command(const mppi_lcm::command_t& msg, const Plant& plant, std::vector<float>* u);

}  // namespace sim
