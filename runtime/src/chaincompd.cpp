// chaincompd: takes commanded axis positions over LCM and publishes corrected targets.
// A receive thread copies each message into its stream's ring (LcmNode); the main thread waits
// on the node's wake fd and handles them; no heap allocation after start-up.
#include <lcm/lcm.h>
#include <poll.h>
#include <pthread.h>
#include <sched.h>
#include <sys/mman.h>
#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <cerrno>
#include <chrono>
#include <csignal>
#include <cstdio>
#include <cstring>
#include <exception>
#include <memory>
#include <string>

#include "chaincomp/daemon_config.hpp"
#include "chaincomp/loaded_model.hpp"
#include "chaincomp/lcm_node.hpp"
#include "chaincomp/params_io.hpp"

namespace {

std::atomic<bool> g_stop{false};
void on_signal(int) { g_stop = true; }

const char* kUsage =
    "usage: chaincompd --machine M.yaml --params P.yaml [--config R.yaml] [--model LIB.so] [--thermal T.yaml]\n"
    "Subscribes to commanded axis positions over LCM and publishes corrected targets.\n"
    "  --machine M.yaml  machine description: its compiled-in model, else one built at start-up\n"
    "                    (chaincomp build; cached in $XDG_CACHE_HOME/chaincomp)\n"
    "  --model LIB.so    a model library made by chaincomp build for exactly this machine file\n"
    "  --params P.yaml   error values of the machine (configs/params/)\n"
    "  --config R.yaml   runtime settings (configs/runtime/default.yaml documents every key)\n"
    "  --thermal T.yaml  a thermal model (chaincomp thermal fit): errors that follow the temperatures\n"
    "                    on the temperatures channel\n"
    "  --version         print the version and exit\n";

// Each setting degrades with one warning when the system does not permit it.
chaincomp::RealtimeObtained realtime_settings(const chaincomp::DaemonConfig& cfg) {
  chaincomp::RealtimeObtained got;
  if (cfg.mlockall) {
    got.mlockall = mlockall(MCL_CURRENT | MCL_FUTURE) == 0;
    if (!got.mlockall)
      std::fprintf(stderr, "chaincompd: warning: mlockall not permitted (%s); continuing\n", std::strerror(errno));
  }
  if (cfg.sched_fifo_priority > 0) {
    sched_param p{};
    p.sched_priority = cfg.sched_fifo_priority;
    got.sched_fifo = sched_setscheduler(0, SCHED_FIFO, &p) == 0;
    if (!got.sched_fifo)
      std::fprintf(stderr, "chaincompd: warning: SCHED_FIFO priority %d not permitted (%s); continuing\n",
                   cfg.sched_fifo_priority, std::strerror(errno));
  }
  if (cfg.cpu >= 0) {
    cpu_set_t set;
    CPU_ZERO(&set);
    CPU_SET(cfg.cpu, &set);
    got.cpu_pinned = sched_setaffinity(0, sizeof set, &set) == 0;
    if (!got.cpu_pinned)
      std::fprintf(stderr, "chaincompd: warning: pinning to CPU %d not permitted (%s); continuing\n", cfg.cpu,
                   std::strerror(errno));
  }
  return got;
}

int fail(const std::string& msg) {
  std::fprintf(stderr, "chaincompd: error: %s\n", msg.c_str());
  return 2;
}

}  // namespace

