// obstacles_t from the bus, through the daemon's decoder and inbox validation into the
// loop's nearest-obstacle selection and the task's cost, then lock-step cycles with a valid
// state. Input: the message bytes, then one byte picking the task.
#include "daemon_rig.hpp"

#include <cstddef>
#include <cstdint>

using namespace mppi;

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  return fuzz::decode_then_states(data, size, &transport::LcmDecoder::obstacles, {1'000'000, 1'020'000});
}
