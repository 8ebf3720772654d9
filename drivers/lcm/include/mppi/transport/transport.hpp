// The daemon's transport seam: receive on the transport's own thread into an Inbox,
// publish commands, status and plans from the loop thread. LCM implements it (udpm for
// flight, memq:// for in-process tests); tests also use a recording fake.
#pragma once

#include <string>

#include "mppi/transport/inbox.hpp"
#include "mppi/transport/messages.hpp"

namespace mppi::transport {

class Transport {
 public:
  virtual ~Transport() = default;
  // A loopback check before the service reports ready: "" when the transport works, else
  // why not.
  virtual std::string self_test() = 0;
  // Starts the receive thread, which fills `inbox` until stop().
  virtual void start(Inbox* inbox) = 0;
  // Returns within the receive timeout (it never blocks on a quiet bus).
  virtual void stop() = 0;

  // Loop thread. False when the message could not be sent.
  virtual bool publish_command(const Command& c) = 0;
  virtual bool publish_status(const StatusReport& s) = 0;
  virtual bool publish_plan(const PlanView& p) = 0;
  // A display sample of a cycle's rollouts (off unless daemon.rollouts.hz > 0).
  virtual bool publish_rollouts(const RolloutsView& r) {
    (void)r;
    return false;
  }
  // The answer to a parameter update (loop thread, between cycles).
  virtual bool publish_param_result(const ParamResult& r) {
    (void)r;
    return false;
  }
};

}  // namespace mppi::transport
