// The LCM layer on LCM's in-process memq:// provider: commands in, targets and status out.
#include <catch2/catch.hpp>

#include <lcm/lcm.h>

#include <cmath>
#include <cstring>
#include <new>
#include <string>
#include <vector>

#include "chaincomp/compensate.hpp"
#include "chaincomp/lcm_node.hpp"
#include "held_back_case.hpp"
#include "node_model.hpp"

namespace {

struct Inbox {
  std::vector<chaincomp_lcm::lcmt_corrected_target> targets;
  std::vector<chaincomp_lcm::lcmt_chaincomp_status> status;
};

void on_target(const lcm_recv_buf_t* rbuf, const char*, void* user) {
  chaincomp_lcm::lcmt_corrected_target t;
  // (a test publishes a truncated one)
  if (t.decode(rbuf->data, 0, static_cast<int>(rbuf->data_size)) >= 0) static_cast<Inbox*>(user)->targets.push_back(t);
}

void on_status(const lcm_recv_buf_t* rbuf, const char*, void* user) {
  chaincomp_lcm::lcmt_chaincomp_status s;
  REQUIRE(s.decode(rbuf->data, 0, static_cast<int>(rbuf->data_size)) >= 0);
  static_cast<Inbox*>(user)->status.push_back(s);
}

// LCM's handlers (the node's copy into its rings) and the node's in turn, as its two threads would.
void drain(chaincomp::LcmNode& node) { node.handle_until_idle(); }

std::vector<unsigned char> encode(const chaincomp_lcm::lcmt_axis_command& c) {
  std::vector<unsigned char> buf(c.getEncodedSize());
  REQUIRE(c.encode(buf.data(), 0, static_cast<int>(buf.size())) > 0);
  return buf;
}

}  // namespace

TEST_CASE("commands over memq:// come back corrected, bad payloads are counted", "[lcm]") {
  const chaincomp::ModelEntry& entry = *chaincomp::find_model("five_axis_ac");
  alignas(64) static unsigned char model[1 << 14];
  chaincomp::DaemonConfig config;
  prepare_node_model(entry, model, config, 2e-5);
  for (auto& a : config.compensator.axes) a.max_correction_step = 1.0;

  lcm_t* lcm = lcm_create("memq://");
  REQUIRE(lcm != nullptr);
  Inbox inbox;
  lcm_subscribe(lcm, "CHAINCOMP_CORRECTED", on_target, &inbox);
  lcm_subscribe(lcm, "CHAINCOMP_STATUS", on_status, &inbox);
  {
    chaincomp::LcmNode node(lcm, entry, model, config, "p.yaml", "0", {});
    chaincomp_lcm::lcmt_axis_command c;
    c.utime = 1000;
    c.seq = 1;
    c.machine = "five_axis_ac";
    c.num_axes = 5;
    const double axes[8] = {10, -20, -100, 30, -45, 0, 0, 0};
    std::memcpy(c.axes, axes, sizeof axes);
    auto good = encode(c);
    lcm_publish(lcm, "CHAINCOMP_COMMAND", good.data(), static_cast<unsigned>(good.size()));
    drain(node);
    REQUIRE(inbox.targets.size() == 1);
    const auto& t = inbox.targets[0];
    CHECK(t.seq == 1);
    CHECK(t.utime == 1000);
    // the same correction as the model's own compensate (converted to mm / deg)
    double q[5], corrected[5], residual[2];
    for (int i = 0; i < 5; ++i) q[i] = axes[i] * entry.info->axes[i].to_internal;
    entry.compensate(model, nullptr, q, chaincomp::kDefaultDirectionWeight, corrected, residual, nullptr);
    for (int i = 0; i < 5; ++i) {
      CHECK(t.correction[i] == Approx((corrected[i] - q[i]) / entry.info->axes[i].to_internal).margin(1e-15));
      CHECK(t.axes[i] == Approx(axes[i] + t.correction[i]).margin(1e-12));
    }

    // undecodable: empty, too short, a string length of zero or of -1, random bytes
    std::vector<std::vector<unsigned char>> bad = {{}, {1, 2, 3}};
    for (std::int32_t len : {0, -1, 1 << 20}) {
      auto b = good;
      const unsigned char be[4] = {static_cast<unsigned char>(len >> 24), static_cast<unsigned char>(len >> 16),
                                   static_cast<unsigned char>(len >> 8), static_cast<unsigned char>(len)};
      std::memcpy(b.data() + 24, be, 4);
      bad.push_back(b);
    }
    for (const auto& b : bad) lcm_publish(lcm, "CHAINCOMP_COMMAND", b.data(), static_cast<unsigned>(b.size()));
    drain(node);
    node.publish_status(true);
    drain(node);
    REQUIRE(!inbox.status.empty());
    const auto& s = inbox.status.back();
    CHECK(s.received == 6);
    CHECK(s.published == 1);
    CHECK(s.rejected[static_cast<int>(chaincomp::Reject::kUndecodable)] == 5);
    CHECK(s.machine == "five_axis_ac");
    CHECK(s.final);
    CHECK(inbox.targets.size() == 1);
  }
  lcm_destroy(lcm);
}

