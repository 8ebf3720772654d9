// obstacles_t from the bus, through the daemon's decoder and inbox validation into the
// loop's nearest-obstacle selection and the task's cost, then lock-step cycles with a valid
// state. Input: the message bytes, then one byte picking the task.
#include "daemon_rig.hpp"

#include <cstddef>
#include <cstdint>

using namespace mppi;

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  return fuzz::run_input(data, size, [](fuzz::Rig& rig, const std::uint8_t* msg, std::size_t n) {
    rig.decoder.obstacles(msg, n, rig.inbox.get());
    rig.valid_state(1, 1'000'000);
    rig.valid_state(2, 1'020'000);
  });
}
