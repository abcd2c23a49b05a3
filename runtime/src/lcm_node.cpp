#include "chaincomp/lcm_node.hpp"

#include "chaincomp/hash.hpp"
#include "chaincomp/params_io.hpp"
#include "chaincomp_lcm/lcmt_params_update.hpp"
#include "chaincomp_lcm/lcmt_temperatures.hpp"

#include <dirent.h>
#include <dlfcn.h>
#include <linux/sock_diag.h>
#include <netinet/in.h>
#include <signal.h>
#include <sys/eventfd.h>
#include <sys/socket.h>
#include <unistd.h>

#include <algorithm>
#include <cctype>
#include <cerrno>
#include <climits>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <random>
#include <stdexcept>

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

// The encoded size of `m` with every string at its longest (255 bytes: lcm_wire.hpp's bound,
// kMaxMachineName) and every array at its longest: a stream's largest valid message.
template <class M>
std::size_t largest(M m) {
  m.machine.assign(LcmNode::kMaxMachineName, 'x');
  return static_cast<std::size_t>(m.getEncodedSize());
}
template <class M>
std::size_t largest_with_names(M m) {
  m.num_values = M::MAX_VALUES;
  m.names.assign(M::MAX_VALUES, std::string(255, 'x'));
  m.values.assign(M::MAX_VALUES, 0.0);
  return largest(m);
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
  s.lcm_queue_capacity = kLcmQueueCapacity;
  status_buf_.resize(s.getEncodedSize() + 64);
  sent_.assign(kSentRing, 0);
  wake_fd_ = eventfd(0, EFD_NONBLOCK | EFD_CLOEXEC);
  // without it the main loop would only wake at each status: refused at start, not slow in silence.
  // (A runtime_error of strerror's text: std::system_error's constructor asks its category
  // virtually, which UBSan checks through a pipe it cannot open when descriptors ran out.)
  if (wake_fd_ < 0) {
    throw std::runtime_error(std::string("eventfd (the receive thread's wake-up): ") + std::strerror(errno));
  }
  subscribe(kCommands, config_.command_channel, kQueueCapacity, largest(chaincomp_lcm::lcmt_axis_command{}));
  subscribe(kControl, config_.control_channel, kControlQueueCapacity,
            static_cast<std::size_t>(control_msg_.getEncodedSize()));
  // Targets on the bus: its own heard back, and another daemon's for this machine.
  subscribe(kTargets, config_.corrected_channel, kQueueCapacity, largest(chaincomp_lcm::lcmt_corrected_target{}));
  find_sockets();
  // An LD_PRELOAD allocation counter, when present, measures the steady state.
  alloc_count_ = reinterpret_cast<long long (*)()>(dlsym(RTLD_DEFAULT, "chaincomp_alloc_count"));
  started_ = Clock::now();
  // A first status announces the node and makes LCM's lazy allocations for publishing.
  publish_status(false);
}

void LcmNode::subscribe(Stream stream, const std::string& channel, int capacity, std::size_t max_size,
                        std::size_t bytes) {
  Inlet& in = inlets_[stream];
  in.node = this;
  in.stream = stream;
  in.ring = std::make_unique<MessageRing>(static_cast<std::size_t>(capacity), max_size, bytes);
  in.sub = lcm_subscribe(lcm_, channel_regex(channel).c_str(), &LcmNode::on_message, &in);
  lcm_subscription_set_queue_capacity(in.sub, kLcmQueueCapacity);
}