int run_daemon(int argc, char** argv) {
  std::string machine_path, params_path, config_path, model_path, thermal_path;
  for (int i = 1; i < argc; ++i) {
    const std::string a = argv[i];
    if (a == "-h" || a == "--help") {
      std::fputs(kUsage, stdout);
      return 0;
    }
    if (a == "--version") {
      std::puts("chaincompd " CHAINCOMP_VERSION);
      return 0;
    }
    if ((a == "--machine" || a == "--params" || a == "--config" || a == "--model" || a == "--thermal") &&
        i + 1 < argc) {
      (a == "--machine" ? machine_path : a == "--params" ? params_path : a == "--model" ? model_path
       : a == "--thermal" ? thermal_path : config_path) = argv[++i];
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
  chaincomp::LoadedModel loaded;
  if (!chaincomp::load_model(machine_path, model_path, params_path, config_path, loaded, error)) return fail(error);
  const chaincomp::ModelEntry* entry = loaded.entry;
  const chaincomp::DaemonConfig& config = loaded.config;
  void* model = loaded.model;
  chaincomp::ThermalModel thermal_model;
  if (!thermal_path.empty() && !chaincomp::load_thermal_model(*entry->info, thermal_path, thermal_model, error))
    return fail(error);

  lcm_t* lcm = lcm_create(config.lcm_url.c_str());
  if (!lcm) return fail("cannot open LCM at '" + config.lcm_url + "'");
  const chaincomp::RealtimeObtained rt = realtime_settings(config);
  auto node = std::make_unique<chaincomp::LcmNode>(lcm, *entry, model, config, params_path, chaincomp::file_hash_hex(params_path), rt);

  chaincomp::ParamsUpdater updater(*entry, model, &loaded.varying, loaded.params, config.params_updates);
  node->accept_params_updates(updater);
  std::unique_ptr<chaincomp::ThermalState> thermal;
  if (!thermal_path.empty()) {
    thermal = std::make_unique<chaincomp::ThermalState>(thermal_model, loaded.params);
    node->accept_temperatures(*thermal);
    std::fprintf(stderr, "chaincompd: thermal model %s: %d errors from %zu sensors on %s\n", thermal_path.c_str(),
                 thermal_model.num_errors, thermal_model.sensors.size(), config.temperatures_channel.c_str());
  }

  struct sigaction sa {};
  sa.sa_handler = on_signal;
  sigaction(SIGINT, &sa, nullptr);
  sigaction(SIGTERM, &sa, nullptr);
  // Both are taken only inside ppoll (blocked elsewhere): one arriving just after the loop looked
  // at g_stop would otherwise wait for the next status (status_period) before the daemon stops.
  sigset_t stop_signals, waiting;
  sigemptyset(&stop_signals);
  sigaddset(&stop_signals, SIGINT);
  sigaddset(&stop_signals, SIGTERM);
  pthread_sigmask(SIG_BLOCK, &stop_signals, &waiting);
  sigdelset(&waiting, SIGINT);
  sigdelset(&waiting, SIGTERM);
  // The kernel reports twice the size asked (its bookkeeping); less means net.core.rmem_max capped it.
  const long long got = node->recv_buf_bytes();
  if (config.lcm_url.rfind("udpm://", 0) == 0 && got >= 0 && got < 2LL * config.recv_buf_size) {
    std::fprintf(stderr, "chaincompd: warning: socket receive buffer %lld bytes, not the %d asked "
                 "(recv_buf_size; raise net.core.rmem_max); continuing\n", got / 2, config.recv_buf_size);
  }
  node->start_receiving();   // after every subscription, before 'ready' (a thread's niceness is its creator's)
  const std::string tables = chaincomp::describe_varying(loaded.varying);
  std::fprintf(stderr, "chaincompd: %s with %s%s on %s: %s -> %s; instance %016llx; ready\n", entry->info->name,
               params_path.c_str(), tables.empty() ? "" : (" (" + tables + ")").c_str(), config.lcm_url.c_str(),
               config.command_channel.c_str(), config.corrected_channel.c_str(),
               static_cast<unsigned long long>(node->instance_id()));

  using Clock = std::chrono::steady_clock;
  const int fd = node->wake_fd();
  const auto period = std::chrono::nanoseconds(static_cast<std::int64_t>(config.status_period_s * 1e9));
  auto next_status = Clock::now() + period;
  while (!g_stop) {
    // ppoll sleeps to the nanosecond: never a zero timeout while the status is not yet due
    // (poll's milliseconds would spin for the last one).
    const auto left = std::max(std::chrono::nanoseconds(0), next_status - Clock::now());
    const timespec wait{static_cast<time_t>(left.count() / 1000000000), static_cast<long>(left.count() % 1000000000)};
    pollfd pfd{fd, POLLIN, 0};
    const int r = ppoll(&pfd, 1, &wait, &waiting);
    if (r > 0 && (pfd.revents & POLLIN)) {
      std::uint64_t woken = 0;
      if (read(fd, &woken, sizeof woken) < 0) {
        // EAGAIN: already read; the rings are looked at anyway
      }
      node->handle_queued();
    }
    const auto now = Clock::now();
    if (now >= next_status) {
      node->publish_status(false);
      next_status += period;
      if (next_status <= now) next_status = now + period;  // after a stall: no burst to catch up
    }
  }
  // What the rings and LCM hold when asked to stop is handled before the final status: no
  // command received goes uncounted (bounded: a flood does not hold the exit up for ever).
  node->stop_receiving();
  node->handle_until_idle(4 * chaincomp::LcmNode::kQueueCapacity);
  node->publish_status(true);
  long long refused = 0;
  for (const auto n : updater.refused()) refused += n;
  std::fprintf(stderr, "chaincompd: params updates: received %lld, applied %lld (last seq %lld), refused %lld\n",
               static_cast<long long>(updater.received()), static_cast<long long>(updater.version()),
               static_cast<long long>(updater.last_seq()), refused);
  const auto& k = node->counters();
  std::fprintf(stderr, "chaincompd: stopped: received %lld, published %lld; clamped %lld (held back %lld), "
               "clamped input %lld; seq gaps %lld (%lld missing), stream restarts %lld, resets %lld, kernel drops "
               "%lld\n", static_cast<long long>(k.received), static_cast<long long>(k.published),
               static_cast<long long>(k.clamped), static_cast<long long>(k.held_back),
               static_cast<long long>(k.clamped_input), static_cast<long long>(k.seq_gaps),
               static_cast<long long>(k.seq_missing), static_cast<long long>(k.stream_restarts),
               static_cast<long long>(k.resets), static_cast<long long>(node->kernel_drops()));
  const auto& s = node->last_status();
  std::fprintf(stderr, "chaincompd: accounted: unpublished %lld, queue dropped %lld (control %lld), LCM's queues "
               "found full %lld times; latency: compute p50 %lld ns p99 %lld ns, receipt to publish p50 %lld ns p99 "
               "%lld ns (last %d)\n",
               static_cast<long long>(s.unpublished), static_cast<long long>(s.queue_dropped),
               static_cast<long long>(s.control_queue_dropped), static_cast<long long>(s.lcm_queue_full),
               static_cast<long long>(s.latency_p50_ns),
               static_cast<long long>(s.latency_p99_ns), static_cast<long long>(s.receipt_p50_ns),
               static_cast<long long>(s.receipt_p99_ns), s.window);
  node.reset();
  lcm_destroy(lcm);
  return 0;
}

// Exit codes, as chaincomp's (docs/reference/grammar.md): 0 done, 2 bad input (one line, from fail),
// 3 internal error (one line here, not an abort's core dump).
int main(int argc, char** argv) {
  try {
    return run_daemon(argc, argv);
  } catch (const std::exception& e) {
    std::fprintf(stderr, "chaincompd: internal error: %s (please report this with the command line)\n", e.what());
  } catch (...) {
    std::fprintf(stderr, "chaincompd: internal error (please report this with the command line)\n");
  }
  return 3;
}
