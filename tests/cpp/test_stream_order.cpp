// The stream rule every input stream shares (stream_order.hpp): against a model written here
// in 128-bit arithmetic, then on each stream (commands, params updates, temperature readings,
// control) with the hostile sequences of issue 39: a jump back, a huge jump forward, INT64_MIN
// and INT64_MAX, a sender that restarts its numbering, and a control message's reset.
#include <catch2/catch.hpp>

#include <lcm/lcm.h>

#include <climits>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <fstream>
#include <random>
#include <string>
#include <unistd.h>
#include <vector>

#include "chaincomp/compensator.hpp"
#include "chaincomp/daemon_config.hpp"
#include "chaincomp/lcm_node.hpp"
#include "chaincomp/params_update.hpp"
#include "chaincomp/stream_order.hpp"
#include "chaincomp/thermal.hpp"
#include "chaincomp_lcm/lcmt_params_update.hpp"
#include "chaincomp_lcm/lcmt_temperatures.hpp"

namespace {

using chaincomp::Refuse;
using chaincomp::StreamOrder;
using V = StreamOrder::Verdict;
__extension__ typedef __int128 I128;   // GCC's and Clang's, for the model only

// The rule as the header states it, in 128-bit integers: no wrap-around to get wrong.
struct Model {
  explicit Model(I128 jump) : jump(jump) {}
  I128 jump;
  bool known = false;
  I128 last = 0, run_key = 0;
  int run = 0;
  bool judge_and_take(std::int64_t key) {   // true: the message is taken
    const I128 k = key;
    if (!known || (k > last && k - last <= jump)) {
      known = true;
      last = k;
      run = 0;
      return true;
    }
    run = (run > 0 && k > run_key && k - run_key <= jump) ? run + 1 : 1;
    run_key = k;
    if (run < 5) return false;
    known = true;
    last = k;
    run = 0;
    return true;
  }
};

bool take(StreamOrder& o, std::int64_t key) {
  const V v = o.judge(key);
  if (StreamOrder::taken(v)) o.accept(key);
  return StreamOrder::taken(v);
}

}  // namespace

TEST_CASE("the stream rule takes what a 128-bit model of it takes, for any int64 keys", "[stream]") {
  const std::int64_t extremes[] = {INT64_MIN, INT64_MIN + 1, -1, 0, 1, INT64_MAX - 1, INT64_MAX};
  std::mt19937_64 random(39);
  for (const std::uint64_t jump : {std::uint64_t(3), std::uint64_t(1) << 32, std::uint64_t(UINT64_MAX)}) {
    for (int trial = 0; trial < 200; ++trial) {
      StreamOrder order(jump);
      Model model(static_cast<I128>(jump));
      std::int64_t key = static_cast<std::int64_t>(random());
      for (int i = 0; i < 60; ++i) {
        switch (random() % 6) {
          case 0: key = extremes[random() % 7]; break;                       // a hostile key
          case 1: key = static_cast<std::int64_t>(random()); break;          // anywhere
          case 2:                                                            // back or the same
            if (key >= INT64_MIN + 4) key -= static_cast<std::int64_t>(random() % 4);
            break;
          default:                                                           // on, by 1..4
            if (key <= INT64_MAX - 4) key += 1 + static_cast<std::int64_t>(random() % 4);
        }
        INFO("jump " << jump << " trial " << trial << " message " << i << " key " << key);
        REQUIRE(take(order, key) == model.judge_and_take(key));
        if (model.known) REQUIRE(order.last() == static_cast<std::int64_t>(model.last));
      }
    }
  }
}