TEST_CASE("targets and status carry the instance; another instance's targets for this machine are "
          "counted; a reset starts a new stream", "[lcm]") {
  const chaincomp::ModelEntry& entry = *chaincomp::find_model("five_axis_ac");
  alignas(64) static unsigned char model[1 << 14];
  chaincomp::DaemonConfig config;
  prepare_node_model(entry, model, config);
  lcm_t* lcm = lcm_create("memq://");
  REQUIRE(lcm != nullptr);
  Inbox inbox;
  lcm_subscribe(lcm, "CHAINCOMP_CORRECTED", on_target, &inbox);
  lcm_subscribe(lcm, "CHAINCOMP_STATUS", on_status, &inbox);
  {
    chaincomp::LcmNode node(lcm, entry, model, config, "p.yaml", "0", {});
    CHECK(node.instance_id() > 0);
    chaincomp_lcm::lcmt_axis_command c;
    c.utime = 1000;
    c.seq = 100;
    c.machine = "five_axis_ac";
    c.num_axes = 5;
    const double axes[8] = {10, -20, -100, 30, -45, 0, 0, 0};
    std::memcpy(c.axes, axes, sizeof axes);
    // lcm-gen's C++ encoder stops a string at a NUL (its decoder does not): `nul_at` puts one in
    auto publish = [&](const chaincomp_lcm::lcmt_axis_command& m, int nul_at = 0) {
      auto b = encode(m);
      if (nul_at) b[24 + 4 + nul_at] = 0;  // after fingerprint, utime, seq, the length
      lcm_publish(lcm, "CHAINCOMP_COMMAND", b.data(), static_cast<unsigned>(b.size()));
      drain(node);
    };
    publish(c);
    REQUIRE(inbox.targets.size() == 1);
    CHECK(inbox.targets[0].instance_id == node.instance_id());
    CHECK(inbox.targets[0].machine == "five_axis_ac");
    // a name with a NUL inside is another machine
    c.seq = 101;
    c.machine = "five_axis_acXx";
    publish(c, 12);
    CHECK(inbox.targets.size() == 1);

    // another daemon's targets: for this machine (counted), for another machine or with
    // a NUL inside the name (not), and a truncated one (ignored)
    chaincomp_lcm::lcmt_corrected_target other = inbox.targets[0];
    other.instance_id = node.instance_id() ^ 0x5a5a;
    auto publish_target = [&](const chaincomp_lcm::lcmt_corrected_target& t, int cut = 0, int nul_at = 0) {
      std::vector<unsigned char> b(t.getEncodedSize());
      REQUIRE(t.encode(b.data(), 0, static_cast<int>(b.size())) > 0);
      if (nul_at) b[196 + 4 + nul_at] = 0;
      lcm_publish(lcm, "CHAINCOMP_CORRECTED", b.data(), static_cast<unsigned>(b.size() - cut));
      drain(node);
    };
    publish_target(other);
    publish_target(other);
    publish_target(other, 3);
    other.machine = "angle_head";
    publish_target(other);
    other.machine = "five_axis_acX";
    publish_target(other, 0, 12);

    // a reset: seq 1 accepted at once
    c.machine = "five_axis_ac";
    c.seq = 1;
    chaincomp_lcm::lcmt_chaincomp_control ctl;
    ctl.utime = 0;
    ctl.enable = true;
    ctl.reset = true;
    std::vector<unsigned char> b(ctl.getEncodedSize());
    ctl.encode(b.data(), 0, static_cast<int>(b.size()));
    lcm_publish(lcm, "CHAINCOMP_CONTROL", b.data(), static_cast<unsigned>(b.size()));
    drain(node);
    publish(c);
    node.publish_status(true);
    drain(node);
    const auto& s = inbox.status.back();
    CHECK(s.instance_id == node.instance_id());
    CHECK(s.own_targets_heard == 2);  // memq delivers its own targets back, as udpm does
    CHECK(s.foreign_targets == 2);
    CHECK(s.foreign_instance == other.instance_id);
    CHECK(s.resets == 1);
    CHECK(s.published == 2);
    CHECK(s.rejected[static_cast<int>(chaincomp::Reject::kWrongMachine)] == 1);
    CHECK(s.kernel_drops == -1);  // memq: no socket
    CHECK(s.recv_buf_bytes == -1);
  }
  lcm_destroy(lcm);
}

