// Compensation along paths through singular poses (issue #17): the correction is a continuous
// function of the command (no jump), every correction stays within its bound, and the
// residual reported is the one pose_exact at the corrected axes leaves against pose_nominal
// at the command. Truth from outside compensate(): the poses, and continuity measured as the
// correction's change between commands shrinking with the command step.
#include <catch2/catch.hpp>

#include <algorithm>
#include <cmath>
#include <functional>
#include <string>
#include <vector>

#include "chaincomp/compensate.hpp"
#include "frame_angle.hpp"
#include "chaincomp/model_info.hpp"

namespace {

struct Machine {
  const chaincomp::ModelEntry& e;
  alignas(64) unsigned char model[1 << 15];
  explicit Machine(const char* name, double length_error, double angle_error_arcsec)
      : e(*chaincomp::find_model(name)) {
    REQUIRE(e.model_size <= sizeof model);
    std::vector<double> params(e.info->num_params);
    for (int i = 0; i < e.info->num_params; ++i) {
      // alternating signs: not every error in the same direction
      const auto& p = e.info->params[i];
      const double sign = i % 2 ? -1.0 : 1.0;
      params[i] = p.role == chaincomp::ParamRole::kError
                      ? sign * (p.kind == chaincomp::UnitKind::kLength ? length_error
                                                                       : angle_error_arcsec * M_PI / 648000.0)
                      : p.nominal;
    }
    e.prepare(params.data(), model);
  }
  double bound(int i) const {
    return e.info->axes[i].kind == chaincomp::UnitKind::kAngle ? chaincomp::kMaxAngularCorrection
                                                               : chaincomp::kMaxLinearCorrection;
  }
};

struct PathStats {
  double largest_change = 0;       // of any axis' correction between commands, / its bound
  double largest_command_step = 0;  // of any axis, / its correction bound
  int residual = 0, commands = 0;
};

// Runs the path cmd(t), t in [0, 1], at `steps` commands, cold (null workspace) or through
// one workspace; checks the bounds and the residual on each command.
PathStats run_path(Machine& m, int steps, bool stream, const std::function<void(double, double*)>& path) {
  const int n = m.e.info->num_axes, ps = m.e.info->pose_size;
  std::vector<unsigned char> storage;
  void* ws = nullptr;
  if (stream) {
    ws = chaincomp::aligned_slot(storage, m.e.workspace_size, m.e.workspace_align);
    m.e.init_workspace(ws);
  }
  PathStats st;
  std::vector<double> cmd(n), out(n), last_cmd(n), last_corr(n), target(ps), actual(ps);
  for (int k = 0; k <= steps; ++k) {
    path(double(k) / steps, cmd.data());
    double residual[2];
    const auto status = static_cast<chaincomp::Status>(m.e.compensate(m.model, ws, cmd.data(), chaincomp::kDefaultDirectionWeight, out.data(), residual, nullptr));
    INFO("command " << k << " of " << steps << ", status " << chaincomp::status_name(status));
    REQUIRE((status == chaincomp::Status::kOk || status == chaincomp::Status::kResidual));
    st.residual += status == chaincomp::Status::kResidual;
    ++st.commands;
    for (int i = 0; i < n; ++i) REQUIRE(std::abs(out[i] - cmd[i]) <= m.bound(i) * (1 + 1e-12));
    m.e.pose_nominal(m.model, cmd.data(), target.data());
    m.e.pose_exact(m.model, out.data(), actual.data());
    double point = 0;
    for (int i = 0; i < 3; ++i) point += (actual[i] - target[i]) * (actual[i] - target[i]);
    CHECK(std::abs(std::sqrt(point) - residual[0]) <= 1e-9 + 1e-9 * residual[0]);
    if (ps == 6) {
      double dir = 0;
      for (int i = 3; i < 6; ++i) dir += (actual[i] - target[i]) * (actual[i] - target[i]);
      CHECK(std::abs(std::sqrt(dir) - residual[1]) <= 1e-12 + 1e-9 * residual[1]);
    } else if (ps == 9) {  // the orientation residual: the frames' angle to first order
      const double angle = frame_angle(&actual[3], &actual[6], &target[3], &target[6]);
      CHECK(std::abs(angle - residual[1]) <= 1e-12 + 1e-3 * angle);
    }
    if (k > 0) {
      for (int i = 0; i < n; ++i) {
        st.largest_change = std::max(st.largest_change, std::abs((out[i] - cmd[i]) - last_corr[i]) / m.bound(i));
        st.largest_command_step = std::max(st.largest_command_step, std::abs(cmd[i] - last_cmd[i]) / m.bound(i));
      }
    }
    for (int i = 0; i < n; ++i) {
      last_cmd[i] = cmd[i];
      last_corr[i] = out[i] - cmd[i];
    }
  }
  return st;
}

// Continuity: the largest change between commands is at most `lipschitz` times the command
// step (both as fractions of the bounds), at a coarse and a ten times finer sampling; a
// jump would not shrink with the step.
// A redundant arm's stream is checked for its bounds and residuals only: a warm start may land
// elsewhere on the set of equally good corrections than a cold one (docs/guide/daemon.md, "Arms").
void check_continuous(Machine& m, int steps, double lipschitz, const std::function<void(double, double*)>& path,
                      bool damped = true, bool redundant = false) {
  for (bool stream : {false, true}) {
    INFO((stream ? "stream" : "cold"));
    const PathStats coarse = run_path(m, steps, stream, path);
    const PathStats fine = run_path(m, 10 * steps, stream, path);
    INFO("largest change " << coarse.largest_change << " / " << fine.largest_change << " of the bound, command step "
                           << coarse.largest_command_step << " / " << fine.largest_command_step);
    if (damped) CHECK(coarse.residual > 0);  // the path does pass where the correction is damped
    if (stream && redundant) continue;
    CHECK(coarse.largest_change <= lipschitz * coarse.largest_command_step);
    CHECK(fine.largest_change <= lipschitz * fine.largest_command_step);
    // (changes below 1e-3 of the bound: the tolerance's reach)
    CHECK(fine.largest_change <= std::max(0.3 * coarse.largest_change, 1e-3));
  }
}

}  // namespace

