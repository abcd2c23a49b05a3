// The daemon's per-message logic without LCM: rejections by reason, limits, bumpless ramp.
#include <catch2/catch.hpp>

#include <algorithm>
#include <climits>
#include <cmath>
#include <functional>
#include <string>
#include <string_view>
#include <vector>

#include "chaincomp/compensate.hpp"
#include "chaincomp/compensator.hpp"
#include "chaincomp/daemon_config.hpp"
#include "held_back_case.hpp"

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

namespace {

chaincomp::Counters run(chaincomp::Compensator& comp, chaincomp::Command c, int* accepted = nullptr) {
  chaincomp::Target t;
  const bool ok = comp.process(c, t);
  if (accepted != nullptr) *accepted += ok ? 1 : 0;
  return comp.counters();
}

}  // namespace

TEST_CASE("one command with seq 2^63-1 does not lock the stream out: refused mid-stream, followed again "
          "after kRestartRun when it started the stream", "[compensator][stream]") {
  Fixture f;
  chaincomp::Compensator comp(f.entry, f.model, f.config.compensator);
  chaincomp::Target t;
  chaincomp::Reject why;
  for (int k = 1; k <= 3; ++k) REQUIRE(comp.process(f.command(k), t));
  auto hostile = f.command(4);
  hostile.seq = INT64_MAX;
  // more than kMaxSeqJump (2^32) ahead: no gap of lost commands, refused, and nothing moves
  CHECK_FALSE(comp.process(hostile, t, &why));
  CHECK(why == chaincomp::Reject::kOutOfOrderSeq);
  CHECK(comp.counters().seq_gaps == 0);
  for (int k = 4; k < 4 + 200; ++k) REQUIRE(comp.process(f.command(k, 10.0 + 0.01 * k), t));
  CHECK(comp.counters().stream_restarts == 0);
  // a seq 2^32 ahead is still a gap (2^32 - 1 commands lost); 2^32 + 1 ahead is not
  auto far = f.command(204, 10.0 + 0.01 * 204);
  far.seq = 203 + (std::int64_t(1) << 32);
  CHECK(comp.process(far, t));
  CHECK(comp.counters().seq_gaps == 1);
  CHECK(comp.counters().seq_missing == (std::int64_t(1) << 32) - 1);
  far.seq += (std::int64_t(1) << 32) + 1;
  CHECK_FALSE(comp.process(far, t));

  // 2^63-1 as the first command of all: the stream starts there; the real one, behind it,
  // is followed from its fifth command
  chaincomp::Compensator fresh(f.entry, f.model, f.config.compensator);
  REQUIRE(fresh.process(hostile, t));
  std::vector<bool> accepted;
  for (int k = 4; k < 4 + 200; ++k) accepted.push_back(fresh.process(f.command(k, 10.0 + 0.01 * k), t));
  CHECK(std::count(accepted.begin(), accepted.begin() + 4, true) == 0);
  CHECK(std::count(accepted.begin() + 4, accepted.end(), true) == 196);
  REQUIRE(chaincomp::kRestartRun == 5);
  const auto& k = fresh.counters();
  CHECK(k.stream_restarts == 1);
  CHECK(k.rejected[static_cast<int>(chaincomp::Reject::kOutOfOrderSeq)] == 4);
  CHECK(k.seq_gaps == 0);  // the restart is not a gap, nor are the commands after it
  CHECK(t.seq == 203);
}

TEST_CASE("a CNC that restarts its numbering is followed after kRestartRun commands; a hostile "
          "interleave or an inconsistent run never restarts", "[compensator][stream]") {
  Fixture f;
  chaincomp::Compensator comp(f.entry, f.model, f.config.compensator);
  int accepted = 0;
  for (int k = 1; k <= 100; ++k) run(comp, f.command(k), &accepted);
  REQUIRE(accepted == 100);
  // old seqs injected between the stream's commands: each resets the run, none gets in
  for (int k = 101; k <= 200; ++k) {
    run(comp, f.command(k), &accepted);
    run(comp, f.command(k - 100), &accepted);
  }
  CHECK(accepted == 200);
  CHECK(comp.counters().stream_restarts == 0);
  // a run going back in time (utime) or jumping in position is not a stream
  for (int k = 1; k <= 10; ++k) {
    auto c = f.command(k);
    c.utime = 1000000 - 1000 * k;
    run(comp, c, &accepted);
  }
  for (int k = 11; k <= 20; ++k) run(comp, f.command(k, k % 2 ? 10.0 : 25.0), &accepted);
  CHECK(accepted == 200);
  CHECK(comp.counters().stream_restarts == 0);
  // the CNC restarts at seq 1 (a new utime origin as well): accepted from its fifth command
  for (int k = 1; k <= 20; ++k) {
    auto c = f.command(k);
    c.utime = 7 + 1000 * k;
    run(comp, c, &accepted);
    if (k == 4) CHECK(accepted == 200);
    if (k == 5) CHECK(accepted == 201);
  }
  CHECK(accepted == 216);
  CHECK(comp.counters().stream_restarts == 1);
  CHECK(comp.counters().seq_gaps == 0);
}

