// Error values updated while running (lcmt_params_update): the decoder against lcm-gen's own
// encoder, every refusal under its reason with nothing applied, all-or-none, the model after
// an update the same as one prepared from the new values, and the correction moving to it
// within max_correction_step per command with no command lost.
#include <catch2/catch.hpp>

#include <lcm/lcm.h>

#include <cmath>
#include <cstring>
#include <limits>
#include <string>
#include <vector>

#include "chaincomp/compensator.hpp"
#include "chaincomp/daemon_config.hpp"
#include "chaincomp/lcm_node.hpp"
#include "chaincomp/params_update.hpp"
#include "chaincomp_lcm/lcmt_params_update.hpp"

namespace {

using chaincomp::Refuse;

std::vector<unsigned char> encode(const chaincomp_lcm::lcmt_params_update& u) {
  std::vector<unsigned char> buf(u.getEncodedSize());
  REQUIRE(u.encode(buf.data(), 0, static_cast<int>(buf.size())) == static_cast<int>(buf.size()));
  return buf;
}

chaincomp_lcm::lcmt_params_update message(std::int64_t seq, std::vector<std::string> names, std::vector<double> values) {
  chaincomp_lcm::lcmt_params_update u;
  u.utime = 5;
  u.seq = seq;
  u.machine = "five_axis_ac";
  u.instance_id = 0;
  u.num_values = static_cast<int>(names.size());
  u.names = std::move(names);
  u.values = std::move(values);
  return u;
}

chaincomp_lcm::lcmt_params_update with_instance(chaincomp_lcm::lcmt_params_update m, std::int64_t id) {
  m.instance_id = id;
  return m;
}

int index_of(const chaincomp::MachineInfo& info, const char* name) {
  for (int i = 0; i < info.num_params; ++i) {
    if (std::strcmp(info.params[i].name, name) == 0) return i;
  }
  FAIL("no parameter " << name);
  return -1;
}

struct Fixture {
  const chaincomp::ModelEntry& entry = *chaincomp::find_model("five_axis_ac");
  alignas(64) unsigned char model[1 << 14];
  std::vector<double> params;
  chaincomp::VaryingErrors varying;
  chaincomp::DaemonConfig config;

  Fixture() {
    params.resize(entry.info->num_params);
    for (int i = 0; i < entry.info->num_params; ++i) params[i] = entry.info->params[i].nominal;
    params[index_of(*entry.info, "EXX")] = 4e-3;
    // EYX as a table over X: not a value an update can set
    const double x[2] = {-400, 400}, y[2] = {0, 2e-3};
    std::string why;
    int at;
    REQUIRE(chaincomp::add_table(varying, index_of(*entry.info, "EYX"), 0, 0, x, y, 2,
                                 chaincomp::Interpolation::kLinear, chaincomp::Outside::kHold, why, at));
    entry.prepare(params.data(), model);
    entry.attach_varying(model, &varying);
    std::string error;
    REQUIRE(chaincomp::load_daemon_config(*entry.info, "", config, error));
  }

  chaincomp::ParamsUpdate decoded(const chaincomp_lcm::lcmt_params_update& m) {
    const auto buf = encode(m);
    bufs.push_back(buf);   // the names point into it
    chaincomp::ParamsUpdate u;
    REQUIRE(chaincomp::decode_params_update(bufs.back().data(), bufs.back().size(),
                                            chaincomp_lcm::lcmt_params_update::getHash(), u));
    return u;
  }
  std::vector<std::vector<unsigned char>> bufs;
};

}  // namespace

TEST_CASE("params updates decode as lcm-gen encodes them, and nothing past their bounds", "[params_update]") {
  auto m = message(7, {"EXX", "ThetaAs"}, {1e-3, -2e-4});
  m.instance_id = 42;
  const auto buf = encode(m);
  const std::int64_t hash = chaincomp_lcm::lcmt_params_update::getHash();
  chaincomp::ParamsUpdate u;
  REQUIRE(chaincomp::decode_params_update(buf.data(), buf.size(), hash, u));
  CHECK(u.utime == 5);
  CHECK(u.seq == 7);
  CHECK(u.machine == "five_axis_ac");
  CHECK(u.instance_id == 42);
  REQUIRE(u.num_values == 2);
  CHECK(u.names[0] == "EXX");
  CHECK(u.names[1] == "ThetaAs");
  CHECK(u.values[0] == 1e-3);
  CHECK(u.values[1] == -2e-4);
  for (std::size_t cut = 0; cut < buf.size(); ++cut) CHECK_FALSE(chaincomp::decode_params_update(buf.data(), cut, hash, u));
  auto longer = buf;
  longer.push_back(0);
  CHECK_FALSE(chaincomp::decode_params_update(longer.data(), longer.size(), hash, u));
  CHECK_FALSE(chaincomp::decode_params_update(buf.data(), buf.size(), hash + 1, u));
  std::vector<std::string> many(65, "EXX");
  CHECK_FALSE(chaincomp::decode_params_update(encode(message(1, many, std::vector<double>(65, 0.0))).data(),
                                              encode(message(1, many, std::vector<double>(65, 0.0))).size(), hash, u));
  const auto long_name = encode(message(1, {std::string(300, 'E')}, {0.0}));
  CHECK_FALSE(chaincomp::decode_params_update(long_name.data(), long_name.size(), hash, u));
}

