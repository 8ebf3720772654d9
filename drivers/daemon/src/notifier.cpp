#include "mppi/daemon/notifier.hpp"

#include <cstdint>
#include <cstdlib>

#ifdef MPPID_HAVE_SYSTEMD
#include <systemd/sd-daemon.h>
#endif

namespace mppi::daemon {

#ifdef MPPID_HAVE_SYSTEMD
Notifier::Notifier() {
  active_ = std::getenv("NOTIFY_SOCKET") != nullptr;
  std::uint64_t usec = 0;
  if (sd_watchdog_enabled(0, &usec) > 0) watchdog_ns_ = static_cast<std::int64_t>(usec) * 1000;
}
void Notifier::ready(const std::string& s) {
  if (active_) sd_notifyf(0, "READY=1\nSTATUS=%s", s.c_str());
}
void Notifier::watchdog() {
  if (active_) sd_notify(0, "WATCHDOG=1");
}
void Notifier::status(const std::string& s) {
  if (active_) sd_notifyf(0, "STATUS=%s", s.c_str());
}
void Notifier::stopping() {
  if (active_) sd_notify(0, "STOPPING=1");
}
#else
Notifier::Notifier() = default;
void Notifier::ready(const std::string&) {}
void Notifier::watchdog() {}
void Notifier::status(const std::string&) {}
void Notifier::stopping() {}
#endif

}  // namespace mppi::daemon