TEST_CASE("reset starts a new stream at once; gaps in seq are counted", "[compensator][stream]") {
  Fixture f;
  chaincomp::Compensator comp(f.entry, f.model, f.config.compensator);
  int accepted = 0;
  for (int seq : {1, 2, 5, 6, 10}) run(comp, f.command(seq), &accepted);
  auto bad = f.command(11);
  bad.axes[0] = std::nan("");
  run(comp, bad, &accepted);  // received, not missing, though rejected
  run(comp, f.command(12), &accepted);
  CHECK(accepted == 6);
  CHECK(comp.counters().seq_gaps == 2);
  CHECK(comp.counters().seq_missing == 5);  // 3, 4, 7, 8, 9
  comp.reset();
  run(comp, f.command(1, 30.0), &accepted);  // behind, and 20 mm away: a new stream nonetheless
  run(comp, f.command(2, 30.0), &accepted);
  CHECK(accepted == 8);
  const auto& k = comp.counters();
  CHECK(k.resets == 1);
  CHECK(k.stream_restarts == 0);
  CHECK(k.seq_gaps == 2);
  CHECK(k.rejected[static_cast<int>(chaincomp::Reject::kStepTooLarge)] == 0);
}

TEST_CASE("a hostile seq refused far ahead (within kMaxSeqJump) neither counts 2^31 commands missing nor "
          "hides the gaps after it", "[compensator][stream]") {
  Fixture f;
  chaincomp::Compensator comp(f.entry, f.model, f.config.compensator);
  int accepted = 0;
  for (int seq = 1; seq <= 10; ++seq) run(comp, f.command(seq), &accepted);
  auto hostile = f.command(11);
  hostile.seq = 10 + (std::int64_t(1) << 31);
  hostile.axes[0] = std::nan("");  // refused: not the stream's
  run(comp, hostile, &accepted);
  for (int seq : {11, 12, 15, 16}) run(comp, f.command(seq), &accepted);   // 13, 14 lost
  CHECK(accepted == 14);
  // 13 and 14: one gap of two, counted from the last command taken, not from the hostile seq
  const auto& k = comp.counters();
  CHECK(k.seq_gaps == 1);
  CHECK(k.seq_missing == 2);
  // a command refused within a gap is received, not missing
  auto bad = f.command(18);
  bad.axes[0] = std::nan("");
  run(comp, bad, &accepted);
  run(comp, f.command(19), &accepted);  // 17 lost
  CHECK(k.seq_gaps == 2);
  CHECK(k.seq_missing == 3);
}

TEST_CASE("machine names are compared exactly: an empty name or one with a NUL inside is refused",
          "[compensator]") {
  Fixture f;
  chaincomp::Compensator comp(f.entry, f.model, f.config.compensator);
  chaincomp::Target t;
  chaincomp::Reject why;
  const char with_nul[] = "five_axis_ac\0garbage";
  for (std::string_view name : {std::string_view(with_nul, sizeof with_nul - 1), std::string_view(""),
                                std::string_view("five_axis_a"), std::string_view("five_axis_ac ")}) {
    auto c = f.command(1);
    c.machine = name;
    CHECK_FALSE(comp.process(c, t, &why));
    CHECK(why == chaincomp::Reject::kWrongMachine);
  }
  CHECK(comp.process(f.command(1), t));
}

