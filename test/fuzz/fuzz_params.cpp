// param_update_t from the bus, through the daemon's decoder and parameter queue into the
// loop's between-cycles update (ControlLoop::apply_param: daemon.* itself, model.* and
// cost.* through Controller::set_param and set_task_param), then cycles that use the new
// value. Input: the message bytes, then one byte picking the task.
#include "daemon_rig.hpp"

#include <cstddef>
#include <cstdint>

using namespace mppi;

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  return fuzz::run_input(data, size, [](fuzz::Rig& rig, const std::uint8_t* msg, std::size_t n) {
    rig.decoder.param(msg, n, rig.inbox.get());
    rig.valid_state(1, 1'000'000);
    rig.valid_state(2, 1'020'000);
    rig.valid_state(3, 1'200'000);  // past the default state timeout: a changed one decides
  });
}
