// The checked decoder of bus bytes (mppi/transport/lcm_decode.hpp), with the inputs the
// fuzz targets found (test/fuzz/regressions/): a count in a message that its bytes do not
// back is undecodable, counted, and allocates nothing; it never throws out of the receive
// thread. And the count offsets the checks read, against the generated encoders.
#include <gtest/gtest.h>

#include <cmath>
#include <cstdint>
#include <cstring>
#include <fstream>
#include <iterator>
#include <string>
#include <vector>

#include "../rt/fakes.hpp"
#include "mppi/transport/lcm_decode.hpp"
#include "source_dir.hpp"

using namespace mppi;
using transport::decode_message;
namespace wire = transport::wire;

namespace {

template <class Msg>
std::vector<std::uint8_t> encode(const Msg& m) {
  std::vector<std::uint8_t> b(static_cast<std::size_t>(m.getEncodedSize()));
  EXPECT_EQ(m.encode(b.data(), 0, static_cast<int>(b.size())), static_cast<int>(b.size()));
  return b;
}

std::int64_t read_be(const std::vector<std::uint8_t>& b, std::size_t at, int bytes) {
  std::uint32_t u = 0;
  for (int i = 0; i < bytes; ++i) u = (u << 8) | b[at + static_cast<std::size_t>(i)];
  return bytes == 4 ? static_cast<std::int64_t>(static_cast<std::int32_t>(u))
                    : static_cast<std::int64_t>(static_cast<std::int16_t>(static_cast<std::uint16_t>(u)));
}

void write_be32(std::vector<std::uint8_t>* b, std::size_t at, std::uint32_t v) {
  for (int i = 0; i < 4; ++i) (*b)[at + static_cast<std::size_t>(i)] = static_cast<std::uint8_t>(v >> (24 - 8 * i));
}

mppi_lcm::vehicle_state_t state16(std::int64_t seq) {
  mppi_lcm::vehicle_state_t m{};
  m.utime = m.sample_utime = 1'000'000;
  m.seq = seq;
  m.model = 1;
  m.vehicle_count = 1;
  m.nx = 16;
  m.n = 16;
  m.x.assign(16, 0.5f);
  return m;
}

// A crash input the fuzzer saved, minus the target's trailing task byte where it has one.
std::vector<std::uint8_t> regression(const std::string& target, const std::string& name, bool task_byte) {
  std::ifstream in(mppi::testing::source_dir() + "/test/fuzz/regressions/" + target + "/" + name, std::ios::binary);
  std::vector<std::uint8_t> b((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  EXPECT_FALSE(b.empty()) << target << "/" << name;
  if (task_byte && !b.empty()) b.pop_back();
  return b;
}

struct Receiver {
  transport::Inbox::Expect expect() {
    transport::Inbox::Expect e;
    e.nx = 16;
    e.vehicles = 1;
    e.model = 1;
    return e;
  }
  test::FakeClock clock;
  transport::Inbox inbox{expect()};
  transport::LcmDecoder decoder{&clock};
  std::int64_t undecodable() const { return inbox.counters.rejected_undecodable.load(); }

  // A daemon fuzz target's crash regression through `decode`: its count field at `count_at`
  // reads `count`; decoding it throws nothing and counts one undecodable message.
  using Decode = void (transport::LcmDecoder::*)(const void*, std::size_t, transport::Inbox*);
  void regression_is_undecodable(Decode decode, const std::string& target, const std::string& name,
                                 std::size_t count_at, std::int64_t count) {
    const auto found = regression(target, name, true);
    EXPECT_EQ(read_be(found, count_at, 4), count);
    EXPECT_NO_THROW((decoder.*decode)(found.data(), found.size(), &inbox));
    EXPECT_EQ(undecodable(), 1);
  }
};

}  // namespace

TEST(LcmWire, CountOffsetsMatchTheGeneratedEncoders) {
  mppi_lcm::vehicle_state_t s = state16(1);
  s.n = 13;
  s.x.assign(13, 1.0f);
  EXPECT_EQ(read_be(encode(s), wire::kStateCount, 4), 13);

  mppi_lcm::command_t c{};
  c.n = 7;
  c.u.assign(7, 1.0f);
  EXPECT_EQ(read_be(encode(c), wire::kCommandCount, 4), 7);

  mppi_lcm::obstacles_t o{};
  o.n = 3;
  o.cylinders.resize(3);
  const auto ob = encode(o);
  EXPECT_EQ(read_be(ob, wire::kObstaclesCount, 4), 3);
  EXPECT_EQ(ob.size(), wire::kObstaclesCount + 4 + 3 * wire::kCylinderBytes);

  mppi_lcm::reference_t r{};
  r.vehicle_count = 5;
  r.goals.assign(5, std::vector<float>(3, 0.0f));
  const auto rb = encode(r);
  EXPECT_EQ(read_be(rb, wire::kReferenceCount, 2), 5);
  EXPECT_EQ(rb.size(), wire::kReferenceCount + 2 + 5 * 12 + wire::kReferenceTail);

  mppi_lcm::param_update_t p{};
  p.key = "cost.w_xy";
  const auto pb = encode(p);
  EXPECT_EQ(read_be(pb, wire::kParamKeyLength, 4), static_cast<std::int64_t>(p.key.size() + 1));

  mppi_lcm::local_map_t m{};
  m.n_cells = 6;
  m.distance_mm.assign(6, 1);
  const auto mb = encode(m);
  EXPECT_EQ(read_be(mb, wire::kLocalMapCount, 4), 6);
  EXPECT_EQ(mb.size(), wire::kLocalMapCount + 4 + 6 * sizeof(std::int16_t));
}

TEST(LcmDecode, ValidMessagesDecode) {
  const auto b = encode(state16(3));
  mppi_lcm::vehicle_state_t m{};
  ASSERT_TRUE(decode_message(b.data(), b.size(), &m));
  EXPECT_EQ(m.seq, 3);
  EXPECT_EQ(m.x.size(), 16u);
  // One byte short or one too many: undecodable.
  EXPECT_FALSE(decode_message(b.data(), b.size() - 1, &m));
  std::vector<std::uint8_t> longer = b;
  longer.push_back(0);
  EXPECT_FALSE(decode_message(longer.data(), longer.size(), &m));
  EXPECT_FALSE(decode_message(b.data(), 0, &m));
}

// Found by fuzz_state: n = 1040187397 in a 62-byte message made the generated decoder ask
// for 4 GB (x.resize(n) before the bytes are checked); n = -1 threw std::length_error out
// of the receive thread, which ends the daemon.
TEST(LcmDecode, StateCountTheBytesDoNotBackIsUndecodable) {
  Receiver r;
  r.regression_is_undecodable(&transport::LcmDecoder::state, "fuzz_state", "state_count_1040187397_asks_4GB",
                              wire::kStateCount, 1040187397);
  for (std::uint32_t n : {0xFFFFFFFFu, 0x80000000u, 0x7FFFFFFFu, 17u}) {
    auto b = encode(state16(1));
    write_be32(&b, wire::kStateCount, n);
    mppi_lcm::vehicle_state_t m{};
    EXPECT_NO_THROW(EXPECT_FALSE(decode_message(b.data(), b.size(), &m))) << n;
    EXPECT_LE(m.x.capacity(), 16u) << "allocated for a count the bytes do not back: " << n;
  }
  EXPECT_EQ(r.inbox.counters.states.load(), 0);
  // The receiver goes on: the next good state is taken.
  const auto good = encode(state16(2));
  r.decoder.state(good.data(), good.size(), &r.inbox);
  EXPECT_EQ(r.inbox.counters.states.load(), 1);
}

// Found by fuzz_obstacles: n = 1085276160 cylinders made the generated decoder value-
// initialise 21 GB before finding the bytes missing.
TEST(LcmDecode, ObstacleCountTheBytesDoNotBackIsUndecodable) {
  Receiver r;
  r.regression_is_undecodable(&transport::LcmDecoder::obstacles, "fuzz_obstacles",
                              "obstacles_count_1085276160_touches_21GB", wire::kObstaclesCount, 1085276160);
  EXPECT_EQ(r.inbox.obstacles.writes(), 0);
  // More than the daemon keeps, every byte there: decodable, refused as a bad input (as before).
  mppi_lcm::obstacles_t o{};
  o.n = transport::kMaxObstaclesIn + 1;
  o.cylinders.resize(static_cast<std::size_t>(o.n));
  const auto many = encode(o);
  r.decoder.obstacles(many.data(), many.size(), &r.inbox);
  EXPECT_EQ(r.undecodable(), 1);
  EXPECT_EQ(r.inbox.counters.rejected_inputs.load(), 1);
}

// Found by fuzz_params: a key length of 0 (it counts the NUL) made the generated decoder
// assign 2^64-1 characters: std::length_error out of the receive thread.
TEST(LcmDecode, ParamKeyLengthZeroOrNegativeIsUndecodable) {
  Receiver r;
  r.regression_is_undecodable(&transport::LcmDecoder::param, "fuzz_params", "param_key_length_0_throws",
                              wire::kParamKeyLength, 0);
  mppi_lcm::param_update_t p{};
  p.key = "cost.w_xy";
  p.value = 3.0;
  for (std::uint32_t len : {0u, 0xFFFFFFFFu, 0x80000000u, 1000u}) {
    auto b = encode(p);
    write_be32(&b, wire::kParamKeyLength, len);
    EXPECT_NO_THROW(r.decoder.param(b.data(), b.size(), &r.inbox)) << len;
  }
  EXPECT_EQ(r.undecodable(), 5);
  transport::ParamUpdate got;
  EXPECT_FALSE(r.inbox.params.pop(&got));
  const auto good = encode(p);
  r.decoder.param(good.data(), good.size(), &r.inbox);
  ASSERT_TRUE(r.inbox.params.pop(&got));
  EXPECT_STREQ(got.key, "cost.w_xy");
}

// Found by fuzz_sim_command: n < 0 in a command threw std::length_error out of the
// simulator's LCM handler.
TEST(LcmDecode, CommandNegativeCountIsUndecodable) {
  const auto found = regression("fuzz_sim_command", "command_negative_count_throws", false);
  EXPECT_LT(read_be(found, wire::kCommandCount, 4), 0);
  mppi_lcm::command_t m{};
  EXPECT_NO_THROW(EXPECT_FALSE(decode_message(found.data(), found.size(), &m)));
}

TEST(LcmDecode, ReferenceGoalCountTheBytesDoNotBackIsUndecodable) {
  mppi_lcm::reference_t r{};
  r.vehicle_count = 2;
  r.goals.assign(2, std::vector<float>(3, 1.0f));
  auto b = encode(r);
  mppi_lcm::reference_t m{};
  ASSERT_TRUE(decode_message(b.data(), b.size(), &m));
  for (std::uint16_t n : {std::uint16_t{0x7FFF}, std::uint16_t{0xFFFF}, std::uint16_t{3}}) {
    b[wire::kReferenceCount] = static_cast<std::uint8_t>(n >> 8);
    b[wire::kReferenceCount + 1] = static_cast<std::uint8_t>(n & 0xFF);
    m = mppi_lcm::reference_t{};
    EXPECT_FALSE(decode_message(b.data(), b.size(), &m)) << n;
    EXPECT_LE(m.goals.capacity(), 2u) << n;
  }
}
