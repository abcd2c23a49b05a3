// chaincompd's LCM side: subscribes to commands and control, publishes corrected targets and
// status. Start-up allocates; handling messages does not. Built for one lcm_t per node.
#pragma once

#include <lcm/lcm.h>

#include <chrono>
#include <memory>
#include <string>
#include <vector>

#include "chaincomp/compensator.hpp"
#include "chaincomp/daemon_config.hpp"
#include "chaincomp/latency.hpp"
#include "chaincomp_lcm/lcmt_axis_command.hpp"
#include "chaincomp_lcm/lcmt_chaincomp_control.hpp"
#include "chaincomp_lcm/lcmt_chaincomp_status.hpp"
#include "chaincomp_lcm/lcmt_corrected_target.hpp"
#include "chaincomp/params_update.hpp"
#include "chaincomp/thermal.hpp"

namespace chaincomp {

// A command payload into `out` (decoded through `scratch`, whose storage is reused);
// false for anything lcm-gen's decoder must not see or cannot decode.
bool decode_command(const void* data, std::size_t size, chaincomp_lcm::lcmt_axis_command& scratch,
                    Command& out) noexcept;
// A target into its message (compute_ns left to the caller).
void to_message(const Target& t, chaincomp_lcm::lcmt_corrected_target& msg) noexcept;
// A control payload into `out`; false for anything not one of this version (trailing bytes
// included: one rule with commands, updates and readings).
bool decode_control(const void* data, std::size_t size, chaincomp_lcm::lcmt_chaincomp_control& out) noexcept;
// A decoded control message applied, by the daemon and by replay alike: `enable` always; a
// reset starts a new stream on every input (commands, and the updater's and the thermal
// model's when given).
void apply_control(const chaincomp_lcm::lcmt_chaincomp_control& c, Compensator& comp, ParamsUpdater* updater,
                   ThermalState* thermal) noexcept;
// The regular expression LCM's subscribe takes that matches exactly the channel `name`.
std::string channel_regex(const std::string& name);

struct RealtimeObtained {
  bool mlockall = false, sched_fifo = false, cpu_pinned = false;
};

class LcmNode {
 public:
  // `model` filled by entry.prepare(); `lcm`, `entry` and `model` outlive the node.
  LcmNode(lcm_t* lcm, const ModelEntry& entry, const void* model, const DaemonConfig& config,
          const std::string& params_file, const std::string& params_hash, RealtimeObtained rt);
  ~LcmNode();
  LcmNode(const LcmNode&) = delete;
  LcmNode& operator=(const LcmNode&) = delete;

  void publish_status(bool final);
  const chaincomp_lcm::lcmt_chaincomp_status& last_status() const { return status_msg_; }  // as last published
  // Take lcmt_params_update on the params channel and apply them through `updater` (which
  // changes the model this node compensates with); it outlives the node.
  void accept_params_updates(ParamsUpdater& updater);
  // Take lcmt_temperatures on the temperatures channel into `thermal` and apply the error
  // values it gives through the updater (accept_params_updates first); it outlives the node.
  void accept_temperatures(ThermalState& thermal);
  const Counters& counters() const { return comp_.counters(); }
  std::int64_t instance_id() const { return instance_id_; }
  // Datagrams the kernel dropped at the process's UDP sockets (-1: none), and the receive
  // buffer of the one LCM receives on (-1: none), as SO_MEMINFO and SO_RCVBUF report them.
  std::int64_t kernel_drops() const;
  std::int64_t recv_buf_bytes() const { return recv_buf_bytes_; }

  // The longest machine name a command may carry (lcm-gen's decoder trusts the length).
  static constexpr int kMaxMachineName = 255;
  // LCM's user-space queue of each subscription (messages; LCM's default is 30): what may wait
  // while the loop is busy, one second of commands at 10 kHz. LCM discards what arrives at a
  // full queue without counting it: a queue found full is counted (docs/guide/daemon.md).
  static constexpr int kQueueCapacity = 10000;         // commands, params updates, readings, targets
  static constexpr int kControlQueueCapacity = 1000;   // control messages

