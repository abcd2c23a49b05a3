// The daemon's per-stream rings (issue 39 item 3): what a full ring drops is counted one by one,
// messages come out whole and in order, one larger than the largest valid is refused (queued empty, marked:
// its stream counts it undecodable, in its place in the order); and the node handles
// the rings' messages in the order they arrived across streams, also with its receive thread
// running beside a sender and its main loop (the ThreadSanitizer build's race check: tools/test).
#include <catch2/catch.hpp>

#include <lcm/lcm.h>
#include <poll.h>
#include <sys/resource.h>
#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <cerrno>
#include <chrono>
#include <cstdint>
#include <cstring>
#include <exception>
#include <functional>
#include <stdexcept>
#include <string>
#include <thread>
#include <vector>

#include "chaincomp/lcm_node.hpp"
#include "node_model.hpp"

namespace {

using chaincomp::MessageRing;

std::vector<unsigned char> bytes_of(std::int64_t k, std::size_t size) {
  std::vector<unsigned char> b(size);
  for (std::size_t i = 0; i < size; ++i) b[i] = static_cast<unsigned char>((k * 31 + i) & 0xFF);
  return b;
}

// Without Catch's assertions, which only the test's own thread may make.
template <class M>
std::vector<unsigned char> encoded(const M& m) {
  std::vector<unsigned char> b(m.getEncodedSize());
  if (m.encode(b.data(), 0, static_cast<int>(b.size())) <= 0) b.clear();
  return b;
}

template <class M>
std::vector<unsigned char> encode(const M& m) {
  auto b = encoded(m);
  REQUIRE(!b.empty());
  return b;
}

}  // namespace

TEST_CASE("a full ring drops and counts, keeps the order, refuses a message larger than the largest", "[ring]") {
  MessageRing ring(4, 16);
  for (std::int64_t k = 0; k < 6; ++k) {
    const auto b = bytes_of(k, 1 + k);
    CHECK(ring.push(b.data(), b.size(), k, 1000 + k) == (k < 4 ? MessageRing::Push::kOk : MessageRing::Push::kFull));
  }
  CHECK(ring.dropped() == 2);   // the fifth and sixth: none of those kept overwritten
  const auto big = bytes_of(9, 17);
  CHECK(ring.push(big.data(), big.size(), 9, 0) == MessageRing::Push::kFull);   // full first
  CHECK(ring.oversized() == 0);
  CHECK(ring.dropped() == 3);
  for (std::int64_t k = 0; k < 4; ++k) {
    const MessageRing::Message* m = ring.front();
    REQUIRE(m != nullptr);
    CHECK(m->arrival == k);
    CHECK(m->recv_utime == 1000 + k);
    CHECK(!m->oversized);
    CHECK(std::vector<unsigned char>(m->data, m->data + m->size) == bytes_of(k, 1 + k));
    ring.pop();
  }
  CHECK(ring.front() == nullptr);
  // with room: refused, not truncated: in the order, empty and marked
  CHECK(ring.push(big.data(), big.size(), 10, 0) == MessageRing::Push::kOversized);
  CHECK(ring.oversized() == 1);
  REQUIRE(ring.front() != nullptr);
  CHECK(ring.front()->oversized);
  CHECK(ring.front()->size == 0);
  CHECK(ring.front()->arrival == 10);
  ring.pop();
  // the largest size exactly, around the end of the buffer many times
  for (std::int64_t k = 0; k < 50; ++k) {
    const auto full = bytes_of(k, 16);
    REQUIRE(ring.push(full.data(), full.size(), k, 0) == MessageRing::Push::kOk);
    REQUIRE(ring.front() != nullptr);
    CHECK(std::vector<unsigned char>(ring.front()->data, ring.front()->data + 16) == full);
    ring.pop();
  }
}

