// systemd notifications (READY=1, WATCHDOG=1, STATUS=, STOPPING=1). Without libsystemd at
// build time, or outside a unit (no NOTIFY_SOCKET), every call is a no-op.
#pragma once

#include <cstdint>
#include <string>

namespace mppi::daemon {

class Notifier {
 public:
  Notifier();
  bool under_systemd() const { return active_; }
  // The watchdog interval systemd expects pings within, 0 when there is no watchdog.
  std::int64_t watchdog_ns() const { return watchdog_ns_; }
  void ready(const std::string& status);
  void watchdog();
  void status(const std::string& status);
  void stopping();

 private:
  bool active_ = false;
  std::int64_t watchdog_ns_ = 0;
};

}  // namespace mppi::daemon
