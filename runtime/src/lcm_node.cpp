#include "chaincomp/lcm_node.hpp"

#include "chaincomp/params_io.hpp"

#include <dlfcn.h>


namespace chaincomp {

namespace {

using Clock = std::chrono::steady_clock;

std::int64_t ns_since(Clock::time_point t0) {
  return std::chrono::duration_cast<std::chrono::nanoseconds>(Clock::now() - t0).count();
}

std::int64_t wall_us() {
  return std::chrono::duration_cast<std::chrono::microseconds>(
             std::chrono::system_clock::now().time_since_epoch()).count();
}

// The machine name's length field must be 1..kMaxMachineName+1 and fit in the payload.
bool machine_name_fits(const void* data, std::size_t size) {
  constexpr std::size_t kAt = 8 + 8 + 8;  // fingerprint, utime, seq
  if (size < kAt + 4) return false;
  const auto* b = static_cast<const unsigned char*>(data) + kAt;
  const std::int64_t len = static_cast<std::int32_t>((std::uint32_t(b[0]) << 24) | (std::uint32_t(b[1]) << 16) |
                                                     (std::uint32_t(b[2]) << 8) | std::uint32_t(b[3]));
  return len >= 1 && len <= LcmNode::kMaxMachineName + 1 && len <= static_cast<std::int64_t>(size - kAt - 4);
}

}  // namespace

bool decode_command(const void* data, std::size_t size, chaincomp_lcm::lcmt_axis_command& scratch,
                    Command& out) noexcept {
  if (!machine_name_fits(data, size) || scratch.decode(data, 0, static_cast<int>(size)) < 0 ||
      scratch.num_axes < 0 || scratch.num_axes > kMaxAxes) {
    return false;
  }
  out.utime = scratch.utime;
  out.seq = scratch.seq;
  out.machine = scratch.machine.c_str();
  out.num_axes = scratch.num_axes;
  for (int i = 0; i < kMaxAxes; ++i) out.axes[i] = scratch.axes[i];
  return true;
}

void to_message(const Target& t, chaincomp_lcm::lcmt_corrected_target& o) noexcept {
  o.utime = t.utime;
  o.seq = t.seq;
  o.num_axes = t.num_axes;
  for (int i = 0; i < kMaxAxes; ++i) {
    o.axes[i] = t.axes[i];
    o.correction[i] = t.correction[i];
  }
  o.residual_point = t.residual_point;
  o.residual_direction = t.residual_direction;
  o.flags = t.flags;
  o.status = t.status;
}

LcmNode::LcmNode(lcm_t* lcm, const ModelEntry& entry, const void* model, const DaemonConfig& config,
                 const std::string& params_file, const std::string& params_hash, RealtimeObtained rt)
    : lcm_(lcm), config_(config), comp_(entry, model, config.compensator), latency_(config.latency_window) {
  cmd_msg_.machine.reserve(kMaxMachineName + 1);
  out_buf_.resize(out_msg_.getEncodedSize() + 64);
  auto& s = status_msg_;
  s.machine = entry.info->name;
  s.model_hash = hash_hex(entry.info->source_hash);
  s.params_file = params_file;
  s.params_hash = params_hash;
  s.mlockall_ok = rt.mlockall;
  s.sched_fifo_ok = rt.sched_fifo;
  s.cpu_pinned_ok = rt.cpu_pinned;
  status_buf_.resize(s.getEncodedSize() + 64);
  command_sub_ = lcm_subscribe(lcm_, config_.command_channel.c_str(), &LcmNode::on_command, this);
  control_sub_ = lcm_subscribe(lcm_, config_.control_channel.c_str(), &LcmNode::on_control, this);
  // LCM drops a subscription's messages beyond its queue capacity (default 30): a short
  // stall of the loop at 10 kHz would lose commands. The socket buffer bounds it anyway.
  lcm_subscription_set_queue_capacity(command_sub_, kQueueCapacity);
  // An LD_PRELOAD allocation counter, when present, measures the steady state.
  alloc_count_ = reinterpret_cast<long long (*)()>(dlsym(RTLD_DEFAULT, "chaincomp_alloc_count"));
  started_ = Clock::now();
  // A first status announces the node and makes LCM's lazy allocations for publishing.
  publish_status(false);
}

LcmNode::~LcmNode() {
  lcm_unsubscribe(lcm_, command_sub_);
  lcm_unsubscribe(lcm_, control_sub_);
}

void LcmNode::on_command(const lcm_recv_buf_t* rbuf, const char*, void* user) {
  static_cast<LcmNode*>(user)->handle_command(rbuf);
}

void LcmNode::on_control(const lcm_recv_buf_t* rbuf, const char*, void* user) {
  auto* self = static_cast<LcmNode*>(user);
  if (self->control_msg_.decode(rbuf->data, 0, static_cast<int>(rbuf->data_size)) >= 0) {
    self->comp_.set_enabled(self->control_msg_.enable);
  }
}

void LcmNode::handle_command(const lcm_recv_buf_t* rbuf) {
  const auto t0 = Clock::now();
  if (!decode_command(rbuf->data, rbuf->data_size, cmd_msg_, command_)) {
    comp_.count_undecodable();
    return;
  }
  if (comp_.process(command_, target_)) {
    auto& o = out_msg_;
    to_message(target_, o);
    o.compute_ns = ns_since(t0);
    const int n = o.encode(out_buf_.data(), 0, static_cast<int>(out_buf_.size()));
    if (n > 0 && lcm_publish(lcm_, config_.corrected_channel.c_str(), out_buf_.data(), n) == 0) {
      comp_.count_published();
    }
    latency_.record(ns_since(t0));
  }
  // LCM allocates per channel on the first message received and the first one published:
  // start-up ends with the first command handled.
  if (!steady_ && alloc_count_) alloc_baseline_ = alloc_count_();
  steady_ = true;
}

void LcmNode::publish_status(bool final) {
  auto& s = status_msg_;
  const auto& k = comp_.counters();
  s.utime = wall_us();
  s.uptime_us = ns_since(started_) / 1000;
  s.received = k.received;
  s.published = k.published;
  for (int i = 0; i < kNumReasons; ++i) s.rejected[i] = k.rejected[i];
  s.clamped = k.clamped;
  s.clamped_input = k.clamped_input;
  s.compensating = comp_.enabled();
  s.ramp = comp_.ramp();
  const auto lat = latency_.summary();
  s.window = lat.count;
  s.latency_p50_ns = lat.p50;
  s.latency_p99_ns = lat.p99;
  s.latency_p999_ns = lat.p999;
  s.latency_max_ns = lat.max;
  s.allocations = (alloc_count_ && steady_) ? alloc_count_() - alloc_baseline_ : -1;
  s.final = final;
  const int n = s.encode(status_buf_.data(), 0, static_cast<int>(status_buf_.size()));
  if (n > 0) lcm_publish(lcm_, config_.status_channel.c_str(), status_buf_.data(), n);
}

}  // namespace chaincomp