TEST_CASE("a clamped or ramped target carries its own residual and status, not the solver's",
          "[compensator][truthful]") {
  Fixture f;
  for (auto& a : f.config.compensator.axes) a.max_correction_step = 1e-4;
  chaincomp::Compensator comp(f.entry, f.model, f.config.compensator);
  const int n = 5;
  const auto c = f.command(1);
  // the full correction, from a compensator without the rate limit
  chaincomp::Target full;
  {
    chaincomp::CompensatorConfig loose = f.config.compensator;
    for (auto& a : loose.axes) a.max_correction_step = 1.0;
    chaincomp::Compensator ref(f.entry, f.model, loose);
    REQUIRE(ref.process(c, full));
    REQUIRE(full.status == 0);
    REQUIRE(full.residual_point < 1e-7);
  }
  // Independent of the daemon's evaluation: the point error left is, to first order, the
  // Jacobian of the point times the correction still missing (internal units).
  auto linear_residual = [&](const chaincomp::Target& t) {
    double q[8], pose[6], jac[6 * 8];
    for (int i = 0; i < n; ++i) q[i] = t.axes[i] * f.entry.info->axes[i].to_internal;
    f.entry.pose_jacobian(f.model, q, pose, jac);
    const int rows = f.entry.info->pose_size;
    double e[3] = {0, 0, 0};
    for (int i = 0; i < n; ++i) {
      const double missing = (full.correction[i] - t.correction[i]) * f.entry.info->axes[i].to_internal;
      for (int r = 0; r < 3; ++r) e[r] += jac[i * rows + r] * missing;
    }
    return std::sqrt(e[0] * e[0] + e[1] * e[1] + e[2] * e[2]);
  };
  chaincomp::Target t;
  REQUIRE(comp.process(c, t));
  CHECK((t.flags & chaincomp::kFlagClamped) != 0);
  CHECK((t.flags & chaincomp::kFlagResidual) != 0);
  CHECK(t.status == 1);
  // (target - command: the rounding of a 100 mm position)
  for (int i = 0; i < n; ++i) CHECK(std::abs(t.correction[i]) <= 1e-4 + 1e-12);
  const double expected = linear_residual(t);
  REQUIRE(expected > 1e-3);  // some µm still missing
  CHECK(t.residual_point == Approx(expected).epsilon(1e-3));
  // the limit lets the correction catch up: then the solver's residual and status again
  for (int k = 2; k <= 400; ++k) REQUIRE(comp.process(f.command(k), t));
  CHECK((t.flags & (chaincomp::kFlagClamped | chaincomp::kFlagResidual)) == 0);
  CHECK(t.status == 0);
  CHECK(t.residual_point < 1e-7);

  // switched off (ramp 0): the target is the command, and its residual the machine's error
  f.config.compensator.start_enabled = false;
  chaincomp::Compensator off(f.entry, f.model, f.config.compensator);
  REQUIRE(off.process(c, t));
  for (int i = 0; i < n; ++i) CHECK(t.correction[i] == 0.0);
  CHECK(t.status == 1);
  CHECK(t.residual_point == Approx(linear_residual(t)).epsilon(1e-3));
}

namespace {

// The weighted error (point^2 + (kDefaultDirectionWeight angle)^2, mm^2) the pose at `axes` (axis
// units) leaves against the nominal pose at `command`: computed here from pose_exact and
// pose_nominal, the direction as the angle between the tool directions, or with a frame the
// angle between the frames (|Ra - Rt|_F = 2 sqrt2 sin(angle / 2)).
double weighted_error(const chaincomp::ModelEntry& e, const void* model, const double* command, const double* axes) {
  const int n = e.info->num_axes, ps = e.info->pose_size;
  double c[8], a[8], target[9], actual[9];
  for (int i = 0; i < n; ++i) {
    c[i] = command[i] * e.info->axes[i].to_internal;
    a[i] = axes[i] * e.info->axes[i].to_internal;
  }
  e.pose_nominal(model, c, target);
  e.pose_exact(model, a, actual);
  double point = 0, d2 = 0;
  for (int k = 0; k < 3; ++k) point += (actual[k] - target[k]) * (actual[k] - target[k]);
  for (int k = 3; k < ps; ++k) d2 += (actual[k] - target[k]) * (actual[k] - target[k]);
  double angle = 0;
  if (ps == 6) angle = 2 * std::asin(std::sqrt(d2) / 2);
  if (ps == 9) {  // the y axes too: y = z x x
    const double* za = actual + 3; const double* xa = actual + 6;
    const double* zt = target + 3; const double* xt = target + 6;
    const double ya[3] = {za[1] * xa[2] - za[2] * xa[1], za[2] * xa[0] - za[0] * xa[2], za[0] * xa[1] - za[1] * xa[0]};
    const double yt[3] = {zt[1] * xt[2] - zt[2] * xt[1], zt[2] * xt[0] - zt[0] * xt[2], zt[0] * xt[1] - zt[1] * xt[0]};
    for (int k = 0; k < 3; ++k) d2 += (ya[k] - yt[k]) * (ya[k] - yt[k]);
    angle = 2 * std::asin(std::sqrt(d2 / 8));
  }
  const double w = chaincomp::kDefaultDirectionWeight * angle;
  return point + w * w;
}

}  // namespace