TEST_CASE("a ring smaller than its count of the largest: the bytes bound it too, whatever the sizes", "[ring]") {
  // 100 messages within 512 bytes (records of 32-byte headers and the bytes, in 32-byte steps):
  // small ones up to the count, the largest (200 bytes: 256 a record) two at least
  MessageRing ring(100, 200, 512);
  CHECK(ring.capacity() == 100);
  CHECK(ring.buffer_bytes() == 512);
  const auto small = bytes_of(1, 0);
  for (int k = 0; k < 16; ++k) CHECK(ring.push(small.data(), 0, k, 0) == MessageRing::Push::kOk);
  CHECK(ring.push(small.data(), 0, 16, 0) == MessageRing::Push::kFull);   // 16 records of 32 bytes: full
  for (int k = 0; k < 16; ++k) ring.front(), ring.pop();
  CHECK(ring.front() == nullptr);
  std::int64_t kept = 0;
  for (std::int64_t k = 0; k < 300; ++k) {
    const auto b = bytes_of(k, static_cast<std::size_t>(k * 37 % 201));
    if (ring.push(b.data(), b.size(), k, 0) == MessageRing::Push::kOk) ++kept;
    if (k % 3 == 2) {   // the consumer behind: out in order, whole
      while (const MessageRing::Message* m = ring.front()) {
        CHECK(std::vector<unsigned char>(m->data, m->data + m->size) == bytes_of(m->arrival, m->arrival * 37 % 201));
        ring.pop();
      }
    }
  }
  CHECK(kept + ring.dropped() == 300 + 1);   // and the one above
  CHECK(ring.dropped() > 1);
  MessageRing counted(3, 8);
  for (int k = 0; k < 5; ++k) counted.push(small.data(), 0, k, 0);
  CHECK(counted.dropped() == 2);   // the count bounds it where the bytes would not
}

TEST_CASE("between two threads: every message out whole and in order, or counted dropped", "[ring]") {
  constexpr std::int64_t kMessages = 200000;
  MessageRing ring(64, 32);
  std::thread producer([&] {
    for (std::int64_t k = 0; k < kMessages; ++k) {
      const auto b = bytes_of(k, 8 + k % 24);
      ring.push(b.data(), b.size(), k, 0);
    }
  });
  std::int64_t taken = 0, last = -1;
  bool whole = true, ordered = true;
  const auto done = [&] { return taken + ring.dropped() == kMessages; };
  while (!done() || ring.front() != nullptr) {
    const MessageRing::Message* m = ring.front();
    if (m == nullptr) continue;
    ordered = ordered && m->arrival > last;
    last = m->arrival;
    whole = whole && std::vector<unsigned char>(m->data, m->data + m->size) == bytes_of(m->arrival, 8 + m->arrival % 24);
    ring.pop();
    ++taken;
  }
  producer.join();
  CHECK(ordered);
  CHECK(whole);
  CHECK(taken + ring.dropped() == kMessages);
  CHECK(taken > 0);
}

