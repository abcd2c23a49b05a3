// lcm_echo: republishes every message of one channel untouched on another, with the same
// LCM setup as chaincompd: the transport floor of the latency benchmark.
#include <lcm/lcm.h>
#include <poll.h>

#include <algorithm>
#include <chrono>
#include <csignal>
#include <cstdint>
#include <cstdio>
#include <string>
#include <vector>

namespace {
volatile std::sig_atomic_t g_stop = 0;
void on_signal(int) { g_stop = 1; }
struct Echo {
  lcm_t* lcm;
  std::string out;
  std::vector<std::int64_t> receipt_ns;  // LCM's receive stamp to published, as chaincompd measures it
};
void on_message(const lcm_recv_buf_t* rbuf, const char*, void* user) {
  auto* e = static_cast<Echo*>(user);
  if (lcm_publish(e->lcm, e->out.c_str(), rbuf->data, rbuf->data_size) != 0) return;
  const auto now = std::chrono::duration_cast<std::chrono::nanoseconds>(
                       std::chrono::system_clock::now().time_since_epoch()).count();
  if (e->receipt_ns.size() < e->receipt_ns.capacity()) e->receipt_ns.push_back(now - rbuf->recv_utime * 1000);
}
std::int64_t percentile(std::vector<std::int64_t>& v, double q) {
  if (v.empty()) return -1;
  auto it = v.begin() + static_cast<std::size_t>(q * (v.size() - 1) + 0.5);  // as chaincompd's LatencyWindow
  std::nth_element(v.begin(), it, v.end());
  return *it;
}
}  // namespace

int main(int argc, char** argv) {
  if (argc != 4) {
    std::fprintf(stderr, "usage: lcm_echo LCM_URL IN_CHANNEL OUT_CHANNEL\n");
    return 2;
  }
  Echo e{lcm_create(argv[1]), argv[3], {}};
  e.receipt_ns.reserve(1 << 20);
  if (!e.lcm) {
    std::fprintf(stderr, "lcm_echo: error: cannot open LCM at '%s'\n", argv[1]);
    return 2;
  }
  // The same queue capacity as chaincompd's command subscription (LCM's default is 30).
  lcm_subscription_set_queue_capacity(lcm_subscribe(e.lcm, argv[2], on_message, &e), 10000);
  struct sigaction sa {};
  sa.sa_handler = on_signal;
  sigaction(SIGINT, &sa, nullptr);
  sigaction(SIGTERM, &sa, nullptr);
  std::fprintf(stderr, "lcm_echo: %s -> %s; ready\n", argv[2], argv[3]);
  const int fd = lcm_get_fileno(e.lcm);
  while (!g_stop) {
    pollfd pfd{fd, POLLIN, 0};
    if (poll(&pfd, 1, 100) > 0 && (pfd.revents & POLLIN)) lcm_handle(e.lcm);
  }
  lcm_destroy(e.lcm);
  const std::size_t n = e.receipt_ns.size();
  const std::int64_t p50 = percentile(e.receipt_ns, 0.5), p99 = percentile(e.receipt_ns, 0.99);
  std::fprintf(stderr, "lcm_echo: latency: receipt to publish p50 %lld ns p99 %lld ns (last %zu)\n",
               static_cast<long long>(p50), static_cast<long long>(p99), n);
  return 0;
}
