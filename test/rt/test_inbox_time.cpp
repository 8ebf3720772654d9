// Timestamps the inbox takes: the loop turns sample, tick and reference times from us into
// ns and subtracts them, so a time outside [0, kMaxUtime] is refused and counted before it
// reaches the loop. fuzz_clock found a sim_clock_t whose sim_utime overflowed int64 in the
// lock-step cycle (sim_utime * 1000, undefined behaviour): test/fuzz/regressions/fuzz_clock.
#include <gtest/gtest.h>

#include <atomic>
#include <cstdint>
#include <fstream>
#include <iterator>
#include <string>
#include <vector>

#include "fakes.hpp"
#include "mppi/daemon/control_loop.hpp"
#include "mppi/transport/lcm_decode.hpp"
#include "source_dir.hpp"

using namespace mppi;
using transport::kMaxUtime;
using transport::Reject;

namespace {

transport::Inbox::Expect expect16(bool tick_on_state = false) {
  transport::Inbox::Expect e;
  e.nx = 16;
  e.vehicles = 1;
  e.model = 1;
  e.tick_on_state = tick_on_state;
  return e;
}

Reject offer(transport::Inbox* in, std::int64_t seq, std::int64_t sample_utime) {
  auto& s = in->state_buffer();
  mppi::test::shape_state(s, seq);
  s.sample_utime = sample_utime;
  for (int i = 0; i < 16; ++i) s.x[i] = 1.0f;
  return in->offer_state();
}

}  // namespace

TEST(InboxTime, StateSampleTimeOutsideTheRangeIsRejectedAndCounted) {
  transport::Inbox in(expect16(/*tick_on_state=*/true));
  EXPECT_EQ(offer(&in, 1, -1), Reject::kTime);
  EXPECT_EQ(offer(&in, 2, kMaxUtime + 1), Reject::kTime);
  EXPECT_EQ(offer(&in, 3, INT64_MAX), Reject::kTime);
  EXPECT_EQ(in.counters.rejected_time.load(), 3);
  EXPECT_EQ(in.counters.ticks.load(), 0);  // a refused state is no tick either
  EXPECT_EQ(offer(&in, 4, 0), Reject::kNone);
  EXPECT_EQ(offer(&in, 5, kMaxUtime), Reject::kNone);
  EXPECT_EQ(in.counters.states.load(), 2);
  EXPECT_EQ(in.counters.ticks.load(), 2);
}

TEST(InboxTime, ReferenceEpochOutsideTheRangeIsABadInput) {
  transport::Inbox in(expect16());
  for (std::int64_t t0 : {std::int64_t{-5}, kMaxUtime + 1}) {
    in.reference_buffer() = transport::ReferenceInput{};
    in.reference_buffer().t0_utime = t0;
    in.offer_reference();
  }
  EXPECT_EQ(in.counters.rejected_inputs.load(), 2);
  EXPECT_EQ(in.reference.writes(), 0);
  in.reference_buffer().t0_utime = 1'000'000;
  in.offer_reference();
  EXPECT_EQ(in.reference.writes(), 1);
}

// The input fuzz_clock found, through the decoder and the lock-step loop: the tick is
// refused and counted, no cycle runs on it (and nothing overflows under UBSan); a tick in
// range then runs one.
TEST(InboxTime, ClockTickThatWouldOverflowTheLoopIsRejected) {
  std::ifstream f(mppi::testing::source_dir() + "/test/fuzz/regressions/fuzz_clock/tick_sim_utime_overflows_ns",
                  std::ios::binary);
  std::vector<std::uint8_t> bytes((std::istreambuf_iterator<char>(f)), std::istreambuf_iterator<char>());
  ASSERT_FALSE(bytes.empty());
  bytes.pop_back();  // the fuzz target's task byte
  mppi_lcm::sim_clock_t tick{};
  ASSERT_TRUE(transport::decode_message(bytes.data(), bytes.size(), &tick));
  EXPECT_GT(tick.sim_utime, kMaxUtime);

  test::FakeClock clock;
  test::FakeController ctl(&clock);
  test::RecordingTransport tx;
  transport::Inbox in(expect16());
  daemon::LoopSettings ls;
  ls.lockstep = true;
  daemon::ControlLoop loop(&ctl, &clock, &tx, &in, ls);
  transport::LcmDecoder decoder(&clock);
  ASSERT_EQ(offer(&in, 1, 1'000'000), Reject::kNone);
  decoder.clock(bytes.data(), bytes.size(), &in);
  EXPECT_EQ(in.counters.ticks_rejected.load(), 1);
  const std::atomic<bool> stop{true};
  EXPECT_FALSE(loop.step_lockstep(stop));
  EXPECT_TRUE(tx.commands.empty());

  transport::ClockTick ok;
  ok.seq = 2;
  ok.sim_utime = 1'000'000;
  in.offer_tick(ok);
  EXPECT_TRUE(loop.step_lockstep(stop));
  ASSERT_EQ(tx.commands.size(), 1u);
  EXPECT_EQ(tx.commands[0].mode, transport::Mode::kNormal);
}
