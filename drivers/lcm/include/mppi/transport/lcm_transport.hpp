// Transport over LCM: one receive thread running handleTimeout (so stop() returns on a
// quiet bus), raw subscriptions decoded by LcmDecoder (so garbage and wrong types are
// counted, not printed and dropped), encoding into buffers sized once.
#pragma once

#include <lcm/lcm-cpp.hpp>

#include <atomic>
#include <cstdint>
#include <string>
#include <thread>
#include <vector>

#include "mppi/rt/clock.hpp"
#include "mppi/transport/lcm_decode.hpp"
#include "mppi/transport/transport.hpp"
#include "mppi_lcm/command_t.hpp"
#include "mppi_lcm/controller_status_t.hpp"
#include "mppi_lcm/obstacles_t.hpp"
#include "mppi_lcm/param_result_t.hpp"
#include "mppi_lcm/param_update_t.hpp"
#include "mppi_lcm/plan_t.hpp"
#include "mppi_lcm/reference_t.hpp"
#include "mppi_lcm/rollouts_t.hpp"
#include "mppi_lcm/sim_clock_t.hpp"
#include "mppi_lcm/vehicle_state_t.hpp"

namespace mppi::transport {

struct LcmChannels {
  std::string state = "MPPI_STATE";
  std::string command = "MPPI_COMMAND";
  std::string status = "MPPI_STATUS";
  std::string plan = "MPPI_PLAN";
  std::string reference = "MPPI_REFERENCE";
  std::string obstacles = "MPPI_OBSTACLES";
  std::string params = "MPPI_PARAMS";
  std::string param_result = "MPPI_PARAM_RESULT";
  std::string clock = "MPPI_SIM_CLOCK";
  std::string rollouts = "MPPI_ROLLOUTS";
  std::string local_map = "MPPI_LOCAL_MAP";  // local_map_t in (forest tasks)
};

class LcmTransport final : public Transport {
 public:
  // Throws std::runtime_error when the URL cannot be opened. recv_clock stamps arrivals
  // (StateSample::recv_ns); max_plan_floats sizes the plan buffer once.
  LcmTransport(const std::string& url, LcmChannels channels, rt::Clock* recv_clock, int max_plan_floats,
               int receive_timeout_ms = 20);
  ~LcmTransport() override;

  std::string self_test() override;
  void start(Inbox* inbox) override;
  // Before start(): run the receive thread SCHED_FIFO at this priority (0: inherit), so
  // states and ticks are taken in as they arrive even while the optimizer fills the cores.
  // A refusal leaves it at its policy; receive_priority_ok() says which happened.
  void set_receive_fifo_priority(int priority) { receive_fifo_ = priority; }
  bool receive_priority_ok() const { return receive_fifo_ok_.load(); }
  // Before start(): the receive thread polls the socket (handleTimeout(0) in a loop) instead of
  // sleeping in it: a busy core, no wake-up between a datagram and its decode.
  void set_receive_spin(bool spin) { receive_spin_ = spin; }
  void stop() override;
  bool publish_command(const Command& c) override;
  bool publish_status(const StatusReport& s) override;
  bool publish_plan(const PlanView& p) override;
  // Before the loop runs: room for rollouts_t messages of up to `rollouts` rollouts with
  // `floats` position floats (publish_rollouts refuses larger ones; it never grows).
  void reserve_rollouts(int rollouts, int floats);
  bool publish_rollouts(const RolloutsView& r) override;
  bool publish_param_result(const ParamResult& r) override;

  lcm::LCM& lcm() { return lcm_; }

 private:
  void on_state(const lcm::ReceiveBuffer* rb, const std::string& channel);
  void on_reference(const lcm::ReceiveBuffer* rb, const std::string& channel);
  void on_obstacles(const lcm::ReceiveBuffer* rb, const std::string& channel);
  void on_param(const lcm::ReceiveBuffer* rb, const std::string& channel);
  void on_clock(const lcm::ReceiveBuffer* rb, const std::string& channel);
  void on_local_map(const lcm::ReceiveBuffer* rb, const std::string& channel);
  template <class Msg>
  bool send(const std::string& channel, const Msg& msg);

  lcm::LCM lcm_;
  std::string url_;
  LcmChannels ch_;
  int timeout_ms_;
  Inbox* inbox_ = nullptr;
  std::thread thread_;
  int receive_fifo_ = 0;
  bool receive_spin_ = false;
  std::atomic<bool> receive_fifo_ok_{false};
  std::atomic<bool> running_{false};

  LcmDecoder decoder_;  // receive thread

  // Loop-thread scratch.
  mppi_lcm::command_t command_out_;
  mppi_lcm::controller_status_t status_out_;
  mppi_lcm::plan_t plan_out_;
  mppi_lcm::rollouts_t rollouts_out_{};
  mppi_lcm::param_result_t param_result_out_{};
  std::vector<std::uint8_t> buf_;
};

}  // namespace mppi::transport
