// chaincompd: takes commanded axis positions over LCM and publishes corrected targets.
// Single-threaded; poll() on the LCM file descriptor; no heap allocation after start-up.
#include <dlfcn.h>
#include <lcm/lcm.h>
#include <poll.h>
#include <sched.h>
#include <sys/mman.h>
#include <unistd.h>

#include <atomic>
#include <chrono>
#include <csignal>
#include <cstdio>
#include <cstring>
#include <fstream>
#include <memory>
#include <sstream>
#include <string>
#include <vector>

#include "chaincomp/compensator.hpp"
#include "chaincomp/daemon_config.hpp"
#include "chaincomp/hash.hpp"
#include "chaincomp/latency.hpp"
#include "chaincomp/params_io.hpp"
#include "chaincomp_lcm/lcmt_axis_command.hpp"
#include "chaincomp_lcm/lcmt_chaincomp_control.hpp"
#include "chaincomp_lcm/lcmt_chaincomp_status.hpp"
#include "chaincomp_lcm/lcmt_corrected_target.hpp"

namespace {

std::atomic<bool> g_stop{false};
void on_signal(int) { g_stop = true; }

using Clock = std::chrono::steady_clock;
std::int64_t ns_since(Clock::time_point t0) {
  return std::chrono::duration_cast<std::chrono::nanoseconds>(Clock::now() - t0).count();
}
std::int64_t wall_us() {
  return std::chrono::duration_cast<std::chrono::microseconds>(
             std::chrono::system_clock::now().time_since_epoch()).count();
}

std::string hex(std::uint64_t h) {
  char buf[17];
  std::snprintf(buf, sizeof buf, "%016llx", static_cast<unsigned long long>(h));
  return buf;
}

std::string file_hash(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  std::ostringstream ss;
  ss << in.rdbuf();
  const std::string t = ss.str();
  return hex(chaincomp::fnv1a64(reinterpret_cast<const unsigned char*>(t.data()), t.size()));
}

const char* kUsage =
    "usage: chaincompd --machine M.yaml --params P.yaml [--config R.yaml]\n"
    "Subscribes to commanded axis positions over LCM and publishes corrected targets.\n"
    "  --machine M.yaml  machine description (its model must be compiled in: configs/machines/)\n"
    "  --params P.yaml   error values of the machine (configs/params/)\n"
    "  --config R.yaml   runtime settings (configs/runtime/default.yaml documents every key)\n";

// Everything the loop touches, created at start-up.
struct Daemon {
  lcm_t* lcm = nullptr;
  chaincomp::DaemonConfig config;
  std::unique_ptr<chaincomp::Compensator> comp;
  chaincomp::LatencyWindow latency{1};
  chaincomp_lcm::lcmt_axis_command cmd_msg;
  chaincomp_lcm::lcmt_corrected_target out_msg;
  chaincomp_lcm::lcmt_chaincomp_control control_msg;
  chaincomp_lcm::lcmt_chaincomp_status status_msg;
  std::vector<unsigned char> out_buf, status_buf;
  chaincomp::Command command;
  chaincomp::Target target;
  Clock::time_point started;
  long long (*alloc_count)() = nullptr;
  long long alloc_baseline = 0;
  bool steady = false;  // the first command has been handled
};

// lcm-gen's decoder trusts the string length it reads (a length of 0 or below makes it throw
// or allocate): check it first, and keep it within the capacity reserved at start-up.
constexpr int kMaxMachineName = 255;
bool machine_name_fits(const lcm_recv_buf_t* rbuf) {
  constexpr std::size_t kAt = 8 + 8 + 8;  // fingerprint, utime, seq
  if (rbuf->data_size < kAt + 4) return false;
  const auto* b = static_cast<const unsigned char*>(rbuf->data) + kAt;
  const std::int64_t len = static_cast<std::int32_t>((std::uint32_t(b[0]) << 24) | (std::uint32_t(b[1]) << 16) |
                                                     (std::uint32_t(b[2]) << 8) | std::uint32_t(b[3]));
  return len >= 1 && len <= kMaxMachineName + 1 && len <= static_cast<std::int64_t>(rbuf->data_size - kAt - 4);
}

void on_command(const lcm_recv_buf_t* rbuf, const char*, void* user) {
  Daemon& d = *static_cast<Daemon*>(user);
  const auto t0 = Clock::now();
  if (!machine_name_fits(rbuf) || d.cmd_msg.decode(rbuf->data, 0, static_cast<int>(rbuf->data_size)) < 0 ||
      d.cmd_msg.num_axes < 0 || d.cmd_msg.num_axes > chaincomp::kMaxAxes) {
    d.comp->count_undecodable();
    return;
  }
  chaincomp::Command& c = d.command;
  c.utime = d.cmd_msg.utime;
  c.seq = d.cmd_msg.seq;
  c.machine = d.cmd_msg.machine.c_str();
  c.num_axes = d.cmd_msg.num_axes;
  for (int i = 0; i < chaincomp::kMaxAxes; ++i) c.axes[i] = d.cmd_msg.axes[i];
  if (!d.comp->process(c, d.target)) return;
  auto& o = d.out_msg;
  o.utime = d.target.utime;
  o.seq = d.target.seq;
  o.num_axes = d.target.num_axes;
  for (int i = 0; i < chaincomp::kMaxAxes; ++i) {
    o.axes[i] = d.target.axes[i];
    o.correction[i] = d.target.correction[i];
  }
  o.residual_point = d.target.residual_point;
  o.residual_direction = d.target.residual_direction;
  o.flags = d.target.flags;
  o.status = d.target.status;
  o.compute_ns = ns_since(t0);
  const int n = o.encode(d.out_buf.data(), 0, static_cast<int>(d.out_buf.size()));
  if (n > 0 && lcm_publish(d.lcm, d.config.corrected_channel.c_str(), d.out_buf.data(), n) == 0) {
    d.comp->count_published();
  }
  d.latency.record(ns_since(t0));
  // LCM allocates per channel on the first message received and the first one published:
  // start-up ends with the first command handled.
  if (!d.steady && d.alloc_count) d.alloc_baseline = d.alloc_count();
  d.steady = true;
}

void on_control(const lcm_recv_buf_t* rbuf, const char*, void* user) {
  Daemon& d = *static_cast<Daemon*>(user);
  if (d.control_msg.decode(rbuf->data, 0, static_cast<int>(rbuf->data_size)) >= 0) {
    d.comp->set_enabled(d.control_msg.enable);
  }
}

void publish_status(Daemon& d, bool final) {
  auto& s = d.status_msg;
  const auto& k = d.comp->counters();
  s.utime = wall_us();
  s.uptime_us = ns_since(d.started) / 1000;
  s.received = k.received;
  s.published = k.published;
  for (int i = 0; i < chaincomp::kNumReasons; ++i) s.rejected[i] = k.rejected[i];
  s.clamped = k.clamped;
  s.clamped_input = k.clamped_input;
  s.compensating = d.comp->enabled();
  s.ramp = d.comp->ramp();
  const auto lat = d.latency.summary();
  s.window = lat.count;
  s.latency_p50_ns = lat.p50;
  s.latency_p99_ns = lat.p99;
  s.latency_p999_ns = lat.p999;
  s.latency_max_ns = lat.max;
  s.allocations = d.alloc_count ? d.alloc_count() - d.alloc_baseline : -1;
  s.final = final;
  const int n = s.encode(d.status_buf.data(), 0, static_cast<int>(d.status_buf.size()));
  if (n > 0) lcm_publish(d.lcm, d.config.status_channel.c_str(), d.status_buf.data(), n);
}

void realtime_settings(const chaincomp::DaemonConfig& cfg, chaincomp_lcm::lcmt_chaincomp_status& s) {
  if (cfg.mlockall) {
    s.mlockall_ok = mlockall(MCL_CURRENT | MCL_FUTURE) == 0;
    if (!s.mlockall_ok) std::fprintf(stderr, "chaincompd: warning: mlockall not permitted (%s); continuing\n",
                                     std::strerror(errno));
  }
  if (cfg.sched_fifo_priority > 0) {
    sched_param p{};
    p.sched_priority = cfg.sched_fifo_priority;
    s.sched_fifo_ok = sched_setscheduler(0, SCHED_FIFO, &p) == 0;
    if (!s.sched_fifo_ok)
      std::fprintf(stderr, "chaincompd: warning: SCHED_FIFO priority %d not permitted (%s); continuing\n",
                   cfg.sched_fifo_priority, std::strerror(errno));
  }
  if (cfg.cpu >= 0) {
    cpu_set_t set;
    CPU_ZERO(&set);
    CPU_SET(cfg.cpu, &set);
    s.cpu_pinned_ok = sched_setaffinity(0, sizeof set, &set) == 0;
    if (!s.cpu_pinned_ok)
      std::fprintf(stderr, "chaincompd: warning: pinning to CPU %d not permitted (%s); continuing\n", cfg.cpu,
                   std::strerror(errno));
  }
}

int fail(const std::string& msg) {
  std::fprintf(stderr, "chaincompd: error: %s\n", msg.c_str());
  return 2;
}

}  // namespace