TEST_CASE("an update applied gives the model prepared from the new values; every refusal applies nothing",
          "[params_update]") {
  Fixture f;
  chaincomp::ParamsUpdater up(f.entry, f.model, &f.varying, f.params, f.config.params_updates);
  const int exx = index_of(*f.entry.info, "EXX"), oas = index_of(*f.entry.info, "Oas");
  const double axes[5] = {100.0, -50.0, -200.0, 0.3, -0.7};
  auto pose = [&](const void* model) {
    std::vector<double> p(f.entry.info->pose_size);
    f.entry.pose_exact(model, axes, p.data());
    return p;
  };
  const auto before = pose(f.model);

  Refuse why;
  REQUIRE(up.apply(f.decoded(message(1, {"EXX", "Oas"}, {-3e-3, 0.02})), 99, 0, &why));
  CHECK(up.version() == 1);
  CHECK(up.last_seq() == 1);
  // the same as a model prepared from scratch with those values (and the table attached)
  std::vector<double> expect = f.params;
  expect[exx] = -3e-3;
  expect[oas] = 0.02;
  CHECK(up.params() == expect);
  alignas(64) static unsigned char fresh[1 << 14];
  f.entry.prepare(expect.data(), fresh);
  f.entry.attach_varying(fresh, &f.varying);
  const auto after = pose(f.model);
  CHECK(after == pose(fresh));
  CHECK(after != before);

  // each refusal: counted under its reason, the params and the model untouched
  struct Case {
    chaincomp_lcm::lcmt_params_update m;
    std::int64_t command_utime;
    Refuse reason;
  };
  auto with = [](chaincomp_lcm::lcmt_params_update m, auto edit) { edit(m); return m; };
  const double nan = std::numeric_limits<double>::quiet_NaN(), inf = std::numeric_limits<double>::infinity();
  const std::vector<Case> cases = {
      {with(message(2, {"EXX"}, {1e-3}), [](auto& m) { m.machine = "five_axis_ac "; }), 100000, Refuse::kWrongMachine},
      {with(message(2, {"EXX"}, {1e-3}), [](auto& m) { m.instance_id = 7; }), 100000, Refuse::kOtherInstance},
      {message(2, {}, {}), 100000, Refuse::kBadCount},
      {message(2, {"EXX", "NoSuch"}, {1e-3, 0}), 100000, Refuse::kUnknownName},
      {message(2, {"X"}, {1.0}), 100000, Refuse::kNotAnError},          // an axis: a symbol, not an error
      {message(2, {"G"}, {151.0}), 100000, Refuse::kNotAnError},        // a constant
      {message(2, {"EYX"}, {1e-3}), 100000, Refuse::kNotAnError},       // a table
      {message(2, {"EXX", "EXX"}, {1e-3, 2e-3}), 100000, Refuse::kRepeatedName},
      {message(2, {"EZZ", "EXX"}, {1e-3, nan}), 100000, Refuse::kNonFinite},
      {message(2, {"EXX"}, {inf}), 100000, Refuse::kNonFinite},
      {message(2, {"EZZ", "EXX"}, {1e-3, 1.5}), 100000, Refuse::kOutOfBound},       // 1.5 mm
      {message(2, {"ThetaAs"}, {0.02}), 100000, Refuse::kOutOfBound},               // 0.02 rad
      {message(1, {"EXX"}, {1e-3}), 100000, Refuse::kStaleSeq},
      {message(2, {"EXX"}, {1e-3}), 9999, Refuse::kTooFrequent},                    // 10 ms of command time
  };
  std::array<std::int64_t, chaincomp::kNumRefusals> expected{};
  for (const auto& c : cases) {
    INFO("reason " << chaincomp::refuse_name(c.reason));
    CHECK_FALSE(up.apply(f.decoded(c.m), 99, c.command_utime, &why));
    CHECK(why == c.reason);
    ++expected[static_cast<int>(c.reason)];
    CHECK(up.refused() == expected);
    CHECK(up.params() == expect);
    CHECK(pose(f.model) == after);
    CHECK(up.version() == 1);
  }
  up.count_undecodable();
  CHECK(up.refused()[0] == 1);
  CHECK(up.received() == static_cast<std::int64_t>(cases.size()) + 2);
  // addressed to this instance, 10 ms of command time later: applied
  REQUIRE(up.apply(f.decoded(with(message(3, {"EXX"}, {1e-3}), [](auto& m) { m.instance_id = 99; })), 99, 10000, &why));
  CHECK(up.version() == 2);
}

