// param_update_t from the bus, through the daemon's decoder and parameter queue into the
// loop's between-cycles update (ControlLoop::apply_param: daemon.* itself, model.* and
// cost.* through Controller::set_param and set_task_param), then cycles that use the new
// value. Input: the message bytes, then one byte picking the task.
#include "daemon_rig.hpp"

#include <cstddef>
#include <cstdint>

using namespace mppi;

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  // The third state is past the default state timeout: a changed one decides.
  return fuzz::decode_then_states(data, size, &transport::LcmDecoder::param, {1'000'000, 1'020'000, 1'200'000});
}