int main(int argc, char** argv) {
  std::string machine_path, params_path, config_path;
  for (int i = 1; i < argc; ++i) {
    const std::string a = argv[i];
    if (a == "-h" || a == "--help") {
      std::fputs(kUsage, stdout);
      return 0;
    }
    if ((a == "--machine" || a == "--params" || a == "--config") && i + 1 < argc) {
      (a == "--machine" ? machine_path : a == "--params" ? params_path : config_path) = argv[++i];
    } else {
      std::fputs(kUsage, stderr);
      return fail("unexpected argument '" + a + "'");
    }
  }
  if (machine_path.empty() || params_path.empty()) {
    std::fputs(kUsage, stderr);
    return fail("--machine and --params are required");
  }

  std::string error;
  const chaincomp::ModelEntry* entry = chaincomp::open_machine(machine_path, error);
  if (!entry) return fail(error);
  std::vector<double> params;
  if (!chaincomp::load_params(*entry->info, params_path, params, error)) return fail(error);
  auto d = std::make_unique<Daemon>();
  if (!chaincomp::load_daemon_config(*entry->info, config_path, d->config, error)) return fail(error);
  // The model lives in heap storage sized for it, filled once.
  std::unique_ptr<unsigned char[]> model_storage(new unsigned char[entry->model_size + entry->model_align]);
  void* model = model_storage.get();
  std::size_t space = entry->model_size + entry->model_align;
  model = std::align(entry->model_align, entry->model_size, model, space);
  entry->prepare(params.data(), model);

  d->lcm = lcm_create(d->config.lcm_url.c_str());
  if (!d->lcm) return fail("cannot open LCM at '" + d->config.lcm_url + "'");
  d->comp = std::make_unique<chaincomp::Compensator>(*entry, model, d->config.compensator);
  d->latency = chaincomp::LatencyWindow(d->config.latency_window);
  d->cmd_msg.machine.reserve(kMaxMachineName + 1);  // machine_name_fits() keeps names within it
  d->out_buf.resize(d->out_msg.getEncodedSize() + 64);
  auto& s = d->status_msg;
  s.machine = entry->info->name;
  s.model_hash = hex(entry->info->source_hash);
  s.params_file = params_path;
  s.params_hash = file_hash(params_path);
  realtime_settings(d->config, s);
  d->status_buf.resize(s.getEncodedSize() + 64);
  lcm_subscribe(d->lcm, d->config.command_channel.c_str(), on_command, d.get());
  lcm_subscribe(d->lcm, d->config.control_channel.c_str(), on_control, d.get());

  struct sigaction sa {};
  sa.sa_handler = on_signal;
  sigaction(SIGINT, &sa, nullptr);
  sigaction(SIGTERM, &sa, nullptr);
  // An LD_PRELOAD allocation counter, when present, measures the steady state.
  d->alloc_count = reinterpret_cast<long long (*)()>(dlsym(RTLD_DEFAULT, "chaincomp_alloc_count"));
  std::fprintf(stderr, "chaincompd: %s (model %s) with %s on %s: %s -> %s; ready\n", entry->info->name,
               s.model_hash.c_str(), params_path.c_str(), d->config.lcm_url.c_str(),
               d->config.command_channel.c_str(), d->config.corrected_channel.c_str());
  d->started = Clock::now();
  // A first status announces the daemon and makes LCM's lazy allocations for publishing.
  publish_status(*d, false);

  const int fd = lcm_get_fileno(d->lcm);
  const auto period_ns = static_cast<std::int64_t>(d->config.status_period_s * 1e9);
  auto next_status = Clock::now();
  while (!g_stop) {
    const std::int64_t wait_ns = std::chrono::duration_cast<std::chrono::nanoseconds>(next_status - Clock::now()).count();
    pollfd pfd{fd, POLLIN, 0};
    const int r = poll(&pfd, 1, wait_ns > 0 ? static_cast<int>(wait_ns / 1000000 + 1) : 0);
    if (r > 0 && (pfd.revents & POLLIN)) lcm_handle(d->lcm);
    if (Clock::now() >= next_status) {
      publish_status(*d, false);
      next_status += std::chrono::nanoseconds(period_ns);
    }
  }
  publish_status(*d, true);
  const auto& k = d->comp->counters();
  std::fprintf(stderr, "chaincompd: stopped: received %lld, published %lld\n", static_cast<long long>(k.received),
               static_cast<long long>(k.published));
  lcm_destroy(d->lcm);
  return 0;
}
