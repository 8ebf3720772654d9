// param_update_t from the bus, through the daemon's decoder and parameter queue into the
// loop's between-cycles update (ControlLoop::apply_param: daemon.* itself, model.* and
// cost.* through Controller::set_param and set_task_param), then cycles that use the new
// value. Input: the message bytes, then one byte picking the task.
#include "daemon_rig.hpp"

#include <cstdint>

using namespace mppi;

extern "C" int LLVMFuzzerInitialize(int*, char***) {
  fuzz::quiet();
  return 0;
}

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  if (size < 1) return 0;
  const auto& tasks = fuzz::tasks();
  fuzz::Rig rig(tasks[data[size - 1] % tasks.size()]);
  rig.decoder.param(data, size - 1, rig.inbox.get());
  rig.valid_state(1, 1'000'000);
  rig.valid_state(2, 1'020'000);
  rig.valid_state(3, 1'200'000);  // past the default state timeout: a changed one decides
  rig.run_cycles();
  return 0;
}
