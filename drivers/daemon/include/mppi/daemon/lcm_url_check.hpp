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

// A local map at capacity (DistanceField::kMaxCells int16, 2 MiB) arrives in ~33 UDP fragments;
// the kernel's default socket receive buffer (net.core.rmem_default, ~208 KiB) drops it whole
// (measured: 0 of 10 1.6 MB messages through udpm on one host; 10 of 10 with 4 MiB). The URL a
// daemon that takes maps opens: udpm/mpudpm with recv_buf_size=kMapReceiveBufferBytes added
// unless the URL sets one; any other URL as it is. The kernel grants at most
// net.core.rmem_max (map_receive_buffer_warning says when that is less).
constexpr int kMapReceiveBufferBytes = 4 << 20;  // two maps at capacity
std::string with_map_receive_buffer(const std::string& url);
// "" when the buffer `url` asks for (recv_buf_size) fits under rmem_max bytes (the content
// of /proc/sys/net/core/rmem_max; <= 0: unknown), else why maps may be dropped.
std::string map_receive_buffer_warning(const std::string& url, long rmem_max);

}  // namespace mppi::daemon