TEST_CASE("the stream rule: a jump back, a huge jump forward, the extremes, a restart run, a reset", "[stream]") {
  StreamOrder o(chaincomp::kMaxSeqJump);
  CHECK(take(o, INT64_MAX));   // the first message starts the stream whatever its key
  CHECK(o.judge(INT64_MIN) == V::kBehind);   // INT64_MIN - INT64_MAX overflows: not here
  o.reset();
  CHECK(take(o, 100));
  CHECK(o.judge(100) == V::kSame);
  CHECK(o.judge(99) == V::kBehind);
  CHECK(o.judge(INT64_MAX) == V::kTooFarAhead);
  CHECK(o.judge(INT64_MIN) == V::kBehind);
  CHECK(take(o, 100 + static_cast<std::int64_t>(chaincomp::kMaxSeqJump)));   // the largest gap
  CHECK(o.judge(o.last() + static_cast<std::int64_t>(chaincomp::kMaxSeqJump) + 1) == V::kTooFarAhead);
  // a sender that restarts at 1: its fifth message in a row is taken, the four before refused
  const std::int64_t top = o.last();
  for (int k = 1; k <= 4; ++k) CHECK(o.judge(k) == V::kBehind);
  CHECK(o.judge(5) == V::kRestart);
  o.accept(5);
  CHECK(take(o, 6));
  // a run broken by a message out of its own order starts again
  for (int k : {1, 2, 3, 2, 3, 4, 5}) CHECK_FALSE(take(o, k - 100));
  CHECK(take(o, 6 - 100));
  // at INT64_MAX and from INT64_MIN: a run ending at the top, then one starting at the bottom
  o.reset();
  CHECK(take(o, 0));
  for (std::int64_t k = INT64_MAX - 4; k < INT64_MAX; ++k) CHECK_FALSE(take(o, k));
  CHECK(take(o, INT64_MAX));
  for (std::int64_t k = INT64_MIN; k < INT64_MIN + 4; ++k) CHECK_FALSE(take(o, k));
  CHECK(take(o, INT64_MIN + 4));
  CHECK(take(o, INT64_MIN + 5));
  (void)top;
  // a restart refused by another check (another sensor of its message, a command's step): the
  // run holds, and the next message in order is taken
  o.reset();
  CHECK(take(o, 100));
  for (int k = 1; k <= 4; ++k) CHECK(o.judge(k) == V::kBehind);
  CHECK(o.judge(5) == V::kRestart);   // not accepted
  CHECK(o.judge(6) == V::kRestart);
  o.accept(6);
  CHECK(o.judge(7) == V::kNext);
  CHECK(chaincomp::ahead_by(INT64_MIN, INT64_MAX) == UINT64_MAX);
  CHECK(chaincomp::ahead_by(INT64_MAX, INT64_MIN) == 0);
}

namespace {

struct Model5 {
  const chaincomp::ModelEntry& entry = *chaincomp::find_model("five_axis_ac");
  alignas(64) unsigned char model[1 << 14];
  std::vector<double> params;
  chaincomp::DaemonConfig config;
  Model5() {
    params.resize(entry.info->num_params);
    for (int i = 0; i < entry.info->num_params; ++i) params[i] = entry.info->params[i].nominal;
    entry.prepare(params.data(), model);
    std::string error;
    REQUIRE(chaincomp::load_daemon_config(*entry.info, "", config, error));
  }
};

chaincomp::ParamsUpdate update(std::int64_t seq, double exx = 1e-3) {
  chaincomp::ParamsUpdate u;
  u.seq = seq;
  u.machine = "five_axis_ac";
  u.num_values = 1;
  u.names[0] = "EXX";
  u.values[0] = exx;
  return u;
}

chaincomp::Command command(std::int64_t seq, std::int64_t utime) {
  chaincomp::Command c;
  c.seq = seq;
  c.utime = utime;
  c.machine = "five_axis_ac";
  c.num_axes = 5;
  c.axes = {10.0, -20.0, -100.0, 30.0, -45.0, 0, 0, 0};
  return c;
}

}  // namespace

TEST_CASE("params updates: seq 2^63-1 or a PLC restarting its numbering never locks updates out", "[stream]") {
  Model5 f;
  chaincomp::ParamsUpdater up(f.entry, f.model, nullptr, f.params, f.config.params_updates);
  chaincomp::Refuse why;
  // 10 ms of command time between updates: none too frequent
  std::int64_t t = 0;
  auto next = [&]() { return t += 10000; };
  REQUIRE(up.apply(update(1001), 1, next()));
  CHECK_FALSE(up.apply(update(INT64_MAX), 1, next(), &why));   // more than 2^32 ahead
  CHECK(why == Refuse::kStaleSeq);
  REQUIRE(up.apply(update(1002), 1, next()));                   // the stream goes on
  CHECK_FALSE(up.apply(update(INT64_MIN), 1, next(), &why));
  CHECK(why == Refuse::kStaleSeq);
  // the PLC restarts at seq 1: four refused, the fifth applied, then on
  for (int k = 1; k <= 4; ++k) CHECK_FALSE(up.apply(update(k), 1, next()));
  CHECK(up.apply(update(5), 1, next()));
  CHECK(up.apply(update(6), 1, next()));
  CHECK(up.last_seq() == 6);
  // 2^63-1 as the first update of all: the real stream is taken from its fifth
  chaincomp::ParamsUpdater first(f.entry, f.model, nullptr, f.params, f.config.params_updates);
  REQUIRE(first.apply(update(INT64_MAX), 1, next()));
  int applied = 0;
  for (int k = 1; k <= 10; ++k) applied += first.apply(update(k), 1, next());
  CHECK(applied == 6);
  // a reset: the next update is taken whatever its seq, and at once
  first.reset();
  CHECK(first.apply(update(-7), 1, t));
  CHECK(first.last_seq() == -7);
}