TEST_CASE("the node handles its rings in arrival order across streams and counts what they drop", "[ring][lcm]") {
  const chaincomp::ModelEntry& entry = *chaincomp::find_model("five_axis_ac");
  alignas(64) static unsigned char model[1 << 14];
  chaincomp::DaemonConfig config;
  prepare_node_model(entry, model, config, 2e-5);
  for (auto& a : config.compensator.axes) a.max_correction_step = 1.0;
  config.compensator.ramp_time_s = 0.0;   // on and off at once: the flag tells which control came first

  lcm_t* lcm = lcm_create("memq://");
  REQUIRE(lcm != nullptr);
  std::vector<chaincomp_lcm::lcmt_corrected_target> targets;
  std::vector<chaincomp_lcm::lcmt_chaincomp_status> status;
  lcm_subscribe(lcm, "CHAINCOMP_CORRECTED", [](const lcm_recv_buf_t* rbuf, const char*, void* user) {
    chaincomp_lcm::lcmt_corrected_target t;
    if (t.decode(rbuf->data, 0, static_cast<int>(rbuf->data_size)) >= 0)
      static_cast<std::vector<chaincomp_lcm::lcmt_corrected_target>*>(user)->push_back(t);
  }, &targets);
  lcm_subscribe(lcm, "CHAINCOMP_STATUS", [](const lcm_recv_buf_t* rbuf, const char*, void* user) {
    chaincomp_lcm::lcmt_chaincomp_status s;
    REQUIRE(s.decode(rbuf->data, 0, static_cast<int>(rbuf->data_size)) >= 0);
    static_cast<std::vector<chaincomp_lcm::lcmt_chaincomp_status>*>(user)->push_back(s);
  }, &status);
  {
    chaincomp::LcmNode node(lcm, entry, model, config, "p.yaml", "0", {});
    node.handle_until_idle();   // its first status
    chaincomp_lcm::lcmt_axis_command c{};
    c.machine = "five_axis_ac";
    c.num_axes = 5;
    const double axes[8] = {10, -20, -100, 30, -45, 0, 0, 0};
    std::memcpy(c.axes, axes, sizeof axes);
    const auto publish_command = [&](std::int64_t seq) {
      c.seq = seq;
      c.utime = 1000 * seq;
      const auto b = encode(c);
      lcm_publish(lcm, "CHAINCOMP_COMMAND", b.data(), static_cast<unsigned>(b.size()));
    };
    const auto publish_control = [&](bool enable) {
      chaincomp_lcm::lcmt_chaincomp_control k{};
      k.enable = enable;
      const auto b = encode(k);
      lcm_publish(lcm, "CHAINCOMP_CONTROL", b.data(), static_cast<unsigned>(b.size()));
    };
    // queued on two streams, not yet handled: off, command 1, on, command 2, off, command 3
    publish_control(false);
    publish_command(1);
    publish_control(true);
    publish_command(2);
    publish_control(false);
    publish_command(3);
    for (int i = 0; i < 6; ++i) REQUIRE(lcm_handle_timeout(lcm, 0) > 0);   // the receive side only
    CHECK(node.counters().received == 0);
    CHECK(node.handle_queued() == 6);
    node.handle_until_idle();
    REQUIRE(targets.size() == 3);
    const int on = chaincomp_lcm::lcmt_corrected_target::FLAG_COMPENSATING;
    CHECK((targets[0].flags & on) == 0);
    CHECK((targets[1].flags & on) == on);
    CHECK((targets[2].flags & on) == 0);

    // a full control ring: the messages beyond it dropped and counted, those kept applied
    for (int i = 0; i < chaincomp::LcmNode::kControlQueueCapacity + 7; ++i) {
      publish_control(true);
      REQUIRE(lcm_handle_timeout(lcm, 0) > 0);
    }
    // a command larger than the largest valid one (a 255-byte machine name) is refused whole
    c.machine.assign(chaincomp::LcmNode::kMaxMachineName, 'x');
    const auto largest = encode(c);
    std::vector<unsigned char> over(largest);
    over.push_back(0);
    lcm_publish(lcm, "CHAINCOMP_COMMAND", largest.data(), static_cast<unsigned>(largest.size()));
    lcm_publish(lcm, "CHAINCOMP_COMMAND", over.data(), static_cast<unsigned>(over.size()));
    node.handle_until_idle();
    node.publish_status(true);
    node.handle_until_idle();
    REQUIRE(!status.empty());
    const auto& s = status.back();
    CHECK(s.control_received == 3 + chaincomp::LcmNode::kControlQueueCapacity);
    CHECK(s.control_queue_dropped == 7);
    CHECK(s.control_queue_capacity == chaincomp::LcmNode::kControlQueueCapacity);
    CHECK(s.oversized == 1);
    // both received: the largest valid size whole (another machine), the larger one as nothing
    CHECK(s.received == 5);
    CHECK(s.rejected[static_cast<int>(chaincomp::Reject::kWrongMachine)] == 1);
    CHECK(s.rejected[static_cast<int>(chaincomp::Reject::kUndecodable)] == 1);
    CHECK(s.queue_dropped == 0);
    CHECK(s.lcm_queue_full == 0);
    CHECK(s.lcm_queue_capacity == chaincomp::LcmNode::kLcmQueueCapacity);
    CHECK(s.compensating);
  }
  lcm_destroy(lcm);
}