void LcmNode::on_message(const lcm_recv_buf_t* rbuf, const char*, void* user) {
  Inlet& in = *static_cast<Inlet*>(user);
  LcmNode& self = *in.node;
  // LCM takes the message out of its queue before calling: capacity - 1 left (or more) means
  // the queue was full at some moment since the last one was taken, and may have discarded one.
  if (lcm_subscription_get_queue_size(in.sub) >= kLcmQueueCapacity - 1)
    self.lcm_queue_full_.store(self.lcm_queue_full_.load(std::memory_order_relaxed) + 1, std::memory_order_relaxed);
  const std::int64_t arrival = self.arrived_.load(std::memory_order_relaxed);
  // an oversized message is queued empty: undecodable where its stream counts refusals
  if (in.ring->push(rbuf->data, rbuf->data_size, arrival, rbuf->recv_utime) == MessageRing::Push::kFull) return;
  self.arrived_.store(arrival + 1, std::memory_order_release);   // the ring's push before the number
  const std::uint64_t one = 1;
  if (write(self.wake_fd_, &one, sizeof one) < 0) {
    // EAGAIN only at a counter of 2^64 - 2: the main thread is awake anyway
  }
}

void LcmNode::start_receiving() {
  // the thread takes no signals: SIGTERM reaches the main thread's wait
  sigset_t all, before;
  sigfillset(&all);
  pthread_sigmask(SIG_SETMASK, &all, &before);
  stop_receiving_ = false;
  receiver_ = std::thread([this] { receive_loop(); });
  pthread_sigmask(SIG_SETMASK, &before, nullptr);
}

void LcmNode::receive_loop() {
  // a timeout, so that it sees stop_receiving_; an error (none expected) does not spin
  while (!stop_receiving_.load(std::memory_order_relaxed)) {
    if (lcm_handle_timeout(lcm_, 100) < 0) usleep(10000);
  }
}

void LcmNode::stop_receiving() {
  if (!receiver_.joinable()) return;
  stop_receiving_ = true;
  receiver_.join();
}

int LcmNode::handle_queued() {
  // Every number below arrived_ is in a ring, and each ring holds its messages in arrival order:
  // the next one is at the front of one of them.
  const std::int64_t arrived = arrived_.load(std::memory_order_acquire);
  const std::int64_t first = next_;
  for (; next_ < arrived; ++next_) {
    for (Inlet& in : inlets_) {
      const MessageRing::Message* m = in.ring ? in.ring->front() : nullptr;
      if (m != nullptr && m->arrival == next_) {
        handle(in.stream, *m);
        in.ring->pop();
        break;
      }
    }
  }
  return static_cast<int>(next_ - first);
}

void LcmNode::handle_until_idle(int max_messages) {
  // one of LCM's messages, then what the rings hold, in turn: as the two threads would
  for (int i = 0; i < max_messages; ++i) {
    const bool got = lcm_handle_timeout(lcm_, 0) > 0;
    if (handle_queued() == 0 && !got) return;
  }
}

void LcmNode::handle(Stream stream, const MessageRing::Message& m) {
  switch (stream) {
    case kCommands: return handle_command(m);
    case kControl: return handle_control(m);
    case kParams: return handle_params(m);
    case kReadings: return handle_readings(m);
    case kTargets: return handle_target(m);
    case kNumStreams: return;
  }
}

CommandTime LcmNode::command_time() const {
  const auto us = [](Clock::time_point t) {
    return std::chrono::duration_cast<std::chrono::microseconds>(t.time_since_epoch()).count();
  };
  const std::int64_t now = us(Clock::now());
  return {comp_.last_utime(), commands_flowing(command_accepted_, us(command_at_), now), now};
}

LcmNode::~LcmNode() {
  stop_receiving();
  for (Inlet& in : inlets_) {
    if (in.sub) lcm_unsubscribe(lcm_, in.sub);
  }
  if (wake_fd_ >= 0) close(wake_fd_);
}

void LcmNode::accept_temperatures(ThermalState& thermal) {
  thermal_ = &thermal;
  subscribe(kReadings, config_.temperatures_channel, kUpdateQueueCapacity,
            largest_with_names(chaincomp_lcm::lcmt_temperatures{}), kUpdateQueueBytes);
}

