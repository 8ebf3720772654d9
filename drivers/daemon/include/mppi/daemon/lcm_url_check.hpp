// Whether the daemon's LCM bus can leave this machine. The shipped URLs keep it on the
// host (udpm with ttl=0: multicast that no router forwards); a URL that would not is
// legal, and mppid runs with it, but warns at start with this reason.
#pragma once

#include <string>

namespace mppi::daemon {

// "" when traffic on `url` stays on this host (udpm/mpudpm with ttl=0, which is also LCM's
// default ttl; memq://; file://; tcpq:// to a loopback address); otherwise why it leaves,
// or why that cannot be told, in words.
std::string lcm_url_leaves_host(const std::string& url);

}  // namespace mppi::daemon
