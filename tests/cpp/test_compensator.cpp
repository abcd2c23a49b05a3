// The daemon's per-message logic without LCM: rejections by reason, limits, bumpless ramp.
#include <catch2/catch.hpp>

#include <cmath>
#include <vector>

#include "chaincomp/compensator.hpp"
#include "chaincomp/daemon_config.hpp"

namespace {

struct Fixture {
  const chaincomp::ModelEntry& entry = *chaincomp::find_model("five_axis_ac");
  alignas(64) unsigned char model[1 << 14];
  chaincomp::DaemonConfig config;
  std::vector<double> params;

  Fixture() {
    std::string error;
    REQUIRE(chaincomp::load_daemon_config(*entry.info, "", config, error));
    params.resize(entry.info->num_params);
    for (int i = 0; i < entry.info->num_params; ++i) {
      // 5 µm / 5 arcsec on every error: a correction of some µm
      const auto& p = entry.info->params[i];
      params[i] = p.role == chaincomp::ParamRole::kError
                      ? (p.kind == chaincomp::UnitKind::kLength ? 5e-3 : 5.0 * M_PI / 648000.0)
                      : p.nominal;
    }
    entry.prepare(params.data(), model);
  }

  chaincomp::Command command(std::int64_t seq, double x = 10.0) const {
    chaincomp::Command c;
    c.seq = seq;
    c.utime = 1000 * seq;  // 1 ms per command
    c.machine = "five_axis_ac";
    c.num_axes = 5;
    c.axes = {x, -20.0, -100.0, 30.0, -45.0, 0, 0, 0};
    return c;
  }
};

}  // namespace

TEST_CASE("each kind of bad command is rejected under its reason", "[compensator]") {
  Fixture f;
  chaincomp::Compensator comp(f.entry, f.model, f.config.compensator);
  chaincomp::Target t;
  chaincomp::Reject why;
  REQUIRE(comp.process(f.command(1), t));

  auto expect = [&](chaincomp::Command c, chaincomp::Reject r) {
    CHECK_FALSE(comp.process(c, t, &why));
    CHECK(why == r);
  };
  auto c = f.command(2);
  c.machine = "angle_head";
  expect(c, chaincomp::Reject::kWrongMachine);
  c = f.command(2);
  c.num_axes = 4;
  expect(c, chaincomp::Reject::kWrongAxisCount);
  c = f.command(2);
  c.axes[3] = std::nan("");
  expect(c, chaincomp::Reject::kNonFinite);
  c = f.command(2);
  c.axes[1] = -301;  // Y limits [-300, 300]
  expect(c, chaincomp::Reject::kOutOfLimits);
  expect(f.command(2, 10.0 + 10.5), chaincomp::Reject::kStepTooLarge);  // default max_step 10 mm
  expect(f.command(1), chaincomp::Reject::kDuplicateSeq);
  expect(f.command(0), chaincomp::Reject::kOutOfOrderSeq);
  CHECK(comp.process(f.command(2, 20.4), t));  // still answers (near the last valid command)
  const auto& k = comp.counters();
  CHECK(k.received == 9);
  for (int r = 1; r <= 7; ++r) CHECK(k.rejected[r] == 1);
}

TEST_CASE("clamp policy clamps commands into limits and flags them", "[compensator]") {
  Fixture f;
  f.config.compensator.clamp_out_of_limits = true;
  chaincomp::Compensator comp(f.entry, f.model, f.config.compensator);
  auto c = f.command(1);
  c.axes[1] = 300.5;
  chaincomp::Target t;
  REQUIRE(comp.process(c, t));
  CHECK((t.flags & chaincomp::kFlagClampedInput) != 0);
  CHECK(t.axes[1] <= 300.0);
  CHECK(comp.counters().clamped_input == 1);
}

TEST_CASE("the correction ramps in and out without exceeding its per-command step", "[compensator]") {
  Fixture f;
  f.config.compensator.ramp_time_s = 0.1;  // 100 commands at 1 ms
  f.config.compensator.start_enabled = false;
  for (auto& a : f.config.compensator.axes) a.max_correction_step = 1.0;
  chaincomp::Compensator comp(f.entry, f.model, f.config.compensator);
  chaincomp::Target t;
  std::vector<double> prev(5, 0.0);
  double full = 0;
  // full correction of axis X at this command, from a compensator that starts enabled
  {
    chaincomp::CompensatorConfig on = f.config.compensator;
    on.start_enabled = true;
    chaincomp::Compensator ref(f.entry, f.model, on);
    REQUIRE(ref.process(f.command(1), t));
    full = t.correction[0];
  }
  REQUIRE(std::abs(full) > 1e-4);
  REQUIRE(comp.process(f.command(1), t));
  CHECK(t.correction[0] == 0.0);  // off: pass-through
  comp.set_enabled(true);
  for (int k = 2; k <= 151; ++k) {
    REQUIRE(comp.process(f.command(k), t));
    if (k == 51) CHECK(t.correction[0] == Approx(0.5 * full).epsilon(1e-9));  // half-way after 50 ms
    if (k <= 100) CHECK((t.flags & chaincomp::kFlagRamping) != 0);
  }
  CHECK(t.correction[0] == Approx(full).epsilon(1e-12));
  CHECK((t.flags & chaincomp::kFlagRamping) == 0);

  // A tight per-command limit: the correction moves by at most that much per command.
  f.config.compensator.start_enabled = true;
  for (auto& a : f.config.compensator.axes) a.max_correction_step = 1e-4;
  chaincomp::Compensator slow(f.entry, f.model, f.config.compensator);
  double last = 0;
  for (int k = 1; k <= 300; ++k) {  // |full| ~ 0.02 mm: 200 steps of 1e-4 and more
    REQUIRE(slow.process(f.command(k), t));
    CHECK(std::abs(t.correction[0] - last) <= 1e-4 * (1 + 1e-12));
    last = t.correction[0];
  }
  CHECK(last == Approx(full).epsilon(1e-12));
  CHECK(slow.counters().clamped > 0);
}

TEST_CASE("after a jump the stream is followed again; a lone spike is dropped", "[compensator]") {
  Fixture f;
  chaincomp::Compensator comp(f.entry, f.model, f.config.compensator);
  chaincomp::Target t;
  chaincomp::Reject why;
  REQUIRE(comp.process(f.command(1, 10.0), t));
  // a lone spike: it and the command back from it are rejected, then the stream goes on
  CHECK_FALSE(comp.process(f.command(2, 50.0), t, &why));
  CHECK(why == chaincomp::Reject::kStepTooLarge);
  CHECK_FALSE(comp.process(f.command(3, 10.1), t, &why));
  CHECK(comp.process(f.command(4, 10.2), t));
  // a real move after a gap (e.g. lost messages): followed again from its second command
  CHECK_FALSE(comp.process(f.command(5, 40.0), t, &why));
  CHECK(comp.process(f.command(6, 40.1), t));
  CHECK(comp.process(f.command(7, 40.2), t));
  CHECK(comp.counters().rejected[static_cast<int>(chaincomp::Reject::kStepTooLarge)] == 3);
}
