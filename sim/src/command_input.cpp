#include "sim/command_input.hpp"

namespace sim {

const char* to_string(CommandCheck c) {
  switch (c) {
    case CommandCheck::kAccepted: return "accepted";
    case CommandCheck::kWrongShape: return "wrong size or kind";
    case CommandCheck::kNonFinite: return "non-finite value";
  }
  return "?";
}

CommandCheck check_command(const mppi_lcm::command_t& msg, const Plant& plant, std::vector<float>* u) {
  const int n = plant.nu() * plant.vehicles();
  if (msg.n != n || static_cast<int>(msg.u.size()) != n ||
      (msg.kind != plant.command_kind() && msg.kind != mppi_lcm::command_t::KIND_GENERIC))
    return CommandCheck::kWrongShape;
  u->assign(msg.u.begin(), msg.u.end());
  return plant.saturate(u->data()) ? CommandCheck::kAccepted : CommandCheck::kNonFinite;
}

}  // namespace sim