TEST_CASE("near a singular pose the rate-limited target is never further off than no correction",
          "[compensator][singular]") {
  struct Case {
    const char* name;
    std::function<void(double, double*)> path;  // axis units at t in [0, 1]
  };
  const Case cases[] = {
      // five_axis_ac: A through 0 (the tool along C) while C turns
      {"five_axis_ac", [](double t, double* q) {
         const double v[5] = {100 + 20 * t, -20, -150, -2 + 4 * t, 30 + 200 * t};
         std::copy(v, v + 5, q);
       }},
      // the UR5: q2 .. q6 together through 0 (the stretched elbow, the wrist), as tools/demo-arm
      {"ur5", [](double t, double* q) {
         q[0] = 30;
         for (int i = 1; i < 6; ++i) q[i] = -6 + 12 * t;
       }},
  };
  for (const Case& c : cases) {
    INFO("machine " << c.name);
    const chaincomp::ModelEntry& entry = *chaincomp::find_model(c.name);
    alignas(64) static unsigned char model[1 << 15];
    REQUIRE(entry.model_size <= sizeof model);
    held_back_case::prepare(entry, model);  // 20 um and 20 arcsec, alternating signs
    chaincomp::DaemonConfig config;
    std::string error;
    REQUIRE(held_back_case::config(entry, config, error));  // every command compensating in full
    chaincomp::Compensator comp(entry, model, config.compensator);
    const int n = entry.info->num_axes, steps = 4000;
    std::vector<double> last(n, 0.0);
    for (int k = 0; k <= steps; ++k) {
      chaincomp::Command cmd;
      cmd.seq = k + 1;
      cmd.utime = 1000 * (k + 1);
      cmd.machine = c.name;
      cmd.num_axes = n;
      c.path(double(k) / steps, cmd.axes.data());
      chaincomp::Target t;
      INFO("command " << k);
      REQUIRE(comp.process(cmd, t));
      const double published = weighted_error(entry, model, cmd.axes.data(), t.axes.data());
      const double none = weighted_error(entry, model, cmd.axes.data(), cmd.axes.data());
      CHECK(published <= none * (1 + 1e-6) + 1e-18);
      for (int i = 0; i < n; ++i) {
        CHECK(std::abs(t.correction[i] - last[i]) <= config.compensator.axes[i].max_correction_step * (1 + 1e-9));
        last[i] = t.correction[i];
      }
    }
    CHECK(comp.counters().clamped > 0);  // the rate limit did engage
  }
}

namespace {

// The wanted correction, the correction published before, and what the limits make of it, as
// docs/guide/daemon.md's "Truthful targets" states the rule: the size limit scales the whole wanted
// correction, the rate limit the whole change from the one before; where that target is
// further off than the command itself, the step back towards none (the one before, scaled
// down by the rate limit) is published instead if it is better.
struct Limited {
  std::vector<double> candidate, back;
  bool clamped = false;
};

Limited limit(const chaincomp::CompensatorConfig& config, const std::vector<double>& wanted,
              const std::vector<double>& prev) {
  const int n = static_cast<int>(wanted.size());
  double size = 1, rate = 1, back = 1;
  for (int i = 0; i < n; ++i) {
    const double most = config.axes[i].max_correction;
    if (std::abs(wanted[i]) > most) size = std::min(size, most / std::abs(wanted[i]));
  }
  for (int i = 0; i < n; ++i) {
    const double step = config.axes[i].max_correction_step, change = std::abs(size * wanted[i] - prev[i]);
    if (change > step) rate = std::min(rate, step / change);
    if (std::abs(prev[i]) > step) back = std::min(back, step / std::abs(prev[i]));
  }
  Limited l;
  l.clamped = size < 1 || rate < 1;
  for (int i = 0; i < n; ++i) {
    l.candidate.push_back(prev[i] + rate * (size * wanted[i] - prev[i]));
    l.back.push_back(prev[i] * (1 - back));
  }
  return l;
}

}  // namespace

