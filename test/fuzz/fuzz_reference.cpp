// reference_t from the bus, through the daemon's decoder and inbox validation into the
// task's cost inputs (goals, reference curve and its epoch), then a lock-step cycle with a
// valid state. Input: the message bytes, then one byte picking the task.
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
  rig.decoder.reference(data, size - 1, rig.inbox.get());
  rig.valid_state(1, 1'000'000);
  rig.valid_state(2, 1'020'000);
  rig.run_cycles();
  return 0;
}