TEST_CASE("five_axis_ac through A = 0 (the tool along C): a continuous, bounded correction", "[singular]") {
  Machine m("five_axis_ac", 5e-3, 20.0);
  const double deg = M_PI / 180;
  // A from -2 to 2 degrees while C turns and the slides move: through the singular pose
  check_continuous(m, 2000, 50.0, [&](double t, double* q) {
    q[0] = 100 + 50 * t;
    q[1] = -20 + 30 * t;
    q[2] = -150 + 20 * t;
    q[3] = (-2 + 4 * t) * deg;
    q[4] = (30 + 40 * t) * deg;
  });
  // and the point stays corrected there (the point's priority over the direction)
  for (int k = 0; k <= 400; ++k) {
    const double q[5] = {100, -20, -150, (-1 + k / 200.0) * deg, 45 * deg};
    double out[5], residual[2];
    m.e.compensate(m.model, nullptr, q, chaincomp::kDefaultDirectionWeight, out, residual, nullptr);
    CHECK(residual[0] < 1e-6);
  }
}

TEST_CASE("the UR5 through the stretched elbow (q3 = 0) and the wrist (q5 = 0): continuous and bounded",
          "[singular]") {
  Machine m("ur5", 5e-3, 20.0);
  const double deg = M_PI / 180;
  // as tools/demo-arm's path near there: q2 .. q6 together through 0
  check_continuous(m, 2000, 50.0, [&](double t, double* q) {
    q[0] = 30 * deg;
    for (int i = 1; i < 6; ++i) q[i] = (-3 + 6 * t) * deg;
  });
  // the wrist alone through q5 = 0, the elbow bent
  check_continuous(m, 2000, 50.0, [&](double t, double* q) {
    const double qs[6] = {10, -60, 80, -40, -2 + 4 * t, 30};
    for (int i = 0; i < 6; ++i) q[i] = qs[i] * deg;
  });
}

TEST_CASE("the Panda (redundant) through its stretched elbow (q4 = 0): continuous and bounded", "[singular]") {
  Machine m("panda", 5e-3, 20.0);
  const double deg = M_PI / 180;
  check_continuous(m, 2000, 50.0, [&](double t, double* q) {
    const double qs[7] = {20, 10, -15, -4 + 8 * t, 10, 2 + 1 * t, 30};
    for (int i = 0; i < 7; ++i) q[i] = qs[i] * deg;
  }, false, true);
}