TEST_CASE("a rate-limited correction that would leave the tool further off than none is held back, and counted",
          "[compensator][singular][held_back]") {
  // the stream and why it must hold corrections back: held_back_case.hpp
  const chaincomp::ModelEntry& entry = *chaincomp::find_model(held_back_case::kMachine);
  alignas(64) static unsigned char model[1 << 15];
  REQUIRE(entry.model_size <= sizeof model);
  held_back_case::prepare(entry, model);
  chaincomp::DaemonConfig config;
  std::string error;
  REQUIRE(held_back_case::config(entry, config, error));
  chaincomp::CompensatorConfig loose = config.compensator;  // the wanted correction: no size or rate limit
  for (auto& a : loose.axes) a.max_correction = a.max_correction_step = 1e9;
  chaincomp::Compensator comp(entry, model, config.compensator), ref(entry, model, loose);
  const int n = entry.info->num_axes;
  std::vector<double> prev(n, 0.0);
  long long held = 0, uncertain = 0, clamped = 0;
  for (int k = 0; k < held_back_case::kCommands; ++k) {
    const chaincomp::Command cmd = held_back_case::command(k);
    chaincomp::Target full, out;
    INFO("command " << k);
    REQUIRE(ref.process(cmd, full));
    REQUIRE((full.flags & chaincomp::kFlagClamped) == 0);
    REQUIRE(comp.process(cmd, out));
    const std::vector<double> wanted(full.correction.begin(), full.correction.begin() + n);
    const Limited l = limit(config.compensator, wanted, prev);
    auto error_of = [&](const std::vector<double>& correction) {
      double axes[8];
      for (int i = 0; i < n; ++i) axes[i] = cmd.axes[i] + correction[i];
      return weighted_error(entry, model, cmd.axes.data(), axes);
    };
    const double e_candidate = error_of(l.candidate), e_none = error_of(std::vector<double>(n, 0.0)),
                 e_back = error_of(l.back);
    // the daemon measures the direction as a chord, this test as the angle: decisions within
    // a part in 1e6 of a tie are left open
    const double tie = 1e-6 * std::max({e_candidate, e_none, e_back}) + 1e-20;
    const bool open = l.clamped && (std::abs(e_candidate - e_none) < tie || std::abs(e_back - e_candidate) < tie);
    const bool hold = l.clamped && e_candidate > e_none && e_back < e_candidate;
    clamped += l.clamped;
    if (open) {
      ++uncertain;
    } else {
      held += hold;
      // the target published is the one the rule chose (to the rounding of command + correction)
      const std::vector<double>& chosen = hold ? l.back : l.candidate;
      for (int i = 0; i < n; ++i) CHECK(std::abs(out.correction[i] - chosen[i]) <= 1e-9);
    }
    for (int i = 0; i < n; ++i) prev[i] = out.correction[i];
  }
  INFO("clamped " << clamped << ", held back " << held << " (" << uncertain << " too close to call)");
  CHECK(comp.counters().clamped == clamped);
  REQUIRE(held > 0);  // the case does hold corrections back
  CHECK(comp.counters().held_back >= held);
  CHECK(comp.counters().held_back <= held + uncertain);
  CHECK(ref.counters().held_back == 0);
}