TEST_CASE("params updates: a command at utime INT64_MIN, or no command at all, holds no update off",
          "[stream]") {
  Model5 f;
  chaincomp::Compensator comp(f.entry, f.model, f.config.compensator);
  chaincomp::ParamsUpdater up(f.entry, f.model, nullptr, f.params, f.config.params_updates);
  chaincomp::Target target;
  chaincomp::Refuse why;
  REQUIRE(comp.process(command(1, INT64_MIN), target));
  REQUIRE(up.apply(update(1), 1, comp.last_utime()));
  // (INT64_MIN's distance to any later utime overflows int64: must not read as "too soon")
  for (std::int64_t k = 2; k <= 5; ++k) {
    REQUIRE(comp.process(command(k, 1000000 * k), target));
    INFO("update " << k);
    CHECK(up.apply(update(k), 1, comp.last_utime(), &why));
  }
  // a command time that went back: a new stream, no update held off
  REQUIRE(comp.process(command(6, -5), target));
  CHECK(up.apply(update(6), 1, comp.last_utime()));
  // within 10 ms of command time while commands flow: too frequent; once they stopped, the
  // receipt clock holds updates off instead (the commands' time frozen holds none off)
  using chaincomp::CommandTime;
  CHECK_FALSE(up.apply(update(7), 1, CommandTime(comp.last_utime(), true), &why));
  CHECK(why == Refuse::kTooFrequent);
  CHECK(up.apply(update(7), 1, CommandTime(comp.last_utime(), false, 10000)));
  CHECK_FALSE(up.apply_values(update(0, 2e-3), CommandTime(comp.last_utime(), false, 19999), &why));
  CHECK(why == Refuse::kTooFrequent);
  CHECK(up.apply_values(update(0, 2e-3), CommandTime(comp.last_utime(), false, 20000)));
  CHECK(up.apply_values(update(0, 3e-3), CommandTime(comp.last_utime(), false, INT64_MAX)));
  CHECK(up.version() == 9);
  // commands_flowing: within kCommandsIdleUs of the last accepted command's receipt, any int64 clocks
  CHECK(chaincomp::commands_flowing(true, 0, chaincomp::kCommandsIdleUs - 1));
  CHECK_FALSE(chaincomp::commands_flowing(true, 0, chaincomp::kCommandsIdleUs));
  CHECK_FALSE(chaincomp::commands_flowing(false, 0, 0));
  CHECK_FALSE(chaincomp::commands_flowing(true, INT64_MIN, INT64_MAX));
  CHECK(chaincomp::commands_flowing(true, INT64_MAX, INT64_MIN));   // a clock that went back
}

namespace {

// EXX = base + 1 um/K * (T_a - 20) + 1 um/K * (lag(T_b, 600 s) - 20)
const char* kThermal =
    "machine: five_axis_ac\n"
    "errors:\n"
    "  EXX:\n"
    "    unit: um\n"
    "    terms:\n"
    "      - {sensor: T_a, gain: 1.0}\n"
    "      - {sensor: T_b, gain: 1.0, time_constant: 600}\n";

struct Thermal {
  Model5 f;
  chaincomp::ThermalModel model;
  Thermal() {
    char name[] = "/tmp/chaincomp-stream-XXXXXX";
    const int fd = mkstemp(name);
    REQUIRE(fd >= 0);
    close(fd);
    std::ofstream(name) << kThermal;
    std::string error;
    REQUIRE(chaincomp::load_thermal_model(*f.entry.info, name, model, error));
    std::remove(name);
  }
};

chaincomp::Readings reading(std::int64_t utime, double a, double b) {
  chaincomp::Readings r;
  r.utime = utime;
  r.num_values = 2;
  r.names[0] = "T_a";
  r.names[1] = "T_b";
  r.values[0] = a;
  r.values[1] = b;
  return r;
}

}  // namespace

