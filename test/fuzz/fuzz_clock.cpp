// sim_clock_t from the bus (lock-step with daemon.lockstep_trigger: clock), through the
// daemon's decoder and tick queue into a lock-step cycle against a valid state. Input: the
// message bytes, then one byte picking the task.
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
  fuzz::Rig rig(tasks[data[size - 1] % tasks.size()], /*tick_on_state=*/false);
  rig.valid_state(1, 1'000'000);
  rig.decoder.clock(data, size - 1, rig.inbox.get());
  rig.run_cycles();
  return 0;
}