void LcmNode::handle_readings(const MessageRing::Message& m) {
  if (!decode_readings(m.data, m.size, chaincomp_lcm::lcmt_temperatures::getHash(), readings_)) {
    thermal_->count_undecodable();
    return;
  }
  if (thermal_->take(readings_, machine_, thermal_update_) && updater_)
    updater_->apply_values(thermal_update_, command_time());
}

void LcmNode::accept_params_updates(ParamsUpdater& updater) {
  updater_ = &updater;
  // a flood is refused one by one (min_interval); beyond the ring, dropped and counted
  subscribe(kParams, config_.params_channel, kUpdateQueueCapacity,
            largest_with_names(chaincomp_lcm::lcmt_params_update{}), kUpdateQueueBytes);
}

void LcmNode::handle_params(const MessageRing::Message& m) {
  if (!decode_params_update(m.data, m.size, chaincomp_lcm::lcmt_params_update::getHash(), update_)) {
    updater_->count_undecodable();
    return;
  }
  updater_->apply(update_, instance_id_, command_time());
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

void LcmNode::handle_target(const MessageRing::Message& m) {
  // Its own targets come back once each, in the order published: told by fingerprint and
  // instance without decoding, then found among those published and not yet heard (those
  // before it were lost). Anyone may forge the instance: a payload it never published, or
  // one already heard, counts nothing.
  const unsigned char* b = m.data;
  if (m.size >= kTargetMachineAt && big_endian64(b) == heard_msg_.getHash() &&
      big_endian64(b + kTargetMachineAt - 8) == instance_id_) {
    const std::uint64_t h = fnv1a64(b, m.size);
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
  if (!machine_name_fits(m.data, m.size, kTargetMachineAt) || t.decode(m.data, 0, static_cast<int>(m.size)) < 0) {
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

void LcmNode::handle_control(const MessageRing::Message& m) {
  ++control_received_;
  if (!decode_control(m.data, m.size, control_msg_)) {
    ++control_refused_;
    return;
  }
  apply_control(control_msg_, comp_, updater_, thermal_);
}

void LcmNode::handle_command(const MessageRing::Message& m) {
  const auto t0 = Clock::now();
  if (!decode_command(m.data, m.size, cmd_msg_, command_)) {
    comp_.count_undecodable();
    return;
  }
  const bool answered = comp_.process(command_, target_);
  if (answered) {
    auto& o = out_msg_;
    to_message(target_, o);
    o.compute_ns = ns_since(t0);
    const int n = o.encode(out_buf_.data(), 0, static_cast<int>(out_buf_.size()));
    if (n > 0 && lcm_publish(lcm_, config_.corrected_channel.c_str(), out_buf_.data(), n) == 0) {
      comp_.count_published();
      sent_[sent_head_++ & (kSentRing - 1)] = fnv1a64(out_buf_.data(), static_cast<std::size_t>(n));
      if (sent_head_ - sent_tail_ > kSentRing) sent_tail_ = sent_head_ - kSentRing;  // the oldest: lost
      receipt_.record(wall_ns() - m.recv_utime * 1000);
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
  s.queue_dropped = dropped(kCommands);
  s.control_queue_dropped = dropped(kControl);
  s.params_queue_dropped = dropped(kParams);
  s.readings_queue_dropped = dropped(kReadings);
  s.targets_queue_dropped = dropped(kTargets);
  std::int64_t oversized = 0;
  for (const Inlet& in : inlets_) oversized += in.ring ? in.ring->oversized() : 0;
  s.oversized = oversized;
  s.lcm_queue_full = lcm_queue_full_.load(std::memory_order_relaxed);
  const auto waited = receipt_.summary();
  s.receipt_p50_ns = waited.p50;
  s.receipt_p99_ns = waited.p99;
  s.receipt_max_ns = waited.max;
  const int n = s.encode(status_buf_.data(), 0, static_cast<int>(status_buf_.size()));
  if (n > 0) lcm_publish(lcm_, config_.status_channel.c_str(), status_buf_.data(), n);
}

}  // namespace chaincomp
