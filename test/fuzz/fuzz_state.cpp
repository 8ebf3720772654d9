// vehicle_state_t from the bus, through the daemon's decoder and inbox validation into a
// lock-step cycle of the task's controller (the state is its own tick, as with
// daemon.lockstep_trigger: state). Input: the message bytes, then one byte picking the task.
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
  rig.valid_state(1, 1'000'000);  // a stream already under way: the sequence checks run too
  rig.decoder.state(data, size - 1, rig.inbox.get());
  rig.run_cycles();
  return 0;
}