TEST_CASE("temperature readings: a clock glitch (a year ahead, 2^63-1) never freezes the thermal model",
          "[stream][thermal]") {
  Thermal th;
  chaincomp::ThermalState state(th.model, th.f.params);
  chaincomp::ParamsUpdate u;
  const std::int64_t s = 1000000, year = 365LL * 86400 * s;
  using R = chaincomp::ReadingRefuse;
  REQUIRE(state.take(reading(10 * s, 20.0, 20.0), "five_axis_ac", u));
  REQUIRE(u.values[0] == 0.0);   // EXX's nominal value, both sensors at the reference
  for (std::int64_t glitch : {10 * s + year, INT64_MAX, INT64_MIN}) {
    CHECK_FALSE(state.take(reading(glitch, 25.0, 25.0), "five_axis_ac", u));
  }
  CHECK(state.refused()[static_cast<int>(R::kTimeNotIncreasing)] == 3);
  // the sensors' stream goes on, the glitches never taken: T_a's term follows at once
  REQUIRE(state.take(reading(11 * s, 21.0, 20.0), "five_axis_ac", u));
  CHECK(u.values[0] == Approx(1e-3 * 1.0).margin(1e-12));
  // a day later is a pause (the lag runs on), more than a day a glitch
  REQUIRE(state.take(reading(11 * s + 86400 * s, 21.0, 20.0), "five_axis_ac", u));
  CHECK_FALSE(state.take(reading(11 * s + 2 * 86400 * s + 1, 21.0, 20.0), "five_axis_ac", u));

  // 2^63-1 as the very first reading: the real clock, behind it, is taken from its fifth
  // message, and the lags settle there (T_b's term equals its reading, as at a first one)
  chaincomp::ThermalState glitched(th.model, th.f.params);
  REQUIRE(glitched.take(reading(INT64_MAX, 20.0, 20.0), "five_axis_ac", u));
  int taken = 0;
  for (int k = 1; k <= 10; ++k) taken += glitched.take(reading(k * s, 20.0, 30.0), "five_axis_ac", u);
  CHECK(taken == 6);
  // settled at 30 degC at the fifth, then a lag of 600 s held at 30: exactly 10 um from T_b
  CHECK(u.values[0] == Approx(10e-3).margin(1e-12));

  // a reset: each sensor's next reading is taken whatever its time, the lags settled there
  glitched.reset();
  REQUIRE(glitched.take(reading(-3 * s, 20.0, 40.0), "five_axis_ac", u));
  CHECK(u.values[0] == Approx(20e-3).margin(1e-12));
  CHECK(glitched.take(reading(-2 * s, 20.0, 40.0), "five_axis_ac", u));
}

namespace {

struct Inbox {
  std::vector<std::vector<unsigned char>> status;
};

void on_status(const lcm_recv_buf_t* rbuf, const char*, void* user) {
  const auto* b = static_cast<const unsigned char*>(rbuf->data);
  static_cast<Inbox*>(user)->status.emplace_back(b, b + rbuf->data_size);
}

chaincomp_lcm::lcmt_chaincomp_status decode_status(const std::vector<unsigned char>& b) {
  chaincomp_lcm::lcmt_chaincomp_status s;
  REQUIRE(s.decode(b.data(), 0, static_cast<int>(b.size())) == static_cast<int>(b.size()));
  return s;
}

template <class M>
void publish(chaincomp::LcmNode& node, lcm_t* lcm, const char* channel, const M& m, int extra = 0) {
  std::vector<unsigned char> b(m.getEncodedSize() + extra, 0);
  REQUIRE(m.encode(b.data(), 0, static_cast<int>(m.getEncodedSize())) > 0);
  lcm_publish(lcm, channel, b.data(), static_cast<unsigned>(b.size()));
  node.handle_until_idle();
}

chaincomp_lcm::lcmt_axis_command wire_command(std::int64_t seq, std::int64_t utime) {
  chaincomp_lcm::lcmt_axis_command c{};
  c.utime = utime;
  c.seq = seq;
  c.machine = "five_axis_ac";
  c.num_axes = 5;
  const double axes[8] = {10, -20, -100, 30, -45, 0, 0, 0};
  std::memcpy(c.axes, axes, sizeof axes);
  return c;
}

chaincomp_lcm::lcmt_params_update wire_update(std::int64_t seq) {
  chaincomp_lcm::lcmt_params_update u{};
  u.seq = seq;
  u.machine = "five_axis_ac";
  u.num_values = 1;
  u.names = {"EXX"};
  u.values = {1e-3};
  return u;
}

chaincomp_lcm::lcmt_temperatures wire_readings(std::int64_t utime) {
  chaincomp_lcm::lcmt_temperatures r{};
  r.utime = utime;
  r.machine = "";
  r.num_values = 2;
  r.names = {"T_a", "T_b"};
  r.values = {20.0, 20.0};
  return r;
}

chaincomp_lcm::lcmt_chaincomp_control wire_control(bool reset) {
  chaincomp_lcm::lcmt_chaincomp_control c{};
  c.enable = true;
  c.reset = reset;
  return c;
}

}  // namespace