TEST_CASE("a command just inside a rejecting table's end is corrected while ramping, not rejected") {
  // EXX (the X slide's positioning error) a table over X on [-100, 100] mm that rejects
  // beyond its ends, -5 µm at X = 100. A command at X = 99.998 lies inside; its correction
  // (about +5 µm in X, and the 5 µm errors of the fixture) puts the target a little past the
  // end. Before, the ramp's residual was taken at that target with the table rejecting there:
  // NaN, and 199 of 200 commands were refused as compensation_failed.
  Fixture f;
  int exx = -1, column = 0;
  for (int i = 0; i < f.entry.info->num_params; ++i) {
    if (std::string_view(f.entry.info->params[i].name) == "EXX") exx = i;
    if (exx < 0 && f.entry.info->params[i].role == chaincomp::ParamRole::kError) ++column;
  }
  REQUIRE(exx >= 0);
  chaincomp::VaryingErrors v;
  const double x[] = {-100, 0, 60, 100}, y[] = {0, 2e-3, -1e-3, -5e-3};
  std::string why;
  int at = -1;
  REQUIRE(chaincomp::add_table(v, exx, column, 0, x, y, 4, chaincomp::Interpolation::kMonotoneCubic,
                               chaincomp::Outside::kReject, why, at));
  f.entry.attach_varying(f.model, &v);
  chaincomp::CompensatorConfig config = f.config.compensator;
  config.ramp_time_s = 0.1;  // 100 commands of ramp
  for (const double xcmd : {99.99, 99.998}) {
    chaincomp::Compensator comp(f.entry, f.model, config);
    int accepted = 0;
    for (int k = 1; k <= 200; ++k) {
      chaincomp::Target t;
      accepted += comp.process(f.command(k, xcmd), t) ? 1 : 0;
    }
    CHECK(accepted == 200);
  }
  // beyond the end the command itself is outside the table: refused, as before
  chaincomp::Compensator comp(f.entry, f.model, config);
  chaincomp::Target t;
  CHECK_FALSE(comp.process(f.command(1, 100.5), t));
}

TEST_CASE("the counters sort the targets by what they correct and sum the objective before and after",
          "[compensator][objective]") {
  Fixture f;
  const int n = 5, count = 50;
  // The command's own objective at weight w (mm), from pose_exact and pose_nominal: the point
  // error squared plus w times the change of the tool direction, squared (compensate.hpp).
  auto command_objective = [&](const chaincomp::Command& c, double w) {
    double q[8], actual[6], nominal[6], point = 0, direction = 0;
    for (int i = 0; i < n; ++i) q[i] = c.axes[i] * f.entry.info->axes[i].to_internal;
    f.entry.pose_exact(f.model, q, actual);
    f.entry.pose_nominal(f.model, q, nominal);
    for (int k = 0; k < 3; ++k) point += (actual[k] - nominal[k]) * (actual[k] - nominal[k]);
    for (int k = 3; k < 6; ++k) direction += (actual[k] - nominal[k]) * (actual[k] - nominal[k]);
    return point + w * w * direction;
  };
  for (auto& a : f.config.compensator.axes) a.max_correction_step = 1.0;  // no rate limit: the whole correction
  for (const double w : {100.0, 25.0}) {
    f.config.compensator.direction_weight = w;
    for (const bool on : {true, false}) {
      f.config.compensator.start_enabled = on;
      chaincomp::Compensator comp(f.entry, f.model, f.config.compensator);
      double before = 0;
      chaincomp::Target t;
      for (int k = 1; k <= count; ++k) {
        const auto c = f.command(k, 10.0 + 0.01 * k);
        REQUIRE(comp.process(c, t));
        before += command_objective(c, w);
      }
      const auto& k = comp.counters();
      REQUIRE(before > 1e-5);  // µm errors: a few µm^2 per command
      CHECK(k.objective_before == Approx(before).epsilon(1e-9));
      CHECK(k.targets_worse == 0);
      if (on) {  // five axes hold point and direction: every target corrected in full
        CHECK((k.targets_full == count && k.targets_partial == 0 && k.targets_uncorrected == 0));
        CHECK(k.objective_after <= count * 2e-14);  // (0.1 nm)^2 + (w 1e-9 rad)^2 at most, each
      } else {  // off: every target the command itself
        CHECK((k.targets_full == 0 && k.targets_partial == 0 && k.targets_uncorrected == count));
        CHECK(k.objective_after == Approx(before).epsilon(1e-9));
      }
    }
  }
}

TEST_CASE("the direction weight is taken within 0.1 .. 10000 mm and refused outside", "[compensator][objective]") {
  Fixture f;
  chaincomp::Compensator comp(f.entry, f.model, f.config.compensator);
  CHECK(comp.direction_weight() == 100.0);  // the documented default
  for (const double bad : {0.0, 0.09, 10000.5, -5.0, std::nan(""), HUGE_VAL}) CHECK_FALSE(comp.set_direction_weight(bad));
  CHECK(comp.direction_weight() == 100.0);
  CHECK(comp.set_direction_weight(0.1));
  CHECK(comp.set_direction_weight(25.0));
  CHECK(comp.direction_weight() == 25.0);
}