TEST_CASE("the status message carries the corrections held back, as the compensator counts them", "[lcm][held_back]") {
  // a stream on which the limits must hold corrections back (held_back_case.hpp; the
  // compensator test predicts each one)
  const chaincomp::ModelEntry& entry = *chaincomp::find_model(held_back_case::kMachine);
  alignas(64) static unsigned char model[1 << 15];
  REQUIRE(entry.model_size <= sizeof model);
  held_back_case::prepare(entry, model);
  chaincomp::DaemonConfig config;
  std::string error;
  REQUIRE(held_back_case::config(entry, config, error));
  chaincomp::Compensator alone(entry, model, config.compensator);  // the same stream without LCM
  lcm_t* lcm = lcm_create("memq://");
  REQUIRE(lcm != nullptr);
  Inbox inbox;
  lcm_subscribe(lcm, "CHAINCOMP_STATUS", on_status, &inbox);
  {
    chaincomp::LcmNode node(lcm, entry, model, config, "p.yaml", "0", {});
    chaincomp_lcm::lcmt_axis_command c;
    c.machine = held_back_case::kMachine;
    for (int k = 0; k < held_back_case::kCommands; ++k) {
      const chaincomp::Command cmd = held_back_case::command(k);
      chaincomp::Target t;
      REQUIRE(alone.process(cmd, t));
      c.utime = cmd.utime;
      c.seq = cmd.seq;
      c.num_axes = cmd.num_axes;
      std::copy(cmd.axes.begin(), cmd.axes.end(), c.axes);
      const auto b = encode(c);
      lcm_publish(lcm, "CHAINCOMP_COMMAND", b.data(), static_cast<unsigned>(b.size()));
      drain(node);
      if (k == 1000) {  // before the first command that is held back: none on the status either
        REQUIRE(alone.counters().held_back == 0);
        node.publish_status(false);
        drain(node);
        REQUIRE(!inbox.status.empty());
        CHECK(inbox.status.back().held_back == 0);
        CHECK(inbox.status.back().clamped == node.counters().clamped);
      }
    }
    node.publish_status(true);
    drain(node);
    const auto& s = inbox.status.back();
    CHECK(s.final);
    CHECK(s.published == held_back_case::kCommands);
    CHECK(node.counters().held_back == alone.counters().held_back);
    CHECK(s.held_back == node.counters().held_back);
    CHECK(s.held_back > 100);
    CHECK(s.clamped == alone.counters().clamped);
  }
  lcm_destroy(lcm);
}

