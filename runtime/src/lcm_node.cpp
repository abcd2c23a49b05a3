#include "chaincomp/lcm_node.hpp"

#include "chaincomp/hash.hpp"
#include "chaincomp/params_io.hpp"
#include "chaincomp_lcm/lcmt_params_update.hpp"
#include "chaincomp_lcm/lcmt_temperatures.hpp"

#include <dirent.h>
#include <dlfcn.h>
#include <linux/sock_diag.h>
#include <netinet/in.h>
#include <sys/socket.h>

#include <algorithm>
#include <cctype>
#include <climits>
#include <cstdio>
#include <cstdlib>
#include <random>

namespace chaincomp {

static_assert(chaincomp_lcm::lcmt_params_update::MAX_VALUES == kMaxUpdateValues, "lcmt_params_update.MAX_VALUES");
static_assert(chaincomp_lcm::lcmt_chaincomp_status::NUM_PARAMS_REASONS == kNumRefusals, "params_refused's size");
static_assert(chaincomp_lcm::lcmt_temperatures::MAX_VALUES == kMaxReadings, "lcmt_temperatures.MAX_VALUES");
static_assert(chaincomp_lcm::lcmt_chaincomp_status::NUM_READING_REASONS == kNumReadingRefusals, "readings_refused");
static_assert(kMaxChannelName == LCM_MAX_CHANNEL_NAME_LENGTH, "daemon_config.hpp's channel limit is LCM's");

namespace {

using Clock = std::chrono::steady_clock;

std::int64_t ns_since(Clock::time_point t0) {
  return std::chrono::duration_cast<std::chrono::nanoseconds>(Clock::now() - t0).count();
}

std::int64_t wall_ns() {
  return std::chrono::duration_cast<std::chrono::nanoseconds>(
             std::chrono::system_clock::now().time_since_epoch()).count();
}

std::int64_t wall_us() { return wall_ns() / 1000; }

// Where the machine name's length field is: in a command after fingerprint, utime and seq;
// in a target after fingerprint, utime, seq, num_axes, axes, correction, the residuals,
// flags, status, compute_ns and instance_id.
constexpr std::size_t kCommandMachineAt = 8 + 8 + 8;
constexpr std::size_t kTargetMachineAt = 8 + 8 + 8 + 4 + 64 + 64 + 8 + 8 + 4 + 4 + 8 + 8;

// The machine name's length field must be 1..kMaxMachineName+1 and fit in the payload.
bool machine_name_fits(const void* data, std::size_t size, std::size_t kAt) {
  if (size < kAt + 4) return false;
  const auto* b = static_cast<const unsigned char*>(data) + kAt;
  const std::int64_t len = static_cast<std::int32_t>((std::uint32_t(b[0]) << 24) | (std::uint32_t(b[1]) << 16) |
                                                     (std::uint32_t(b[2]) << 8) | std::uint32_t(b[3]));
  return len >= 1 && len <= LcmNode::kMaxMachineName + 1 && len <= static_cast<std::int64_t>(size - kAt - 4);
}

std::int64_t big_endian64(const unsigned char* b) {
  std::uint64_t v = 0;
  for (int i = 0; i < 8; ++i) v = (v << 8) | b[i];
  return static_cast<std::int64_t>(v);
}

}  // namespace

bool decode_command(const void* data, std::size_t size, chaincomp_lcm::lcmt_axis_command& scratch,
                    Command& out) noexcept {
  // the whole payload or nothing: trailing bytes are refused, as for updates and readings
  if (!machine_name_fits(data, size, kCommandMachineAt) ||
      scratch.decode(data, 0, static_cast<int>(size)) != static_cast<int>(size) || scratch.num_axes < 0 ||
      scratch.num_axes > kMaxAxes) {
    return false;
  }
  out.utime = scratch.utime;
  out.seq = scratch.seq;
  out.machine = scratch.machine;  // all of it: a NUL inside is part of the name
  out.num_axes = scratch.num_axes;
  for (int i = 0; i < kMaxAxes; ++i) out.axes[i] = scratch.axes[i];
  return true;
}

bool decode_control(const void* data, std::size_t size, chaincomp_lcm::lcmt_chaincomp_control& out) noexcept {
  return size <= static_cast<std::size_t>(INT32_MAX) &&
         out.decode(data, 0, static_cast<int>(size)) == static_cast<int>(size);
}

void apply_control(const chaincomp_lcm::lcmt_chaincomp_control& c, Compensator& comp, ParamsUpdater* updater,
                   ThermalState* thermal) noexcept {
  comp.set_enabled(c.enable);
  if (!c.reset) return;
  comp.reset();
  if (updater) updater->reset();
  if (thermal) thermal->reset();
}

std::string channel_regex(const std::string& name) {
  // LCM compiles "^name$" with GLib's (PCRE) regex: a backslash makes any punctuation literal
  std::string out;
  for (const char c : name) {
    const auto u = static_cast<unsigned char>(c);
    if (u < 0x80 && !std::isalnum(u) && c != '_') out += '\\';
    out += c;
  }
  return out;
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
    : lcm_(lcm), config_(config), comp_(entry, model, config.compensator), latency_(config.latency_window),
      receipt_(config.latency_window) {
  std::random_device random;
  while (instance_id_ == 0) {
    instance_id_ = static_cast<std::int64_t>(((std::uint64_t(random()) << 32) | random()) >> 1);
  }
  machine_ = entry.info->name;
  cmd_msg_.machine.reserve(kMaxMachineName + 1);
  heard_msg_.machine.reserve(kMaxMachineName + 1);
  out_msg_.instance_id = instance_id_;
  out_msg_.machine = machine_;
  out_buf_.resize(out_msg_.getEncodedSize() + 64);
  auto& s = status_msg_;
  s.machine = entry.info->name;
  s.instance_id = instance_id_;
  s.config_file = config.source_file;
  s.model_hash = hash_hex(entry.info->source_hash);
  s.params_file = params_file;
  s.params_hash = params_hash;
  s.mlockall_ok = rt.mlockall;
  s.sched_fifo_ok = rt.sched_fifo;
  s.cpu_pinned_ok = rt.cpu_pinned;
  s.queue_capacity = kQueueCapacity;
  s.control_queue_capacity = kControlQueueCapacity;
  status_buf_.resize(s.getEncodedSize() + 64);
  sent_.assign(kSentRing, 0);
  command_sub_ = subscribe(config_.command_channel, &LcmNode::on_command, kQueueCapacity);
  control_sub_ = subscribe(config_.control_channel, &LcmNode::on_control, kControlQueueCapacity);
  // Targets on the bus: its own heard back, and another daemon's for this machine.
  target_sub_ = subscribe(config_.corrected_channel, &LcmNode::on_target, kQueueCapacity);
  find_sockets();
  // An LD_PRELOAD allocation counter, when present, measures the steady state.
  alloc_count_ = reinterpret_cast<long long (*)()>(dlsym(RTLD_DEFAULT, "chaincomp_alloc_count"));
  started_ = Clock::now();
  // A first status announces the node and makes LCM's lazy allocations for publishing.
  publish_status(false);
}

lcm_subscription_t* LcmNode::subscribe(const std::string& channel, lcm_msg_handler_t handler, int capacity) {
  lcm_subscription_t* sub = lcm_subscribe(lcm_, channel_regex(channel).c_str(), handler, this);
  lcm_subscription_set_queue_capacity(sub, capacity);
  return sub;
}

bool LcmNode::queue_was_full(lcm_subscription_t* sub, int capacity) {
  // LCM counts the message being handled out of the queue before calling its handler: capacity - 1
  // left (or more: arrived since) means it was full (or one short of it) at some moment since the
  // last message was taken, and nothing but taking one empties it.
  return lcm_subscription_get_queue_size(sub) >= capacity - 1;
}

CommandTime LcmNode::command_time() const {
  const auto us = [](Clock::time_point t) {
    return std::chrono::duration_cast<std::chrono::microseconds>(t.time_since_epoch()).count();
  };
  const std::int64_t now = us(Clock::now());
  return {comp_.last_utime(), commands_flowing(command_accepted_, us(command_at_), now), now};
}

LcmNode::~LcmNode() {
  lcm_unsubscribe(lcm_, command_sub_);
  lcm_unsubscribe(lcm_, control_sub_);
  lcm_unsubscribe(lcm_, target_sub_);
  if (params_sub_) lcm_unsubscribe(lcm_, params_sub_);
  if (readings_sub_) lcm_unsubscribe(lcm_, readings_sub_);
}

void LcmNode::accept_temperatures(ThermalState& thermal) {
  thermal_ = &thermal;
  readings_sub_ = subscribe(config_.temperatures_channel, &LcmNode::on_readings, kQueueCapacity);
}

void LcmNode::on_readings(const lcm_recv_buf_t* rbuf, const char*, void* user) {
  auto* self = static_cast<LcmNode*>(user);
  if (!decode_readings(rbuf->data, rbuf->data_size, chaincomp_lcm::lcmt_temperatures::getHash(), self->readings_)) {
    self->thermal_->count_undecodable();
    return;
  }
  if (self->thermal_->take(self->readings_, self->machine_, self->thermal_update_) && self->updater_)
    self->updater_->apply_values(self->thermal_update_, self->command_time());
}

void LcmNode::accept_params_updates(ParamsUpdater& updater) {
  updater_ = &updater;
  // a flood is refused one by one (min_interval), never dropped unseen by a short queue
  params_sub_ = subscribe(config_.params_channel, &LcmNode::on_params, kQueueCapacity);
}

void LcmNode::on_params(const lcm_recv_buf_t* rbuf, const char*, void* user) {
  auto* self = static_cast<LcmNode*>(user);
  if (!decode_params_update(rbuf->data, rbuf->data_size, chaincomp_lcm::lcmt_params_update::getHash(), self->update_)) {
    self->updater_->count_undecodable();
    return;
  }
  self->updater_->apply(self->update_, self->instance_id_, self->command_time());
}

// LCM's udpm provider receives on a socket of its own thread; lcm_get_fileno gives a
// notification pipe. The process's UDP sockets are LCM's (a receiving and a sending one):
// found once here, asked for their drop counters at each status.
void LcmNode::find_sockets() {
  DIR* dir = opendir("/proc/self/fd");
  if (dir == nullptr) return;
  const int own = dirfd(dir);
  while (dirent* e = readdir(dir)) {
    const int fd = std::atoi(e->d_name);
    int type = 0, domain = 0, size = 0;
    socklen_t len = sizeof type;
    if (fd == own || e->d_name[0] < '0' || e->d_name[0] > '9') continue;
    if (getsockopt(fd, SOL_SOCKET, SO_TYPE, &type, &len) != 0 || type != SOCK_DGRAM) continue;
    len = sizeof domain;
    if (getsockopt(fd, SOL_SOCKET, SO_DOMAIN, &domain, &len) != 0 || domain != AF_INET) continue;
    if (num_sockets_ == kMaxSockets) break;
    sockets_[num_sockets_++] = fd;
    // the receiving socket is the one bound to a port (udpm binds it to the group's port)
    sockaddr_in addr{};
    len = sizeof addr;
    if (getsockname(fd, reinterpret_cast<sockaddr*>(&addr), &len) == 0 && addr.sin_port != 0) {
      len = sizeof size;
      if (getsockopt(fd, SOL_SOCKET, SO_RCVBUF, &size, &len) == 0) recv_buf_bytes_ = size;
    }
  }
  closedir(dir);
}

std::int64_t LcmNode::kernel_drops() const {
  std::int64_t drops = -1;  // no socket, or a kernel without SO_MEMINFO (before Linux 4.6)
  for (int i = 0; i < num_sockets_; ++i) {
    std::uint32_t info[SK_MEMINFO_VARS] = {};
    socklen_t len = sizeof info;
    if (getsockopt(sockets_[i], SOL_SOCKET, SO_MEMINFO, info, &len) == 0) {
      drops = std::max<std::int64_t>(drops, 0) + info[SK_MEMINFO_DROPS];
    }
  }
  return drops;
}

void LcmNode::on_target(const lcm_recv_buf_t* rbuf, const char*, void* user) {
  static_cast<LcmNode*>(user)->handle_target(rbuf);
}

void LcmNode::handle_target(const lcm_recv_buf_t* rbuf) {
  // Its own targets come back once each, in the order published: told by fingerprint and
  // instance without decoding, then found among those published and not yet heard (those
  // before it were lost). Anyone may forge the instance: a payload it never published, or
  // one already heard, counts nothing.
  const auto* b = static_cast<const unsigned char*>(rbuf->data);
  if (rbuf->data_size >= kTargetMachineAt && big_endian64(b) == heard_msg_.getHash() &&
      big_endian64(b + kTargetMachineAt - 8) == instance_id_) {
    const std::uint64_t h = fnv1a64(b, rbuf->data_size);
    for (std::uint64_t i = sent_tail_; i < sent_head_; ++i) {
      if (sent_[i & (kSentRing - 1)] == h) {
        ++own_heard_;
        sent_tail_ = i + 1;
        break;
      }
    }
    return;
  }
  auto& t = heard_msg_;
  if (!machine_name_fits(rbuf->data, rbuf->data_size, kTargetMachineAt) ||
      t.decode(rbuf->data, 0, static_cast<int>(rbuf->data_size)) < 0) {
    return;  // not a target of this version: nobody this node could be confused with
  }
  if (t.instance_id == instance_id_ || t.machine != machine_) return;  // exact: length and bytes
  ++foreign_;
  foreign_instance_ = t.instance_id;
  for (int i = 0; i < num_reported_; ++i) {
    if (reported_[i] == t.instance_id) return;
  }
  if (num_reported_ < kMaxReported) reported_[num_reported_++] = t.instance_id;
  std::fprintf(stderr, "chaincompd: warning: another daemon (instance %016llx) publishes targets for %s on %s; "
               "this is instance %016llx\n", static_cast<unsigned long long>(t.instance_id), machine_.c_str(),
               config_.corrected_channel.c_str(), static_cast<unsigned long long>(instance_id_));
}

void LcmNode::on_command(const lcm_recv_buf_t* rbuf, const char*, void* user) {
  static_cast<LcmNode*>(user)->handle_command(rbuf);
}

void LcmNode::on_control(const lcm_recv_buf_t* rbuf, const char*, void* user) {
  auto* self = static_cast<LcmNode*>(user);
  ++self->control_received_;
  if (queue_was_full(self->control_sub_, kControlQueueCapacity)) ++self->control_queue_full_;
  if (!decode_control(rbuf->data, rbuf->data_size, self->control_msg_)) {
    ++self->control_refused_;
    return;
  }
  apply_control(self->control_msg_, self->comp_, self->updater_, self->thermal_);
}

void LcmNode::handle_command(const lcm_recv_buf_t* rbuf) {
  const auto t0 = Clock::now();
  // Commands LCM discarded at a full queue show as a gap before the first one it kept after
  // them; the moment it was full is seen by a command at most kQueueCapacity - 1 ahead of that
  // gap (the queue held it and those before it), so a gap that near a full queue is the queue's.
  if (queue_was_full(command_sub_, kQueueCapacity)) {
    ++queue_full_;
    full_at_ = handled_;
  }
  const bool near_full = full_at_ >= 0 && handled_ - full_at_ <= kQueueCapacity;
  ++handled_;
  if (!decode_command(rbuf->data, rbuf->data_size, cmd_msg_, command_)) {
    comp_.count_undecodable();
    return;
  }
  const std::int64_t missing_before = comp_.counters().seq_missing;
  const bool answered = comp_.process(command_, target_);
  if (near_full) queue_dropped_ += comp_.counters().seq_missing - missing_before;
  if (answered) {
    auto& o = out_msg_;
    to_message(target_, o);
    o.compute_ns = ns_since(t0);
    const int n = o.encode(out_buf_.data(), 0, static_cast<int>(out_buf_.size()));
    if (n > 0 && lcm_publish(lcm_, config_.corrected_channel.c_str(), out_buf_.data(), n) == 0) {
      comp_.count_published();
      sent_[sent_head_++ & (kSentRing - 1)] = fnv1a64(out_buf_.data(), static_cast<std::size_t>(n));
      if (sent_head_ - sent_tail_ > kSentRing) sent_tail_ = sent_head_ - kSentRing;  // the oldest: lost
      receipt_.record(wall_ns() - rbuf->recv_utime * 1000);
    } else {
      ++unpublished_;
    }
    latency_.record(ns_since(t0));
    command_accepted_ = true;
    command_at_ = t0;
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
  s.seq_gaps = k.seq_gaps;
  s.seq_missing = k.seq_missing;
  s.stream_restarts = k.stream_restarts;
  s.resets = k.resets;
  s.kernel_drops = kernel_drops();
  s.recv_buf_bytes = recv_buf_bytes_;
  s.own_targets_heard = own_heard_;
  s.foreign_targets = foreign_;
  s.foreign_instance = foreign_instance_;
  s.held_back = k.held_back;
  s.targets_full = k.targets_full;
  s.targets_partial = k.targets_partial;
  s.targets_uncorrected = k.targets_uncorrected;
  s.targets_worse = k.targets_worse;
  s.objective_before = k.objective_before;
  s.objective_after = k.objective_after;
  s.direction_weight = comp_.direction_weight();
  if (updater_) {
    s.params_version = updater_->version();
    s.params_seq = updater_->last_seq();
    s.params_received = updater_->received();
    for (int i = 0; i < kNumRefusals; ++i) s.params_refused[i] = updater_->refused()[i];
  }
  if (thermal_) {
    s.readings_received = thermal_->received();
    for (int i = 0; i < kNumReadingRefusals; ++i) s.readings_refused[i] = thermal_->refused()[i];
  }
  s.control_received = control_received_;
  s.control_refused = control_refused_;
  s.unpublished = unpublished_;
  s.queue_full = queue_full_;
  s.queue_dropped = queue_dropped_;
  s.control_queue_full = control_queue_full_;
  const auto waited = receipt_.summary();
  s.receipt_p50_ns = waited.p50;
  s.receipt_p99_ns = waited.p99;
  s.receipt_max_ns = waited.max;
  const int n = s.encode(status_buf_.data(), 0, static_cast<int>(status_buf_.size()));
  if (n > 0) lcm_publish(lcm_, config_.status_channel.c_str(), status_buf_.data(), n);
}

}  // namespace chaincomp