 private:
  static void on_command(const lcm_recv_buf_t* rbuf, const char* channel, void* user);
  static void on_control(const lcm_recv_buf_t* rbuf, const char* channel, void* user);
  static void on_target(const lcm_recv_buf_t* rbuf, const char* channel, void* user);
  static void on_params(const lcm_recv_buf_t* rbuf, const char* channel, void* user);
  static void on_readings(const lcm_recv_buf_t* rbuf, const char* channel, void* user);
  lcm_subscription_t* subscribe(const std::string& channel, lcm_msg_handler_t handler, int capacity);
  // Whether the subscription's queue held `capacity` messages before this one was taken from it.
  static bool queue_was_full(lcm_subscription_t* sub, int capacity);
  void handle_command(const lcm_recv_buf_t* rbuf);
  // The command stream's time for params updates (now: this node's clock).
  CommandTime command_time() const;
  void handle_target(const lcm_recv_buf_t* rbuf);
  void find_sockets();

  lcm_t* lcm_;
  DaemonConfig config_;
  Compensator comp_;
  LatencyWindow latency_;   // compute: the handler's start to the target published
  LatencyWindow receipt_;   // waiting too: LCM's receive stamp to the target published
  // Every message is value-initialised: no field ever carries process memory onto the bus.
  chaincomp_lcm::lcmt_axis_command cmd_msg_{};
  chaincomp_lcm::lcmt_corrected_target out_msg_{}, heard_msg_{};
  chaincomp_lcm::lcmt_chaincomp_control control_msg_{};
  chaincomp_lcm::lcmt_chaincomp_status status_msg_{};
  std::vector<unsigned char> out_buf_, status_buf_;
  Command command_;
  Target target_;
  std::chrono::steady_clock::time_point started_;
  long long (*alloc_count_)() = nullptr;
  long long alloc_baseline_ = 0;
  bool steady_ = false;  // the first command has been handled
  bool command_accepted_ = false;                 // the last accepted command's receipt
  std::chrono::steady_clock::time_point command_at_;
  std::int64_t control_received_ = 0, control_refused_ = 0, control_queue_full_ = 0;
  // Commands: answered but not sent; handled with the queue full; missing while it was.
  std::int64_t unpublished_ = 0, queue_full_ = 0, queue_dropped_ = 0;
  std::int64_t handled_ = 0, full_at_ = -1;  // commands handled; the last found with the queue full
  lcm_subscription_t* command_sub_ = nullptr;
  lcm_subscription_t* control_sub_ = nullptr;
  lcm_subscription_t* target_sub_ = nullptr;
  lcm_subscription_t* params_sub_ = nullptr;
  ParamsUpdater* updater_ = nullptr;
  ParamsUpdate update_, thermal_update_;
  lcm_subscription_t* readings_sub_ = nullptr;
  ThermalState* thermal_ = nullptr;
  Readings readings_;
  std::int64_t instance_id_ = 0;
  std::string machine_;
  // Targets on the corrected channel: this node's own, heard back, and another instance's
  // for the same machine (two daemons answering one CNC); each other instance is reported
  // on stderr once (the first kMaxReported of them). Own targets are those it published
  // and has not heard yet (a ring of their payloads' hashes, oldest first): a forged copy
  // counts nothing, each published target is heard at most once.
  std::int64_t own_heard_ = 0, foreign_ = 0, foreign_instance_ = 0;
  static constexpr std::uint64_t kSentRing = 16384;  // a power of two
  std::vector<std::uint64_t> sent_;
  std::uint64_t sent_head_ = 0, sent_tail_ = 0;       // unheard: [tail, head)
  static constexpr int kMaxReported = 8;
  std::int64_t reported_[kMaxReported] = {};
  int num_reported_ = 0;
  static constexpr int kMaxSockets = 8;
  int sockets_[kMaxSockets] = {};
  int num_sockets_ = 0;
  std::int64_t recv_buf_bytes_ = -1;
};

}  // namespace chaincomp