TEST_CASE("an update during a 1 kHz stream moves every target by at most max_correction_step and loses none",
          "[params_update]") {
  Fixture f;
  f.config.compensator.ramp_time_s = 0;
  chaincomp::Compensator comp(f.entry, f.model, f.config.compensator);
  chaincomp::ParamsUpdater up(f.entry, f.model, &f.varying, f.params, f.config.params_updates);
  auto command = [](std::int64_t seq) {
    chaincomp::Command c;
    c.seq = seq;
    c.utime = 1000 * seq;
    c.machine = "five_axis_ac";
    c.num_axes = 5;
    c.axes = {10.0 + 0.01 * seq, -20.0, -100.0, 30.0, -45.0, 0, 0, 0};
    return c;
  };
  chaincomp::Target t;
  std::array<double, 8> last{};
  std::int64_t seq = 0;
  for (; seq < 50; ++seq) {
    REQUIRE(comp.process(command(seq + 1), t));
    last = t.correction;
  }
  // 20 µm more on EXX, EYY and EZZ: the wanted correction jumps by about 20 µm per axis
  REQUIRE(up.apply(f.decoded(message(1, {"EXX", "EYY", "EZZ"}, {0.024, 0.02, 0.02})), 1, comp.last_utime()));
  double largest_step = 0;
  for (; seq < 150; ++seq) {
    REQUIRE(comp.process(command(seq + 1), t));
    for (int i = 0; i < 5; ++i) {
      largest_step = std::max(largest_step, std::abs(t.correction[i] - last[i]) /
                                                f.config.compensator.axes[i].max_correction_step);
    }
    last = t.correction;
  }
  CHECK(largest_step <= 1.0 + 1e-9);   // (target - command, at 100 mm, rounds to 1e-14 mm)
  CHECK(largest_step > 0.5);   // the limit did act: the jump was many steps
  CHECK(comp.counters().received == 150);
  std::int64_t rejected = 0;
  for (auto n : comp.counters().rejected) rejected += n;
  CHECK(rejected == 0);
  // settled on the new model: where a compensator that had it from the start is
  chaincomp::Compensator fresh(f.entry, f.model, f.config.compensator);
  chaincomp::Target u;
  for (std::int64_t k = 1; k <= seq; ++k) REQUIRE(fresh.process(command(k), u));
  for (int i = 0; i < 5; ++i) CHECK(t.correction[i] == Approx(u.correction[i]).margin(1e-9));
}

TEST_CASE("params updates over memq:// are applied, refused and counted on status", "[params_update][lcm]") {
  Fixture f;
  for (auto& a : f.config.compensator.axes) a.max_correction_step = 1.0;
  lcm_t* lcm = lcm_create("memq://");
  REQUIRE(lcm != nullptr);
  std::vector<chaincomp_lcm::lcmt_chaincomp_status> status;
  lcm_subscribe(lcm, "CHAINCOMP_STATUS", [](const lcm_recv_buf_t* rbuf, const char*, void* user) {
    chaincomp_lcm::lcmt_chaincomp_status s;
    REQUIRE(s.decode(rbuf->data, 0, static_cast<int>(rbuf->data_size)) >= 0);
    static_cast<std::vector<chaincomp_lcm::lcmt_chaincomp_status>*>(user)->push_back(s);
  }, &status);
  {
    chaincomp::LcmNode node(lcm, f.entry, f.model, f.config, "p.yaml", "0", {});
    chaincomp::ParamsUpdater up(f.entry, f.model, &f.varying, f.params, f.config.params_updates);
    node.accept_params_updates(up);
    auto publish = [&](const std::vector<unsigned char>& b) {
      lcm_publish(lcm, "CHAINCOMP_PARAMS", b.data(), static_cast<unsigned>(b.size()));
    };
    // a flood of 1000 updates within one command time: the first applied, the rest too frequent
    for (int k = 1; k <= 1000; ++k) publish(encode(message(k, {"EXX"}, {1e-3 * (k % 7)})));
    publish(encode(with_instance(message(2000, {"EXX"}, {1e-3}), node.instance_id() + 1)));
    const unsigned char junk[5] = {1, 2, 3, 4, 5};
    lcm_publish(lcm, "CHAINCOMP_PARAMS", junk, sizeof junk);
    node.handle_until_idle();
    node.publish_status(false);
    node.handle_until_idle();
    REQUIRE(!status.empty());
    const auto& s = status.back();
    CHECK(s.params_received == 1002);
    CHECK(s.params_version == 1);
    CHECK(s.params_seq == 1);
    CHECK(s.params_refused[static_cast<int>(Refuse::kTooFrequent)] == 999);
    CHECK(s.params_refused[static_cast<int>(Refuse::kOtherInstance)] == 1);
    CHECK(s.params_refused[static_cast<int>(Refuse::kUndecodable)] == 1);
    CHECK(up.params()[index_of(*f.entry.info, "EXX")] == 1e-3);
  }
  lcm_destroy(lcm);
}
