// The --stats summary printed on exit: a human block and one `mppid-stats {json}` line
// that tools (daemon bench, tests) parse.
#pragma once

#include <string>

#include "mppi/daemon/control_loop.hpp"
#include "mppi/transport/inbox.hpp"

namespace mppi::daemon {

struct RunFacts {
  std::string task, backend;
  int rollouts = 0, horizon = 0;
  double rate_hz = 0.0, seconds = 0.0;
  bool lockstep = false, realtime = false;
  long rss_start_kb = -1, rss_end_kb = -1;
};

std::string format_stats(const RunFacts& f, const ControlLoop& loop, const transport::InboxCounters& in);

}  // namespace mppi::daemon