TEST_CASE("status carries only what the node put there: nodes built over memory filled with different bytes "
          "publish the same status for the same commands", "[lcm][status]") {
  const chaincomp::ModelEntry& entry = *chaincomp::find_model("five_axis_ac");
  alignas(64) static unsigned char model[1 << 14];
  chaincomp::DaemonConfig config;
  prepare_node_model(entry, model, config);
  struct Bytes {
    std::vector<std::vector<unsigned char>> status;
  };
  auto run = [&](unsigned char fill) {
    lcm_t* lcm = lcm_create("memq://");
    REQUIRE(lcm != nullptr);
    Bytes out;
    lcm_subscribe(lcm, "CHAINCOMP_STATUS", [](const lcm_recv_buf_t* rbuf, const char*, void* user) {
      const auto* b = static_cast<const unsigned char*>(rbuf->data);
      static_cast<Bytes*>(user)->status.emplace_back(b, b + rbuf->data_size);
    }, &out);
    // the node's memory holds `fill` before it is built: a field it leaves unset shows it
    alignas(chaincomp::LcmNode) static unsigned char storage[sizeof(chaincomp::LcmNode)];
    std::memset(storage, fill, sizeof storage);
    auto* node = new (storage) chaincomp::LcmNode(lcm, entry, model, config, "p.yaml", "0", {});
    chaincomp_lcm::lcmt_axis_command c{};
    c.machine = "five_axis_ac";
    c.num_axes = 5;
    for (int k = 1; k <= 20; ++k) {
      c.utime = 1000 * k;
      c.seq = k == 10 ? 9 : k;   // one duplicate: rejected
      const double axes[8] = {10.0 + 0.01 * k, -20, -100, 30, -45, 0, 0, 0};
      std::memcpy(c.axes, axes, sizeof axes);
      const auto b = encode(c);
      lcm_publish(lcm, "CHAINCOMP_COMMAND", b.data(), static_cast<unsigned>(b.size()));
      drain(*node);
    }
    node->publish_status(true);
    drain(*node);
    node->~LcmNode();
    lcm_destroy(lcm);
    // what differs from run to run by design: the clock, the instance, the measured latency
    REQUIRE(out.status.size() == 2);
    std::vector<unsigned char> last = out.status.back();
    chaincomp_lcm::lcmt_chaincomp_status s;
    REQUIRE(s.decode(last.data(), 0, static_cast<int>(last.size())) == static_cast<int>(last.size()));
    CHECK(s.readings_received == 0);   // no thermal model: zero, not the memory's bytes
    CHECK(s.params_received == 0);
    CHECK(s.rejected[static_cast<int>(chaincomp::Reject::kDuplicateSeq)] == 1);
    s.utime = s.uptime_us = s.instance_id = 0;
    // every command accounted for: 20 sent, the duplicate rejected, the rest published
    CHECK(s.received == 20);
    CHECK(s.published == 19);
    CHECK(s.unpublished == 0);
    CHECK(s.queue_dropped == 0);
    // from the publish (memq's receive stamp, µs) to the target published: not negative
    CHECK(s.receipt_p50_ns >= 0);
    CHECK(s.receipt_max_ns >= s.receipt_p50_ns);
    s.latency_p50_ns = s.latency_p99_ns = s.latency_p999_ns = s.latency_max_ns = 0;
    s.receipt_p50_ns = s.receipt_p99_ns = s.receipt_max_ns = 0;
    std::vector<unsigned char> masked(s.getEncodedSize());
    REQUIRE(s.encode(masked.data(), 0, static_cast<int>(masked.size())) == static_cast<int>(masked.size()));
    return masked;
  };
  CHECK(run(0xA5) == run(0x5A));
}
