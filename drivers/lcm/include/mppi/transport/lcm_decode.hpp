// Raw LCM bytes from the bus -> messages -> the inbox, for every C++ decoder of bus input:
// the daemon's receive thread (LcmDecoder, called by LcmTransport), the simulator's
// command input, and the fuzz targets (test/fuzz), which drive the same code without a
// socket.
//
// decode_message: one message per call. The generated decoders trust the counts inside a
// message: vehicle_state_t's and command_t's n size their arrays before the bytes behind
// them are checked (n = -1 throws std::length_error out of the LCM callback and ends the
// process; n = 2^30 asks for 4 GB), obstacles_t's n sizes its cylinders the same way
// (value-initialised: 20 GB touched for n = 2^30), and a string length of 0 or less
// throws. decode_message checks every declared count against the bytes actually there
// first, so what a message can make the receiver allocate is bounded by its own size, and
// it never throws: false means undecodable (wrong type, truncated, padded, or a count the
// bytes do not back).
#pragma once

#include <cstddef>
#include <cstdint>

#include "mppi/rt/clock.hpp"
#include "mppi/transport/inbox.hpp"
#include "mppi_lcm/command_t.hpp"
#include "mppi_lcm/local_map_t.hpp"
#include "mppi_lcm/obstacles_t.hpp"
#include "mppi_lcm/param_update_t.hpp"
#include "mppi_lcm/reference_t.hpp"
#include "mppi_lcm/sim_clock_t.hpp"
#include "mppi_lcm/vehicle_state_t.hpp"

namespace mppi::transport {

bool decode_message(const void* data, std::size_t size, mppi_lcm::vehicle_state_t* m);
bool decode_message(const void* data, std::size_t size, mppi_lcm::reference_t* m);
bool decode_message(const void* data, std::size_t size, mppi_lcm::obstacles_t* m);
bool decode_message(const void* data, std::size_t size, mppi_lcm::param_update_t* m);
bool decode_message(const void* data, std::size_t size, mppi_lcm::sim_clock_t* m);
bool decode_message(const void* data, std::size_t size, mppi_lcm::command_t* m);
// local_map_t: also false when n_cells exceeds DistanceField::kMaxCells (the decoder's
// scratch is reserved for that many; a larger map is never decoded).
bool decode_message(const void* data, std::size_t size, mppi_lcm::local_map_t* m);

// Where each message's count sits in its encoding (8-byte fingerprint included) and how
// many bytes one counted element takes; test_lcm_decode.cpp checks them against the
// generated encoders, so a change of the .lcm files that moves them fails a test.
namespace wire {
constexpr std::size_t kStateCount = 8 + 8 + 8 + 8 + 1 + 2 + 2;  // int32 n, then n floats
constexpr std::size_t kCommandCount = 8 + 8 + 8 + 8 + 1 + 1 + 4 + 4 + 4 + 4;  // int32 n, then n floats
constexpr std::size_t kObstaclesCount = 8 + 8 + 8;               // int32 n, then n cylinders
constexpr std::size_t kCylinderBytes = 5 * 4;
constexpr std::size_t kReferenceCount = 8 + 8 + 8 + 1 + 12 + 4 + 4 + 4 + 8;  // int16, then 3 floats each
constexpr std::size_t kReferenceTail = 3 * 4;  // after the goals: ramp_s, phase, end_s
constexpr std::size_t kParamKeyLength = 8 + 8 + 8;  // int32 length including the NUL, then bytes
constexpr std::size_t kLocalMapCount = 8 + 8 + 8 + 12 + 4 + 4 + 4 + 4 + 4;  // int32 n_cells, then n_cells int16
}  // namespace wire

// One channel's bytes -> the inbox, which validates them (Inbox::offer_*). Undecodable
// bytes and counts past the fixed capacities are counted there. Receive thread only: the
// scratch messages are reused (their vectors keep the capacity reserved at construction).
class LcmDecoder {
 public:
  // MapScratch::kNone: no map scratch (2 MiB reserved, resident under mlockall) for a decoder that
  // never sees a map: LcmTransport's for states and the rest (maps have a decoder of their own).
  enum class MapScratch { kReserve, kNone };
  explicit LcmDecoder(rt::Clock* recv_clock, MapScratch maps = MapScratch::kReserve);
  void state(const void* data, std::size_t size, Inbox* inbox);
  void reference(const void* data, std::size_t size, Inbox* inbox);
  void obstacles(const void* data, std::size_t size, Inbox* inbox);
  void param(const void* data, std::size_t size, Inbox* inbox);
  void clock(const void* data, std::size_t size, Inbox* inbox);
  // Into inbox->map_buffer() (nothing when the inbox takes no maps). Allocates on the first
  // map with MapScratch::kNone.
  void local_map(const void* data, std::size_t size, Inbox* inbox);

 private:
  rt::Clock* recv_clock_;
  mppi_lcm::vehicle_state_t state_in_;
  mppi_lcm::reference_t reference_in_;
  mppi_lcm::obstacles_t obstacles_in_;
  mppi_lcm::param_update_t param_in_;
  mppi_lcm::sim_clock_t clock_in_;
  mppi_lcm::local_map_t map_in_;
};

}  // namespace mppi::transport
