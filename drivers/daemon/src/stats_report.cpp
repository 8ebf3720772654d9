#include "mppi/daemon/stats_report.hpp"

#include <cstdint>
#include <spdlog/fmt/fmt.h>

namespace mppi::daemon {

namespace {
std::string line(const char* name, const rt::DurationSummary& d) {
  return fmt::format("  {:<24} n={:<7} min={:.3f} mean={:.3f} p99={:.3f} max={:.3f} ms\n", name, d.count, d.min_ms,
                     d.mean_ms, d.p99_ms, d.max_ms);
}
std::string json(const char* name, const rt::DurationSummary& d) {
  return fmt::format("\"{}\":{{\"n\":{},\"min_ms\":{:.4f},\"mean_ms\":{:.4f},\"p99_ms\":{:.4f},\"max_ms\":{:.4f}}}", name,
                     d.count, d.min_ms, d.mean_ms, d.p99_ms, d.max_ms);
}

// The report for people: one line per kind of count.
std::string text_stats(const RunFacts& f, const ControlLoop& loop, const transport::InboxCounters& in) {
  const rt::TimingSummary t = loop.timing_total();
  const LoopCounters& c = loop.counters();
  auto v = [](const std::atomic<std::int64_t>& a) { return a.load(); };
  std::string out = fmt::format(
      "mppid stats: task={} backend={} K={} T={} rate={} Hz {} {} run={:.1f} s\n", f.task, f.backend, f.rollouts,
      f.horizon, f.rate_hz, f.lockstep ? "lock-step" : "real-time clock", f.realtime ? "SCHED_FIFO" : "SCHED_OTHER",
      f.seconds);
  out += fmt::format("  cycles={} misses={} (late start {}) max_consecutive_misses={} skipped_periods={}\n", t.cycles,
                     t.misses, t.late_start_misses, t.max_consecutive_misses, loop.skipped_periods());
  out += line("compute", t.compute);
  out += line("period", t.period);
  out += line("jitter |period-nominal|", t.jitter);
  out += line("state sampled -> command-out", t.latency);
  out += line("state age at cycle start", t.age);
  out += line("lead (sample -> expected actuation)", t.lead);
  out += line("optimizer update", t.optimize);
  if (loop.settings().trigger == Trigger::kState) out += line("state in -> its cycle's start", t.wake);
  out += fmt::format("  latency expected={:.3f} ms (estimator rejected {}), future states={}, plan skips={}, "
                     "repeated ticks={}\n",
                     static_cast<double>(loop.latency_estimate_ns()) * 1e-6, v(c.latency_rejected), v(c.future_states),
                     v(c.plan_skips), v(c.repeated_ticks));
  if (loop.settings().trigger == Trigger::kState)
    out += fmt::format("  trigger state: cycles started by a state={}, by the grace running out={}\n",
                       v(c.state_triggered), v(c.clock_triggered));
  if (v(c.holds_without_goal) > 0) out += "  held where the first state was until a goal or reference came\n";
  out += fmt::format("  actuation delay flown with at the end={:.1f} ms\n", static_cast<double>(v(c.actuation_delay_ns)) * 1e-6);
  out += fmt::format("  commands normal={} hold_plan={} failsafe={} blocked={} send_failures={} (failsafe entries {})\n",
                     v(c.commands_normal), v(c.commands_hold), v(c.commands_failsafe), v(c.commands_blocked),
                     v(c.publish_failures), v(c.failsafe_entries));
  out += fmt::format(
      "  optimizer nonfinite={} errors={} gate_rejects={} late_holds={} stale_cycles={} guard takeovers={} "
      "commands={} anytime partial_updates={} holds={}\n",
      v(c.optimizer_nonfinite), v(c.optimizer_errors), v(c.gate_rejects), v(c.late_holds), v(c.stale_cycles),
      v(c.guard_takeovers), v(c.guard_commands), v(c.partial_updates), v(c.anytime_holds));
  out += fmt::format(
      "  states accepted={} rejected: nan={} duplicate={} out_of_order={} shape={} time={} undecodable={} inputs={}"
      " (ticks rejected={})\n",
      v(in.states), v(in.rejected_nan), v(in.rejected_duplicate), v(in.rejected_out_of_order), v(in.rejected_shape),
      v(in.rejected_time), v(in.rejected_undecodable), v(in.rejected_inputs), v(in.ticks_rejected));
  if (v(in.maps) + in.maps_rejected() > 0)
    out += fmt::format("  maps accepted={} rejected: invalid={} out_of_order={} stale={} time={} undecodable={};"
                       " cycles with a stale map={}\n",
                       v(in.maps), v(in.maps_rejected_invalid), v(in.maps_rejected_out_of_order),
                       v(in.maps_rejected_stale), v(in.maps_rejected_time), v(in.maps_undecodable),
                       v(c.map_stale_cycles));
  out += fmt::format("  params applied={} rejected={} dropped={}  status={} plans={}\n", v(c.params_applied),
                     v(c.params_rejected), v(in.params_dropped), v(c.status_published), v(c.plans_published));
  out += fmt::format("  rss start={} kB end={} kB\n", f.rss_start_kb, f.rss_end_kb);
  return out;
}

// The same for tools: one JSON object on a line of its own.
std::string json_stats(const RunFacts& f, const ControlLoop& loop, const transport::InboxCounters& in) {
  const rt::TimingSummary t = loop.timing_total();
  const LoopCounters& c = loop.counters();
  auto v = [](const std::atomic<std::int64_t>& a) { return a.load(); };
  std::string out = "mppid-stats {";
  out += fmt::format(
      "\"task\":\"{}\",\"backend\":\"{}\",\"rollouts\":{},\"horizon\":{},\"rate_hz\":{},\"seconds\":{:.3f},"
      "\"lockstep\":{},\"realtime\":{},\"cycles\":{},\"misses\":{},\"late_start_misses\":{},"
      "\"max_consecutive_misses\":{},\"skipped_periods\":{},",
      f.task, f.backend, f.rollouts, f.horizon, f.rate_hz, f.seconds, f.lockstep, f.realtime, t.cycles, t.misses,
      t.late_start_misses, t.max_consecutive_misses, loop.skipped_periods());
  out += json("compute", t.compute) + "," + json("period", t.period) + "," + json("jitter", t.jitter) + "," +
         json("latency", t.latency) + "," + json("age", t.age) + "," + json("lead", t.lead) + "," +
         json("optimize", t.optimize) + "," + json("wake", t.wake) + ",";
  out += fmt::format("\"latency_expected_ms\":{:.3f},\"future_states\":{},\"plan_skips\":{},\"repeated_ticks\":{},",
                     static_cast<double>(loop.latency_estimate_ns()) * 1e-6, v(c.future_states), v(c.plan_skips),
                     v(c.repeated_ticks));
  out += fmt::format(
      "\"commands_normal\":{},\"commands_hold\":{},\"commands_failsafe\":{},\"commands_blocked\":{},"
      "\"optimizer_nonfinite\":{},\"optimizer_errors\":{},\"late_holds\":{},\"stale_cycles\":{},"
      "\"guard_takeovers\":{},\"guard_commands\":{},\"partial_updates\":{},\"anytime_holds\":{},"
      "\"states\":{},\"rejected_nan\":{},\"rejected_duplicate\":{},\"rejected_out_of_order\":{},"
      "\"rejected_shape\":{},\"rejected_time\":{},\"rejected_undecodable\":{},\"params_applied\":{},"
      "\"params_rejected\":{},\"held_without_goal\":{},\"trigger\":\"{}\",\"state_triggered\":{},\"clock_triggered\":{},"
      "\"maps\":{},\"maps_rejected\":{},\"map_stale_cycles\":{},\"rss_start_kb\":{},\"rss_end_kb\":{}}}\n",
      v(c.commands_normal), v(c.commands_hold), v(c.commands_failsafe), v(c.commands_blocked),
      v(c.optimizer_nonfinite), v(c.optimizer_errors), v(c.late_holds), v(c.stale_cycles),
      v(c.guard_takeovers), v(c.guard_commands), v(c.partial_updates), v(c.anytime_holds), v(in.states),
      v(in.rejected_nan), v(in.rejected_duplicate), v(in.rejected_out_of_order), v(in.rejected_shape),
      v(in.rejected_time), v(in.rejected_undecodable), v(c.params_applied), v(c.params_rejected),
      v(c.holds_without_goal), loop.settings().trigger == Trigger::kState ? "state" : "clock", v(c.state_triggered), v(c.clock_triggered), v(in.maps), in.maps_rejected(), v(c.map_stale_cycles),
      f.rss_start_kb, f.rss_end_kb);
  return out;
}
}  // namespace

std::string format_stats(const RunFacts& f, const ControlLoop& loop, const transport::InboxCounters& in) {
  return text_stats(f, loop, in) + json_stats(f, loop, in);
}

}  // namespace mppi::daemon
