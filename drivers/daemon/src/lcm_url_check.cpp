#include "mppi/daemon/lcm_url_check.hpp"

#include <algorithm>
#include <cstdlib>

namespace mppi::daemon {
namespace {

// The value of `key` in LCM's "?a=1&b=2" options, "" when absent.
std::string option(const std::string& opts, const std::string& key) {
  std::size_t at = 0;
  while (at <= opts.size()) {
    const std::size_t end = std::min(opts.find('&', at), opts.size());
    const std::string kv = opts.substr(at, end - at);
    const std::size_t eq = kv.find('=');
    if (kv.substr(0, eq) == key) return eq == std::string::npos ? std::string() : kv.substr(eq + 1);
    at = end + 1;
  }
  return {};
}

bool loopback_host(const std::string& host) {
  return host == "localhost" || host == "::1" || host == "[::1]" || host.rfind("127.", 0) == 0;
}

}  // namespace

std::string with_map_receive_buffer(const std::string& url) {
  const std::size_t sep = url.find("://");
  if (sep == std::string::npos) return url;
  const std::string provider = url.substr(0, sep);
  if (provider != "udpm" && provider != "mpudpm") return url;
  const std::size_t q = url.find('?');
  if (q != std::string::npos && !option(url.substr(q + 1), "recv_buf_size").empty()) return url;
  return url + (q == std::string::npos ? "?" : "&") + "recv_buf_size=" + std::to_string(kMapReceiveBufferBytes);
}

std::string map_receive_buffer_warning(const std::string& url, long rmem_max) {
  const std::size_t q = url.find('?');
  if (q == std::string::npos || rmem_max <= 0) return {};
  const std::string asked = option(url.substr(q + 1), "recv_buf_size");
  const long bytes = asked.empty() ? 0 : std::strtol(asked.c_str(), nullptr, 10);
  if (bytes <= rmem_max) return {};
  return "the socket receive buffer is capped at net.core.rmem_max = " + std::to_string(rmem_max) + " bytes, below the " +
         std::to_string(bytes) + " asked: large local maps may be dropped (sysctl -w net.core.rmem_max=" +
         std::to_string(bytes) + ")";
}

namespace {
// udpm/mpudpm: a ttl above 0 sends the datagrams past this host.
std::string udpm_leaves_host(const std::string& opts) {
  const std::string ttl = option(opts, "ttl");
  if (ttl.empty()) return {};  // LCM's default ttl is 0
  char* end = nullptr;
  const long v = std::strtol(ttl.c_str(), &end, 10);
  if (end == ttl.c_str() || *end != '\0' || v < 0) return "ttl=" + ttl + " is not a number: cannot tell";
  if (v == 0) return {};
  return "ttl=" + ttl + ": multicast datagrams leave this host (routers forward them up to " + ttl +
         " hops); every state and command is on the network. Use ttl=0 to keep the bus on the host";
}

// tcpq: a host other than the loopback is another machine.
std::string tcpq_leaves_host(const std::string& address) {
  const std::size_t colon = address.rfind(':');
  const std::string host = colon == std::string::npos ? address : address.substr(0, colon);
  if (loopback_host(host)) return {};
  return "tcpq to " + (host.empty() ? std::string("(no host)") : host) +
         ": the bus goes over the network to another machine";
}
}  // namespace

std::string lcm_url_leaves_host(const std::string& url) {
  const std::size_t sep = url.find("://");
  if (sep == std::string::npos) return "not provider://address: cannot tell where it sends";
  const std::string provider = url.substr(0, sep);
  const std::string rest = url.substr(sep + 3);
  const std::size_t q = rest.find('?');
  const std::string address = rest.substr(0, q);
  const std::string opts = q == std::string::npos ? std::string() : rest.substr(q + 1);

  if (provider == "memq") return {};  // inside this process
  if (provider == "file") return {};  // a log file
  if (provider == "udpm" || provider == "mpudpm") return udpm_leaves_host(opts);
  if (provider == "tcpq") return tcpq_leaves_host(address);
  return "unknown LCM provider '" + provider + "': cannot tell whether traffic leaves this host";
}

}  // namespace mppi::daemon
