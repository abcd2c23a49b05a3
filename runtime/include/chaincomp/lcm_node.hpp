// chaincompd's LCM side: subscribes to commands and control, publishes corrected targets and
// status. Start-up allocates; handling messages does not. Built for one lcm_t per node.
// Receiving and handling are apart: LCM's handlers (the receive thread's lcm_handle) only copy
// each message into its stream's ring; the main thread handles the rings' messages in the order
// they arrived (handle_queued). A ring that is full drops the message there and counts it.
#pragma once

#include <lcm/lcm.h>

#include <atomic>
#include <chrono>
#include <memory>
#include <string>
#include <thread>
#include <vector>

#include "chaincomp/compensator.hpp"
#include "chaincomp/daemon_config.hpp"
#include "chaincomp/latency.hpp"
#include "chaincomp/message_ring.hpp"
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
  // `model` filled by entry.prepare(); `lcm`, `entry` and `model` outlive the node. Throws
  // std::runtime_error when it cannot make its wake-up eventfd (descriptors exhausted).
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
  // Receiving on a thread of the node's own (lcm_handle, nothing else): after every subscription
  // (accept_*), before the main loop; stopped by stop_receiving or the destructor.
  void start_receiving();
  void stop_receiving();
  // Readable (an eventfd) when messages wait in the rings; the main loop polls it, reads it
  // empty, then calls handle_queued: the messages queued, every stream's in arrival order.
  int wake_fd() const { return wake_fd_; }
  int handle_queued();
  // Without the receive thread (tests, fuzzers, the daemon's exit): LCM's handlers and this
  // node's in turn until neither has anything left, or `max_messages` were handled.
  void handle_until_idle(int max_messages = 1 << 30);
  const Counters& counters() const { return comp_.counters(); }
  std::int64_t instance_id() const { return instance_id_; }
  // Datagrams the kernel dropped at the process's UDP sockets (-1: none), and the receive
  // buffer of the one LCM receives on (-1: none), as SO_MEMINFO and SO_RCVBUF report them.
  std::int64_t kernel_drops() const;
  std::int64_t recv_buf_bytes() const { return recv_buf_bytes_; }

  // The longest machine name a command may carry (lcm-gen's decoder trusts the length).
  static constexpr int kMaxMachineName = 255;
  // The rings (messages): what may wait while the main thread is busy, one second of commands at
  // 10 kHz; what arrives at a full ring is dropped and counted (docs/guide/daemon.md).
  static constexpr int kQueueCapacity = 10000;         // commands, targets heard back
  static constexpr int kControlQueueCapacity = 1000;   // control messages
  // params updates, readings: 10000 within 4 MiB (the largest valid one is 17 KB: 240 of those)
  static constexpr int kUpdateQueueCapacity = 10000;
  static constexpr std::size_t kUpdateQueueBytes = std::size_t(4) << 20;
  // LCM's own queue of each subscription, drained by a thread that only copies: never full in
  // practice. LCM discards what arrives at a full queue without counting it, so a queue found
  // full is counted (lcm_queue_full): the one case where the drops are not known exactly.
  static constexpr int kLcmQueueCapacity = 100000;

 private:
  enum Stream { kCommands, kControl, kParams, kReadings, kTargets, kNumStreams };
  // One subscription and its ring; LCM's handler gets the inlet.
  struct Inlet {
    LcmNode* node = nullptr;
    Stream stream = kCommands;
    lcm_subscription_t* sub = nullptr;
    std::unique_ptr<MessageRing> ring;
  };
  // The receive side: copies the message into its inlet's ring (or counts it dropped).
  static void on_message(const lcm_recv_buf_t* rbuf, const char* channel, void* user);
  void subscribe(Stream stream, const std::string& channel, int capacity, std::size_t max_size,
                 std::size_t bytes = 0);
  void receive_loop();
  // The main thread's side, one message of a ring each.
  void handle(Stream stream, const MessageRing::Message& m);
  void handle_command(const MessageRing::Message& m);
  void handle_control(const MessageRing::Message& m);
  void handle_params(const MessageRing::Message& m);
  void handle_readings(const MessageRing::Message& m);
  void handle_target(const MessageRing::Message& m);
  // The command stream's time for params updates (now: this node's clock).
  CommandTime command_time() const;
  void find_sockets();
  std::int64_t dropped(Stream stream) const { return inlets_[stream].ring ? inlets_[stream].ring->dropped() : 0; }

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
  std::int64_t control_received_ = 0, control_refused_ = 0;
  std::int64_t unpublished_ = 0;  // commands answered, their target not sent
  Inlet inlets_[kNumStreams];
  // Written by the receiving thread only: messages pushed to a ring (their arrival numbers
  // 0 .. arrived_-1), LCM's queues found full. The main thread handles arrival next_ next.
  std::atomic<std::int64_t> arrived_{0}, lcm_queue_full_{0};
  std::int64_t next_ = 0;
  int wake_fd_ = -1;
  std::thread receiver_;
  std::atomic<bool> stop_receiving_{false};
  ParamsUpdater* updater_ = nullptr;
  ParamsUpdate update_, thermal_update_;
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