TEST_CASE("control over memq://: a reset clears every stream; trailing bytes are refused and counted on "
          "every stream", "[stream][lcm]") {
  Thermal th;
  Model5& f = th.f;
  lcm_t* lcm = lcm_create("memq://");
  REQUIRE(lcm != nullptr);
  Inbox inbox;
  lcm_subscribe(lcm, "CHAINCOMP_STATUS", on_status, &inbox);
  {
    chaincomp::LcmNode node(lcm, f.entry, f.model, f.config, "p.yaml", "0", {});
    chaincomp::ParamsUpdater up(f.entry, f.model, nullptr, f.params, f.config.params_updates);
    chaincomp::ThermalState thermal(th.model, f.params);
    node.accept_params_updates(up);
    node.accept_temperatures(thermal);
    // each stream far ahead: 2^62 (commands, updates), the year 2^62 µs (readings)
    const std::int64_t far = std::int64_t(1) << 62;
    publish(node, lcm, "CHAINCOMP_COMMAND", wire_command(far, far));
    publish(node, lcm, "CHAINCOMP_TEMPERATURES", wire_readings(far));
    publish(node, lcm, "CHAINCOMP_COMMAND", wire_command(far + 1, far + 20000));   // 20 ms later
    publish(node, lcm, "CHAINCOMP_PARAMS", wire_update(far));
    REQUIRE(node.counters().published == 2);
    REQUIRE(up.version() == 2);   // the thermal model's values, then the update
    // one reset, and every stream takes seq 1 / time 1 at once
    publish(node, lcm, "CHAINCOMP_CONTROL", wire_control(true));
    publish(node, lcm, "CHAINCOMP_COMMAND", wire_command(1, 1000));
    publish(node, lcm, "CHAINCOMP_PARAMS", wire_update(1));
    publish(node, lcm, "CHAINCOMP_TEMPERATURES", wire_readings(1));
    CHECK(node.counters().published == 3);
    CHECK(up.last_seq() == 1);
    CHECK(thermal.refused()[static_cast<int>(chaincomp::ReadingRefuse::kTimeNotIncreasing)] == 0);
    // one byte more on each stream: refused whole, counted as undecodable, nothing applied
    publish(node, lcm, "CHAINCOMP_COMMAND", wire_command(2, 2000), 1);
    publish(node, lcm, "CHAINCOMP_PARAMS", wire_update(2), 1);
    publish(node, lcm, "CHAINCOMP_TEMPERATURES", wire_readings(2), 1);
    publish(node, lcm, "CHAINCOMP_CONTROL", wire_control(true), 1);
    CHECK(node.counters().published == 3);
    CHECK(node.counters().resets == 1);
    node.publish_status(true);
    node.handle_until_idle();
    REQUIRE(!inbox.status.empty());
    const auto s = decode_status(inbox.status.back());
    CHECK(s.rejected[static_cast<int>(chaincomp::Reject::kUndecodable)] == 1);
    CHECK(s.params_refused[static_cast<int>(chaincomp::Refuse::kUndecodable)] == 1);
    CHECK(s.readings_refused[static_cast<int>(chaincomp::ReadingRefuse::kUndecodable)] == 1);
    CHECK(s.control_received == 2);
    CHECK(s.control_refused == 1);
    CHECK(s.resets == 1);
  }
  lcm_destroy(lcm);
}

TEST_CASE("channel names reach LCM's subscribe as exact names, not as regular expressions", "[stream][lcm]") {
  CHECK(chaincomp::channel_regex("CHAINCOMP_COMMAND") == "CHAINCOMP_COMMAND");
  CHECK(chaincomp::channel_regex("A.B*|C") == "A\\.B\\*\\|C");
  Model5 f;
  f.config.command_channel = "CMD.*";
  lcm_t* lcm = lcm_create("memq://");
  REQUIRE(lcm != nullptr);
  {
    chaincomp::LcmNode node(lcm, f.entry, f.model, f.config, "p.yaml", "0", {});
    publish(node, lcm, "CMDX", wire_command(1, 1000));       // the regex CMD.* would take it: the name does not
    CHECK(node.counters().received == 0);
    publish(node, lcm, "CMD.*", wire_command(1, 1000));
    CHECK(node.counters().received == 1);
    CHECK(node.counters().published == 1);
  }
  lcm_destroy(lcm);
}
