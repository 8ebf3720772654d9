// vehicle_state_t from the bus, through the daemon's decoder and inbox validation into a
// lock-step cycle of the task's controller (the state is its own tick, as with
// daemon.lockstep_trigger: state). Input: the message bytes, then one byte picking the task.
#include "daemon_rig.hpp"

#include <cstddef>
#include <cstdint>

using namespace mppi;

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  return fuzz::run_input(data, size, [](fuzz::Rig& rig, const std::uint8_t* msg, std::size_t n) {
    rig.valid_state(1, 1'000'000);  // a stream already under way: the sequence checks run too
    rig.decoder.state(msg, n, rig.inbox.get());
  });
}