TEST_CASE("with its receive thread: a publisher thread's commands and controls each handled in order or counted "
          "dropped, while the main thread publishes targets and status", "[ring][lcm][thread]") {
  // The daemon's three threads in one process (memq://): a sender publishing, the node's receive
  // thread in lcm_handle, the main thread waiting on wake_fd as chaincompd does. Built with
  // -fsanitize=thread this is the race check of the receive side (docs/guide/daemon.md).
  const chaincomp::ModelEntry& entry = *chaincomp::find_model("five_axis_ac");
  alignas(64) static unsigned char model[1 << 14];
  chaincomp::DaemonConfig config;
  prepare_node_model(entry, model, config);
  lcm_t* lcm = lcm_create("memq://");
  REQUIRE(lcm != nullptr);
  std::vector<std::int64_t> seqs;   // the targets' seq, appended by the receive thread, read after its join
  lcm_subscription_t* sub = lcm_subscribe(lcm, "CHAINCOMP_CORRECTED", [](const lcm_recv_buf_t* rbuf, const char*,
                                                                          void* user) {
    chaincomp_lcm::lcmt_corrected_target t;
    if (t.decode(rbuf->data, 0, static_cast<int>(rbuf->data_size)) >= 0)
      static_cast<std::vector<std::int64_t>*>(user)->push_back(t.seq);
  }, &seqs);
  lcm_subscription_set_queue_capacity(sub, chaincomp::LcmNode::kLcmQueueCapacity);
  constexpr std::int64_t kCommands = 20000, kControlEvery = 100;
  std::int64_t published = 0, queue_dropped = 0;
  {
    chaincomp::LcmNode node(lcm, entry, model, config, "p.yaml", "0", {});
    node.start_receiving();
    std::atomic<bool> sent{false};
    std::thread sender([&] {
      chaincomp_lcm::lcmt_axis_command c{};
      c.machine = "five_axis_ac";
      c.num_axes = 5;
      chaincomp_lcm::lcmt_chaincomp_control k{};
      k.enable = true;
      const auto control = encoded(k);
      for (std::int64_t seq = 1; seq <= kCommands; ++seq) {
        c.seq = seq;
        c.utime = 1000 * seq;
        c.axes[0] = 1e-3 * static_cast<double>(seq % 1000);
        const auto b = encoded(c);
        lcm_publish(lcm, "CHAINCOMP_COMMAND", b.data(), static_cast<unsigned>(b.size()));
        if (seq % kControlEvery == 0)
          lcm_publish(lcm, "CHAINCOMP_CONTROL", control.data(), static_cast<unsigned>(control.size()));
      }
      sent = true;
    });
    // the daemon's main loop: wait, read the eventfd empty, handle what the rings hold; a status now and then
    const auto settled = [&] {
      const auto& s = node.last_status();
      return sent && s.received + s.queue_dropped == kCommands &&
             s.control_received + s.control_queue_dropped == kCommands / kControlEvery;
    };
    const auto deadline = std::chrono::steady_clock::now() + std::chrono::seconds(120);
    int woken = 0;
    while (!settled() && std::chrono::steady_clock::now() < deadline) {
      pollfd pfd{node.wake_fd(), POLLIN, 0};
      if (poll(&pfd, 1, 10) > 0) {
        std::uint64_t n = 0;
        CHECK(read(node.wake_fd(), &n, sizeof n) == sizeof n);
        node.handle_queued();
        ++woken;
      }
      node.publish_status(false);
    }
    sender.join();
    node.stop_receiving();
    node.handle_until_idle();
    node.publish_status(true);
    const auto& s = node.last_status();
    WARN("commands sent " << kCommands << ": received " << s.received << ", dropped at the full ring "
         << s.queue_dropped << "; the main thread woken " << woken << " times");
    // what the sender sent, each accounted for exactly once
    CHECK(s.received + s.queue_dropped == kCommands);
    CHECK(s.control_received + s.control_queue_dropped == kCommands / kControlEvery);
    CHECK(s.control_refused == 0);
    CHECK(s.lcm_queue_full == 0);
    CHECK(s.oversized == 0);
    CHECK(s.received > 0);
    std::int64_t rejected = 0;
    for (const auto r : s.rejected) rejected += r;
    CHECK(rejected == 0);
    CHECK(s.published == s.received);
    published = s.published;
    queue_dropped = s.queue_dropped;
  }
  while (lcm_handle_timeout(lcm, 0) > 0) {
  }
  // every command is a target on the bus, in the order sent, or dropped at the ring
  CHECK(static_cast<std::int64_t>(seqs.size()) == published);
  CHECK(static_cast<std::int64_t>(seqs.size()) + queue_dropped == kCommands);
  CHECK(std::adjacent_find(seqs.begin(), seqs.end(), std::greater_equal<std::int64_t>()) == seqs.end());
  lcm_destroy(lcm);
}

TEST_CASE("a node that cannot have its wake-up eventfd refuses to start (it would wake only at each status)",
          "[ring][lcm]") {
  const chaincomp::ModelEntry& entry = *chaincomp::find_model("five_axis_ac");
  alignas(64) static unsigned char model[1 << 14];
  chaincomp::DaemonConfig config;
  prepare_node_model(entry, model, config);
  lcm_t* lcm = lcm_create("memq://");
  REQUIRE(lcm != nullptr);
  // every descriptor below a low limit taken: the next one the process opens fails with EMFILE
  rlimit before{};
  REQUIRE(getrlimit(RLIMIT_NOFILE, &before) == 0);
  rlimit low = before;
  low.rlim_cur = 64;
  REQUIRE(setrlimit(RLIMIT_NOFILE, &low) == 0);
  std::vector<int> taken;
  for (int fd; (fd = dup(lcm_get_fileno(lcm))) >= 0;) taken.push_back(fd);
  const int why = errno;
  std::exception_ptr thrown;
  try {
    chaincomp::LcmNode node(lcm, entry, model, config, "p.yaml", "0", {});
  } catch (...) {
    thrown = std::current_exception();  // looked at once descriptors are back (sanitizers need some)
  }
  for (const int fd : taken) close(fd);
  REQUIRE(setrlimit(RLIMIT_NOFILE, &before) == 0);
  CHECK(why == EMFILE);
  REQUIRE(thrown);
  std::string message;
  try {
    std::rethrow_exception(thrown);
  } catch (const std::runtime_error& e) {
    message = e.what();
  }
  CHECK(message.find("eventfd") != std::string::npos);
  CHECK(message.find(std::strerror(EMFILE)) != std::string::npos);
  lcm_destroy(lcm);
}
