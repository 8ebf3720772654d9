// Transport over LCM: receive threads running handleTimeout (so stop() returns on a quiet
// bus), raw subscriptions decoded by LcmDecoder (so garbage and wrong types are counted, not
// printed and dropped), encoding into buffers sized once. Local maps (~1-2 MB, 10 Hz) come in
// on a second LCM instance on the same URL with a receive thread of its own: a state never
// waits behind a map's decode and copy on the states' thread (docs/sensing.md).
#pragma once

#include <lcm/lcm-cpp.hpp>

#include <atomic>
#include <cstdint>
#include <memory>
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

  // A loopback on a probe instance of the URL, and on the maps' instance once it is open.
  std::string self_test() override;
  // Subscribes and starts the receive thread(s); returns once subscribed. With an inbox that
  // takes maps, the maps' instance is opened first if it is not yet (std::runtime_error when
  // it cannot be). LCM's udpm reads each instance's socket on a thread of its own, started at
  // the instance's first subscription with the policy of the thread that subscribes: the
  // states' instance subscribes from the receive thread, after its SCHED_FIFO, so no state
  // waits in the socket for a time-shared thread behind the optimizer's workers.
  void start(Inbox* inbox) override;
  // Before start(): run the receive thread SCHED_FIFO at this priority (0: inherit), so
  // states and ticks are taken in as they arrive even while the optimizer fills the cores.
  // A refusal leaves it at its policy; receive_priority_ok() says which happened.
  void set_receive_fifo_priority(int priority) { receive_fifo_ = priority; }
  bool receive_priority_ok() const { return receive_fifo_ok_.load(); }
  // Before start(): the receive thread polls the socket (handleTimeout(0) in a loop) instead of
  // sleeping in it: a busy core, no wake-up between a datagram and its decode.
  void set_receive_spin(bool spin) { receive_spin_ = spin; }

  // Where local maps are received (before start()). kOwnThread (default): on the maps'
  // instance, by a thread of its own that keeps the policy of the thread calling start() (a
  // decode at SCHED_FIFO would hold the optimizer off; a map waits for an idle core instead),
  // and the states' instance never subscribes to them. kStateThread: on the states' instance
  // and thread, one FIFO in the order published (the replay, which needs that order).
  enum class MapThread { kOwnThread, kStateThread };
  void set_map_thread(MapThread m) { map_thread_ = m; }
  // Opens the maps' instance now (kOwnThread; std::runtime_error when the URL cannot be
  // opened), so self_test() checks it before the service reports ready.
  void open_map_receiver();
  // The instance maps are received on: the maps' once open (kOwnThread), else the states'.
  // Tests over memq:// publish maps on it (each memq:// instance is a queue of its own).
  lcm::LCM& map_lcm() { return map_lcm_ ? *map_lcm_ : lcm_; }
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
  void subscribe_maps();
  void subscribe_states();
  void receive(lcm::LCM* lcm, int timeout_ms);

  lcm::LCM lcm_;
  std::string url_;
  LcmChannels ch_;
  rt::Clock* recv_clock_;
  int timeout_ms_;
  Inbox* inbox_ = nullptr;
  std::thread thread_;
  int receive_fifo_ = 0;
  bool receive_spin_ = false;
  std::atomic<bool> receive_fifo_ok_{false};
  std::atomic<bool> running_{false};

  LcmDecoder decoder_;  // states' thread: states, references, obstacles, parameters, ticks

  // Local maps: their instance and thread (kOwnThread), and their decoder (2 MiB of scratch,
  // made only when the inbox takes maps), used by whichever thread receives them.
  MapThread map_thread_ = MapThread::kOwnThread;
  std::unique_ptr<lcm::LCM> map_lcm_;
  std::thread map_receiver_;
  std::unique_ptr<LcmDecoder> map_decoder_;

  // Loop-thread scratch.
  mppi_lcm::command_t command_out_;
  mppi_lcm::controller_status_t status_out_;
  mppi_lcm::plan_t plan_out_;
  mppi_lcm::rollouts_t rollouts_out_{};
  mppi_lcm::param_result_t param_result_out_{};
  std::vector<std::uint8_t> buf_;
};

}  // namespace mppi::transport
