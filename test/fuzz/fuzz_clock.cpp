// sim_clock_t from the bus (lock-step with daemon.lockstep_trigger: clock), through the
// daemon's decoder and tick queue into a lock-step cycle against a valid state. Input: the
// message bytes, then one byte picking the task.
#include "daemon_rig.hpp"

#include <cstddef>
#include <cstdint>

using namespace mppi;

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  return fuzz::run_input(
      data, size,
      [](fuzz::Rig& rig, const std::uint8_t* msg, std::size_t n) {
        rig.valid_state(1, 1'000'000);
        rig.decoder.clock(msg, n, rig.inbox.get());
      },
      /*tick_on_state=*/false);
}
