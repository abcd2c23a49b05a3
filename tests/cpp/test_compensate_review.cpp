// Review of the compensation speed-up (trig.hpp, compensate.hpp of ed81529) against truth from
// outside the solver: the generated models evaluated with sines and cosines from the x87 long
// double sinl / cosl (not trig.hpp) and the linear axes' lanes poisoned with NaN; a machine of
// this file's own (closed form, axis kinds interleaved: X A Y C Z) whose every evaluation
// checks the sines and cosines the solver hands it; the least-squares optimum found by an
// independent Gauss-Newton on central differences; and the pose's period 2 pi.
#include <catch2/catch.hpp>

#include <Eigen/Dense>  // the test's own least squares (SVD)
#include <algorithm>
#include <cmath>
#include <cstring>
#include <limits>
#include <memory>
#include <random>
#include <string>
#include <vector>

#include "angle_head.hpp"
#include "chaincomp/compensate.hpp"
#include "frame_angle.hpp"
#include "chaincomp/model_info.hpp"
#include "five_axis_ac.hpp"
#include "me220_xz.hpp"
#include "mori_seiki_nv1500.hpp"
#include "panda.hpp"
#include "trunnion_ac.hpp"
#include "ur5.hpp"
#include "vmc_xyz.hpp"

namespace {

using chaincomp::Status;
constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();
constexpr double kInf = std::numeric_limits<double>::infinity();

// ---- the generated models, evaluated apart from the solver --------------------------------

// A generated model (K its Kinematics) with errors set through the registry's prepare.
template <class K>
struct Generated {
  const chaincomp::ModelEntry& e;
  alignas(64) unsigned char buf[1 << 15];
  // `random`: each error uniform in +-(length, angle); else alternating signs at full size.
  Generated(const char* name, double length, double arcsec, bool random, unsigned seed)
      : e(*chaincomp::find_model(name)) {
    REQUIRE(e.model_size <= sizeof buf);
    REQUIRE(e.info->num_axes == K::kNumAxes);
    std::mt19937_64 rng(seed);
    std::uniform_real_distribution<double> u(-1, 1);
    std::vector<double> p(e.info->num_params);
    for (int i = 0; i < e.info->num_params; ++i) {
      const auto& pi = e.info->params[i];
      const double size = pi.kind == chaincomp::UnitKind::kLength  ? length
                          : pi.kind == chaincomp::UnitKind::kAngle ? arcsec * M_PI / 648000.0
                                                                   : 1e-5;
      p[i] = pi.role == chaincomp::ParamRole::kError ? (random ? u(rng) : (i % 2 ? -1.0 : 1.0)) * size : pi.nominal;
    }
    e.prepare(p.data(), buf);
  }
  const typename K::Model& model() const { return *reinterpret_cast<const typename K::Model*>(buf); }
};

// sin and cos of the angles from sinl / cosl; the linear axes' lanes NaN (a model reading
// them would give a NaN pose).
template <class K>
typename K::Trig exact_trig(const typename K::Axes& q) {
  typename K::Trig t;
  for (int i = 0; i < K::kNumAxes; ++i) {
    t.s[i] = K::kAxisIsAngle[i] ? static_cast<double>(sinl(q[i])) : kNaN;
    t.c[i] = K::kAxisIsAngle[i] ? static_cast<double>(cosl(q[i])) : kNaN;
  }
  return t;
}

struct Residual {
  double point, direction;  // mm; rad (with a frame: the frames' angle)
};

// The actual pose at `corrected` against the nominal one at `command`, with exact_trig.
template <class K>
Residual true_residual(const typename K::Model& m, const typename K::Axes& command,
                       const typename K::Axes& corrected) {
  typename K::Pose target, actual;
  K::pose_nominal(m, command, exact_trig<K>(command), target);
  K::pose_exact(m, corrected, exact_trig<K>(corrected), actual);
  Residual r{(actual.template head<3>() - target.template head<3>()).norm(), 0};
  if constexpr (K::Pose::RowsAtCompileTime == 6) {
    r.direction = (actual.template segment<3>(3) - target.template segment<3>(3)).norm();
  } else if constexpr (K::Pose::RowsAtCompileTime == 9) {
    r.direction = frame_angle(&actual[3], &actual[6], &target[3], &target[6]);
  }
  return r;
}

template <class K>
double bound_of(int i) {
  return K::kAxisIsAngle[i] ? chaincomp::kMaxAngularCorrection : chaincomp::kMaxLinearCorrection;
}

template <class K>
struct Outcome {
  Status status;
  typename K::Axes corrected;
  double residual[2];
};

template <class K>
Outcome<K> run(const typename K::Model& m, chaincomp::Workspace<K>* ws, const typename K::Axes& command) {
  std::unique_ptr<chaincomp::Workspace<K>> fresh;
  if (ws == nullptr) {
    fresh = std::make_unique<chaincomp::Workspace<K>>();
    ws = fresh.get();
  }
  chaincomp::Result<K> r;
  Outcome<K> o;
  o.status = chaincomp::compensate<K>(m, *ws, command, r);
  o.corrected = r.corrected;
  o.residual[0] = r.residual_point;
  o.residual[1] = r.residual_direction;
  return o;
}

// Checks one outcome against the model evaluated apart: status ok or residual, every axis
// within its bound, the residual reported the true one, and ok within the tolerance.
template <class K>
void check_outcome(const typename K::Model& m, const typename K::Axes& command, const Outcome<K>& o) {
  INFO("status " << chaincomp::status_name(o.status));
  REQUIRE((o.status == Status::kOk || o.status == Status::kResidual));
  for (int i = 0; i < K::kNumAxes; ++i) {
    INFO("axis " << i << " command " << command[i] << " corrected " << o.corrected[i]);
    // (to the rounding of command +- bound: 1.5e-11 at 1e5 rad)
    const double ulp = std::nextafter(std::abs(command[i]), kInf) - std::abs(command[i]);
    CHECK(std::abs(o.corrected[i] - command[i]) <= bound_of<K>(i) * (1 + 1e-12) + ulp);
  }
  const Residual t = true_residual<K>(m, command, o.corrected);
  CHECK(std::abs(t.point - o.residual[0]) <= 1e-9 + 1e-9 * t.point);
  constexpr int ps = K::Pose::RowsAtCompileTime;
  if (K::kCorrectsDirection && ps == 6) CHECK(std::abs(t.direction - o.residual[1]) <= 1e-12 + 1e-9 * t.direction);
  if (K::kCorrectsDirection && ps == 9) CHECK(std::abs(t.direction - o.residual[1]) <= 1e-12 + 1e-3 * t.direction);
  if (o.status == Status::kOk) {
    // the solver's own sines and cosines differ from sinl's by < 3e-16: < 1e-12 mm here
    CHECK(t.point <= chaincomp::kPointTolerance + 1e-12);
    if (K::kCorrectsDirection) CHECK(t.direction <= chaincomp::kDirectionTolerance * (1 + 1e-6) + 1e-14);
  }
}

// A command uniform within the axes' limits.
template <class K>
typename K::Axes random_command(const chaincomp::MachineInfo& info, std::mt19937_64& rng) {
  std::uniform_real_distribution<double> u(0, 1);
  typename K::Axes q;
  for (int i = 0; i < K::kNumAxes; ++i) {
    const auto& a = info.axes[i];
    q[i] = (a.lower + (a.upper - a.lower) * u(rng)) * a.to_internal;
  }
  return q;
}

constexpr int kDof(bool direction) { return direction ? 5 : 3; }

// The whole review on one generated machine.
template <class K>
void review_machine(const char* name) {
  INFO("machine " << name);
  constexpr int n = K::kNumAxes;
  constexpr int kCommands = 600;
  constexpr bool kUnique = n <= kDof(K::kCorrectsDirection);  // one solution (not an arm's set)
  bool any_angle = false;
  for (int i = 0; i < n; ++i) any_angle = any_angle || K::kAxisIsAngle[i];
  for (int errors = 0; errors < 2; ++errors) {
    Generated<K> g(name, errors ? 0.05 : 0.02, errors ? 50.0 : 20.0, errors == 1, 11 + errors);
    const auto& m = g.model();
    INFO("error set " << errors);
    std::mt19937_64 rng(31 + errors);
    std::uniform_real_distribution<double> u(0, 1);
    int compared = 0, same_status = 0;
    double worst_period = 0, worst_limit = 0;
    for (int k = 0; k < kCommands; ++k) {
      const typename K::Axes q = random_command<K>(*g.e.info, rng);
      INFO("command " << k);
      const Outcome<K> base = run<K>(m, nullptr, q);
      check_outcome<K>(m, q, base);
      if (!any_angle) continue;
      // The same pose 2 pi k away: every angle by its own whole turns, within kSinCosLimit
      // (the reduction), or one angle beyond it (the library for all; up to 2e5 rad, where
      // the angle's ulp, 2.9e-11, times a metre is still within the tolerance).
      typename K::Axes far = q;
      const bool beyond = k % 3 == 0;
      int moved = -1;
      for (int i = 0; i < n; ++i) {
        if (!K::kAxisIsAngle[i]) continue;
        const double turns = beyond && moved < 0
                                 ? std::floor((chaincomp::kSinCosLimit + 10 + u(rng) * 1e5) / (2 * M_PI))
                                 : std::floor(u(rng) * (chaincomp::kSinCosLimit - 7) / (2 * M_PI));
        far[i] = static_cast<double>(static_cast<long double>(q[i]) +
                                     (i % 2 ? -1 : 1) * turns * 6.283185307179586476925286766559L);
        if (beyond && moved < 0) moved = i;
      }
      const Outcome<K> shifted = run<K>(m, nullptr, far);
      check_outcome<K>(m, far, shifted);
      // The correction is the same to the rounding of the far angle (ulp(1e5) = 1.5e-11, ulp(1e9) = 1.2e-7: the
      // pose at `far` is that of q moved by that much), amplified near singular poses; the status the same.
      if (kUnique && base.status == Status::kOk && shifted.status == Status::kOk) {
        ++compared;
        for (int i = 0; i < n; ++i)
          worst_period = std::max(worst_period, std::abs((shifted.corrected[i] - far[i]) - (base.corrected[i] - q[i])) /
                                                    bound_of<K>(i));
      }
      same_status += base.status == shifted.status;
      // An angle at the limit and just beyond it (the reduction, then the library): continuous.
      typename K::Axes at = q, past = q;
      for (int i = 0; i < n; ++i) {
        if (!K::kAxisIsAngle[i]) continue;
        at[i] = (k % 2 ? -1 : 1) * chaincomp::kSinCosLimit;
        past[i] = std::nextafter(at[i], 2 * at[i]);
        break;
      }
      const Outcome<K> o_at = run<K>(m, nullptr, at), o_past = run<K>(m, nullptr, past);
      check_outcome<K>(m, at, o_at);
      check_outcome<K>(m, past, o_past);
      CHECK(o_at.status == o_past.status);
      if (kUnique && o_at.status == Status::kOk && o_past.status == Status::kOk) {
        for (int i = 0; i < n; ++i)
          worst_limit = std::max(worst_limit, std::abs((o_at.corrected[i] - at[i]) - (o_past.corrected[i] - past[i])) /
                                                  bound_of<K>(i));
      }
    }
    if (any_angle) {
      INFO("corrections 2 pi k apart differ by " << worst_period << " of the bound (" << compared
                                                 << " compared), at and past the limit by " << worst_limit);
      CHECK(same_status >= kCommands - 5);  // near a singular pose a status may flip with the angle's rounding
      CHECK(worst_period <= 1e-7);  // a wrong quadrant or reduction: of the order of the correction itself
      CHECK(worst_limit <= 1e-7);
    }
  }
}

}  // namespace

TEST_CASE("review: every correction checked against the model evaluated with sinl / cosl, angles 2 pi k apart",
          "[compensate][review]") {
  namespace models = chaincomp::models;
  review_machine<models::ur5::Kinematics>("ur5");
  review_machine<models::panda::Kinematics>("panda");
  review_machine<models::five_axis_ac::Kinematics>("five_axis_ac");
  review_machine<models::trunnion_ac::Kinematics>("trunnion_ac");
  review_machine<models::angle_head::Kinematics>("angle_head");
  review_machine<models::vmc_xyz::Kinematics>("vmc_xyz");
  review_machine<models::me220_xz::Kinematics>("me220_xz");
  review_machine<models::mori_seiki_nv1500::Kinematics>("mori_seiki_nv1500");
}

// ---- special commands on the generated machines --------------------------------------------

namespace {

template <class K>
void review_special(const char* name) {
  INFO("machine " << name);
  constexpr int n = K::kNumAxes;
  Generated<K> g(name, 0.02, 20.0, false, 3);
  const auto& m = g.model();
  std::mt19937_64 rng(5);
  auto ws = std::make_unique<chaincomp::Workspace<K>>();
  for (int k = 0; k < 20; ++k) {
    const typename K::Axes q = random_command<K>(*g.e.info, rng);
    for (int i = 0; i < n; ++i) {
      INFO("command " << k << " axis " << i);
      // NaN or Inf: refused, the command returned bit for bit, nothing else, cold or in a stream;
      // the stream's next command is corrected as a cold start is
      for (double bad : {kNaN, kInf, -kInf}) {
        typename K::Axes b = q;
        b[i] = bad;
        for (chaincomp::Workspace<K>* w : {static_cast<chaincomp::Workspace<K>*>(nullptr), ws.get()}) {
          run<K>(m, ws.get(), q);  // a warm state before
          const Outcome<K> o = run<K>(m, w, b);
          CHECK(o.status == Status::kNonFiniteInput);
          CHECK(std::memcmp(o.corrected.data(), b.data(), sizeof(double) * n) == 0);
          CHECK(o.residual[0] == 0);
          CHECK(o.residual[1] == 0);
        }
        const Outcome<K> next = run<K>(m, ws.get(), q), cold = run<K>(m, nullptr, q);
        CHECK(next.status == cold.status);
        CHECK(std::memcmp(next.corrected.data(), cold.corrected.data(), sizeof(double) * n) == 0);
      }
      // -0, the smallest subnormal and the smallest normal: the correction at 0 (to rounding)
      typename K::Axes zero = q;
      zero[i] = 0.0;
      const Outcome<K> at_zero = run<K>(m, nullptr, zero);
      check_outcome<K>(m, zero, at_zero);
      for (double tiny : {-0.0, 5e-324, -5e-324, 2.2250738585072014e-308}) {
        typename K::Axes t = q;
        t[i] = tiny;
        const Outcome<K> o = run<K>(m, nullptr, t);
        check_outcome<K>(m, t, o);
        CHECK(o.status == at_zero.status);
        for (int j = 0; j < n; ++j) CHECK(std::abs((o.corrected[j] - t[j]) - (at_zero.corrected[j] - zero[j])) <= 1e-15);
      }
    }
  }
}

}  // namespace

TEST_CASE("review: NaN and Inf refused on every axis, -0 and subnormals as 0", "[compensate][review]") {
  namespace models = chaincomp::models;
  review_special<models::ur5::Kinematics>("ur5");
  review_special<models::panda::Kinematics>("panda");
  review_special<models::five_axis_ac::Kinematics>("five_axis_ac");
  review_special<models::trunnion_ac::Kinematics>("trunnion_ac");
  review_special<models::angle_head::Kinematics>("angle_head");
  review_special<models::vmc_xyz::Kinematics>("vmc_xyz");
  review_special<models::me220_xz::Kinematics>("me220_xz");
}

// ---- machines with fewer DOF than the pose: the residual is the least-squares minimum --------

namespace {

// The weighted residual compensate() minimises (point; kDefaultDirectionWeight x direction where
// corrected), from the model evaluated with exact_trig.
template <class K>
Eigen::VectorXd weighted_residual(const typename K::Model& m, const typename K::Pose& target,
                                  const typename K::Axes& q) {
  typename K::Pose actual;
  K::pose_exact(m, q, exact_trig<K>(q), actual);
  const int rows = K::kCorrectsDirection ? 6 : 3;
  Eigen::VectorXd r(rows);
  r.head<3>() = actual.template head<3>() - target.template head<3>();
  if (K::kCorrectsDirection) r.tail<3>() = chaincomp::kDefaultDirectionWeight * (actual.template segment<3>(3) - target.template segment<3>(3));
  return r;
}

// Gauss-Newton on central differences from `q` (not the generated Jacobian, not the solver),
// with a step halving line search: the local minimum of |r|^2 near q.
template <class K>
typename K::Axes least_squares(const typename K::Model& m, const typename K::Pose& target, typename K::Axes q) {
  constexpr int n = K::kNumAxes;
  for (int it = 0; it < 40; ++it) {
    const Eigen::VectorXd r = weighted_residual<K>(m, target, q);
    Eigen::MatrixXd J(r.size(), n);
    for (int i = 0; i < n; ++i) {
      const double h = K::kAxisIsAngle[i] ? 1e-6 : 1e-4;
      typename K::Axes a = q, b = q;
      a[i] += h;
      b[i] -= h;
      J.col(i) = (weighted_residual<K>(m, target, a) - weighted_residual<K>(m, target, b)) / (2 * h);
    }
    const Eigen::VectorXd step = J.jacobiSvd(Eigen::ComputeThinU | Eigen::ComputeThinV).solve(r);
    double f0 = r.squaredNorm();
    double scale = 1;
    bool moved = false;
    for (int ls = 0; ls < 30; ++ls, scale *= 0.5) {
      const typename K::Axes trial = q - scale * step;
      if (weighted_residual<K>(m, target, trial).squaredNorm() < f0) {
        q = trial;
        moved = true;
        break;
      }
    }
    if (!moved) break;
  }
  return q;
}

template <class K>
void review_residual(const char* name) {
  INFO("machine " << name);
  for (int errors = 0; errors < 2; ++errors) {
    Generated<K> g(name, errors ? 0.05 : 0.02, errors ? 50.0 : 20.0, errors == 1, 21 + errors);
    const auto& m = g.model();
    std::mt19937_64 rng(41 + errors);
    auto ws = std::make_unique<chaincomp::Workspace<K>>();
    double worst_gap = 0;
    int residuals = 0;
    for (int k = 0; k < 300; ++k) {
      INFO("error set " << errors << " command " << k);
      typename K::Axes q = random_command<K>(*g.e.info, rng);
      typename K::Pose target;
      K::pose_nominal(m, q, exact_trig<K>(q), target);
      for (chaincomp::Workspace<K>* w : {static_cast<chaincomp::Workspace<K>*>(nullptr), ws.get()}) {
        const Outcome<K> o = run<K>(m, w, q);
        check_outcome<K>(m, q, o);
        if (o.status != Status::kResidual) continue;
        ++residuals;
        // the optimum near the correction, and near the command
        const double mine = weighted_residual<K>(m, target, o.corrected).norm();
        double best = weighted_residual<K>(m, target, least_squares<K>(m, target, o.corrected)).norm();
        best = std::min(best, weighted_residual<K>(m, target, least_squares<K>(m, target, q)).norm());
        // The chord's fixed point (J at the command, J^T r = 0 there) is not quite the optimum
        // (J at the solution): at 0.03 mm of residual and 1e-4 rad of correction it leaves up to
        // about 1e-4 relative more (the code before ed81529 the same: 2.5e-6 and 8.2e-6 mm at
        // most here). A pass stopped early would leave the step it did not take.
        CHECK(mine <= best * (1 + 1e-3) + 2e-8);
        worst_gap = std::max(worst_gap, (mine - best) / (best + 1e-12));
      }
      q[0] += 1e-3;  // a stream: the next command near this one
    }
    INFO("worst excess over the least-squares optimum " << worst_gap << " relative, " << residuals << " residuals");
    CHECK(residuals > 0);
    CHECK(worst_gap <= 1e-3);
  }
}

}  // namespace

TEST_CASE("review: fewer DOF than the pose: the residual reported is the least-squares optimum", "[compensate][review]") {
  namespace models = chaincomp::models;
  review_residual<models::angle_head::Kinematics>("angle_head");
  review_residual<models::me220_xz::Kinematics>("me220_xz");
}

// ---- a machine of this file's own, through the solver directly ------------------------------
//
// X A Y C Z (the axis kinds interleaved, mask 0b01010, none of the bundled machines has it): the
// tool point (X, Y, Z) + Rz(C) Rx(A) (0, 0, -L) and direction Rz(C) Rx(A) e_z, with slide,
// squareness, rotary zero, tilt and offset errors in the actual pose. Every evaluation checks
// the sines and cosines the solver passes against sinl / cosl of its axes and logs the call.

namespace {

using Mixed = chaincomp::Core<5, 0b01010u, 6, 6, false>;
using MAxes = Mixed::Axes;
using MPose = Mixed::Pose;

struct MixedMachine {
  double L = 200;
  // errors (mm, rad): slides, squareness, the rotaries' zeros, a tilt of the tool, its offset
  double ex = 0.01, ey = -0.02, ez = 0.015, sxy = 2e-5, szx = -3e-5, ea = 5e-5, ec = -4e-5, eb = 3e-5;
  double ox = 0.02, oy = -0.01, dl = 0.03;
  struct Call {
    char kind;  // 'N' nominal, 'E' exact, 'J' Jacobian
    MAxes q;
  };
  std::vector<Call> calls;
  double worst_trig = 0;  // of the sines and cosines passed, against sinl / cosl of q

  void check_trig(const MAxes& q, const Mixed::Trig& t) {
    for (int i : {1, 3}) {
      worst_trig = std::max({worst_trig, static_cast<double>(std::fabs(t.s[i] - sinl(q[i]))),
                             static_cast<double>(std::fabs(t.c[i] - cosl(q[i])))});
    }
  }
  // The pose from the sines and cosines of A and C (the solver's, or the test's own).
  void pose(const MAxes& q, double sa0, double ca0, double sc0, double cc0, bool errors, MPose& out,
            Mixed::Jacobian* J) const {
    const double e = errors ? 1.0 : 0.0;
    // sin and cos of A + ea and C + ec by the angle-sum formulas
    const double sa = sa0 * std::cos(e * ea) + ca0 * std::sin(e * ea), ca = ca0 * std::cos(e * ea) - sa0 * std::sin(e * ea);
    const double sc = sc0 * std::cos(e * ec) + cc0 * std::sin(e * ec), cc = cc0 * std::cos(e * ec) - sc0 * std::sin(e * ec);
    const Eigen::Vector3d w(e * ox, e * oy, -L + e * dl), u(std::sin(e * eb), 0, std::cos(e * eb));
    auto rx = [&](const Eigen::Vector3d& v) { return Eigen::Vector3d(v[0], ca * v[1] - sa * v[2], sa * v[1] + ca * v[2]); };
    auto drx = [&](const Eigen::Vector3d& v) { return Eigen::Vector3d(0, -sa * v[1] - ca * v[2], ca * v[1] - sa * v[2]); };
    auto rz = [&](const Eigen::Vector3d& v) { return Eigen::Vector3d(cc * v[0] - sc * v[1], sc * v[0] + cc * v[1], v[2]); };
    auto drz = [&](const Eigen::Vector3d& v) { return Eigen::Vector3d(-sc * v[0] - cc * v[1], cc * v[0] - sc * v[1], 0); };
    const Eigen::Vector3d base(q[0] + e * (ex + sxy * q[2]), q[2] + e * ey, q[4] + e * (ez + szx * q[0]));
    out.head<3>() = base + rz(rx(w));
    out.tail<3>() = rz(rx(u));
    if (J != nullptr) {
      J->setZero();
      (*J)(0, 0) = 1;
      (*J)(2, 0) = e * szx;
      J->col(1).head<3>() = rz(drx(w));
      J->col(1).tail<3>() = rz(drx(u));
      (*J)(0, 2) = e * sxy;
      (*J)(1, 2) = 1;
      J->col(3).head<3>() = drz(rx(w));
      J->col(3).tail<3>() = drz(rx(u));
      (*J)(2, 4) = 1;
    }
  }
  // The same with the test's own sines and cosines (sinl, cosl).
  void pose_exact_trig(const MAxes& q, bool errors, MPose& out) const {
    pose(q, static_cast<double>(sinl(q[1])), static_cast<double>(cosl(q[1])), static_cast<double>(sinl(q[3])),
         static_cast<double>(cosl(q[3])), errors, out, nullptr);
  }

  static void nominal(void* c, const MAxes& q, const Mixed::Trig& t, MPose& out) noexcept {
    auto& m = *static_cast<MixedMachine*>(c);
    m.check_trig(q, t);
    m.calls.push_back({'N', q});
    m.pose(q, t.s[1], t.c[1], t.s[3], t.c[3], false, out, nullptr);
  }
  static void exact(void* c, const MAxes& q, const Mixed::Trig& t, MPose& out) noexcept {
    auto& m = *static_cast<MixedMachine*>(c);
    m.check_trig(q, t);
    m.calls.push_back({'E', q});
    m.pose(q, t.s[1], t.c[1], t.s[3], t.c[3], true, out, nullptr);
  }
  static void jacobian(void* c, const MAxes& q, const Mixed::Trig& t, MPose& out, Mixed::Jacobian& J) noexcept {
    auto& m = *static_cast<MixedMachine*>(c);
    m.check_trig(q, t);
    m.calls.push_back({'J', q});
    m.pose(q, t.s[1], t.c[1], t.s[3], t.c[3], true, out, &J);
  }
  Mixed::Machine machine() { return Mixed::Machine{this, this, &nominal, &exact, &jacobian}; }
};

double mixed_bound(int i) { return i == 1 || i == 3 ? chaincomp::kMaxAngularCorrection : chaincomp::kMaxLinearCorrection; }

struct MixedCall {
  Status status;
  Mixed::Result out;
  bool cold;    // the solve began with the Jacobian at the command
  bool damped;  // a pose at the command after the first pass (the damped pass' lambda)
};

MixedCall mixed_run(MixedMachine& mm, Mixed::State& ws, const MAxes& command) {
  mm.calls.clear();
  MixedCall c;
  c.status = Mixed::compensate(mm.machine(), ws, command, c.out);
  // a warm call redone cold begins again with the nominal pose: the last solve counts
  std::size_t begin = 0;
  for (std::size_t i = 0; i < mm.calls.size(); ++i)
    if (mm.calls[i].kind == 'N') begin = i;
  c.cold = mm.calls.size() > begin + 1 && mm.calls[begin + 1].kind == 'J' && mm.calls[begin + 1].q == command;
  c.damped = false;
  for (std::size_t i = begin + 2; i < mm.calls.size(); ++i)
    c.damped = c.damped || (mm.calls[i].kind == 'E' && mm.calls[i].q == command);
  // every evaluation within the correction bounds of the command (to its rounding)
  for (const auto& call : mm.calls) {
    for (int i = 0; i < 5; ++i) {
      const double ulp = std::nextafter(std::abs(command[i]), kInf) - std::abs(command[i]);
      CHECK(std::abs(call.q[i] - command[i]) <= mixed_bound(i) + ulp);
    }
  }
  return c;
}

// The residual the actual pose at the correction leaves, with sinl / cosl.
Residual mixed_residual(const MixedMachine& mm, const MAxes& command, const MAxes& corrected) {
  MPose target, actual;
  mm.pose_exact_trig(command, false, target);
  mm.pose_exact_trig(corrected, true, actual);
  return {(actual.head<3>() - target.head<3>()).norm(), (actual.tail<3>() - target.tail<3>()).norm()};
}

}  // namespace

TEST_CASE("review: the test's own X A Y C Z machine: its Jacobian against central differences", "[review]") {
  MixedMachine mm;
  std::mt19937_64 rng(9);
  std::uniform_real_distribution<double> u(-1, 1);
  for (int k = 0; k < 50; ++k) {
    const MAxes q(300 * u(rng), 1.5 * u(rng), 300 * u(rng), 3 * u(rng), -150 + 150 * u(rng));
    MPose p;
    Mixed::Jacobian J;
    mm.pose(q, std::sin(q[1]), std::cos(q[1]), std::sin(q[3]), std::cos(q[3]), true, p, &J);
    for (int i = 0; i < 5; ++i) {
      const double h = 1e-5;
      MAxes a = q, b = q;
      a[i] += h;
      b[i] -= h;
      MPose pa, pb;
      mm.pose(a, std::sin(a[1]), std::cos(a[1]), std::sin(a[3]), std::cos(a[3]), true, pa, nullptr);
      mm.pose(b, std::sin(b[1]), std::cos(b[1]), std::sin(b[3]), std::cos(b[3]), true, pb, nullptr);
      CHECK(((pa - pb) / (2 * h) - J.col(i)).norm() <= 1e-6 * (1 + J.col(i).norm()));
    }
  }
}

TEST_CASE("review: X A Y C Z through the solver: the sines and cosines of every evaluation, ok to the tolerance",
          "[compensate][review]") {
  MixedMachine mm;
  std::mt19937_64 rng(10);
  std::uniform_real_distribution<double> u(-1, 1), v(0, 1);
  auto stream = std::make_unique<Mixed::State>();
  int ok = 0, total = 0, warm = 0;
  for (int k = 0; k < 3000; ++k) {
    const double a = (0.2 + 1.3 * v(rng)) * (u(rng) < 0 ? -1 : 1);  // away from A = 0 (tool along C)
    MAxes q(300 * u(rng), a, 300 * u(rng), 3 * u(rng), -150 + 150 * u(rng));
    // A and C whole turns away: within the reduction's limit, at it, and beyond (the library)
    const int kind = k % 4;
    if (kind == 1) q[3] += std::floor(v(rng) * 15000) * 6.283185307179586;
    if (kind == 2) q[3] = std::copysign(chaincomp::kSinCosLimit, u(rng)) * (k % 8 == 2 ? 1.0 : 1.0 + 2.2e-16);
    if (kind == 3) q[1] += std::floor(v(rng) * 30000) * 6.283185307179586;
    INFO("command " << k << ": " << q.transpose());
    for (int s = 0; s < 2; ++s) {
      Mixed::State fresh;
      Mixed::State& ws = s ? *stream : fresh;
      // the stream: this command, then one 2 um / 2e-5 rad away (a warm start)
      for (int step = 0; step < (s ? 2 : 1); ++step) {
        const MAxes c = step ? MAxes(q + MAxes(2e-3, 2e-5, -2e-3, 2e-5, 1e-3)) : q;
        mm.worst_trig = 0;
        const MixedCall r = mixed_run(mm, ws, c);
        CHECK(mm.worst_trig <= 4e-16);
        REQUIRE((r.status == Status::kOk || r.status == Status::kResidual));
        ++total;
        ok += r.status == Status::kOk;
        warm += !r.cold;
        const Residual t = mixed_residual(mm, c, r.out.corrected);
        CHECK(std::abs(t.point - r.out.residual_point) <= 1e-9 + 1e-9 * t.point);
        CHECK(std::abs(t.direction - r.out.residual_direction) <= 1e-12 + 1e-9 * t.direction);
        if (r.status == Status::kOk) {
          CHECK(t.point <= chaincomp::kPointTolerance + 1e-12);
          CHECK(t.direction <= chaincomp::kDirectionTolerance + 1e-14);
        }
      }
    }
  }
  INFO(ok << " of " << total << " ok, " << warm << " warm");
  CHECK(ok == total);  // away from the singular pose every command is corrected in full
  CHECK(warm >= 2000);  // and the stream's second commands start warm
}

TEST_CASE("review: X A Y C Z: after a damped call, a refused one or a residual, the next call starts cold",
          "[compensate][review]") {
  MixedMachine mm;
  auto ws = std::make_unique<Mixed::State>();
  // clean: a warm start follows
  const MAxes clean(10, 0.8, -20, 0.3, -100);
  MixedCall r = mixed_run(mm, *ws, clean);
  REQUIRE(r.status == Status::kOk);
  CHECK(r.cold);
  CHECK(!r.damped);
  r = mixed_run(mm, *ws, clean + MAxes(1e-3, 1e-5, 0, 0, 0));
  CHECK(r.status == Status::kOk);
  CHECK(!r.cold);
  // A = 0: the tool along C, its tilt eb turns about C only with a quarter turn of C: held
  // at the bound, damped
  const MAxes singular(10, 0.0, -20, 0.3, -100);
  for (const MAxes& next : {MAxes(singular + MAxes(1e-3, 0, 0, 0, 0)), MAxes(clean + MAxes(0, 0, 0, 1e-4, 0))}) {
    r = mixed_run(mm, *ws, clean);  // warm state first
    r = mixed_run(mm, *ws, singular);
    INFO("status " << chaincomp::status_name(r.status));
    CHECK(r.damped);
    CHECK(r.status == Status::kResidual);
    const Residual t = mixed_residual(mm, singular, r.out.corrected);
    CHECK(std::abs(t.point - r.out.residual_point) <= 1e-9 + 1e-9 * t.point);
    CHECK(t.point <= 1e-6);  // the point keeps priority
    // the next call, near the damped one or back near the clean one: cold, as a fresh state's
    const MixedCall after = mixed_run(mm, *ws, next);
    CHECK(after.cold);
    Mixed::State fresh;
    const MixedCall alone = mixed_run(mm, fresh, next);
    CHECK(after.status == alone.status);
    CHECK(after.out.corrected == alone.out.corrected);
    CHECK(after.out.residual_point == alone.out.residual_point);
    CHECK(after.out.residual_direction == alone.out.residual_direction);
  }
  // NaN or Inf on a linear or an angular axis: refused without evaluating the model; then cold
  for (int axis : {0, 1, 3, 4}) {
    for (double bad : {kNaN, kInf}) {
      mixed_run(mm, *ws, clean);
      MAxes b = clean + MAxes(1e-4, 0, 0, 0, 0);
      b[axis] = bad;
      r = mixed_run(mm, *ws, b);
      CHECK(r.status == Status::kNonFiniteInput);
      CHECK(mm.calls.empty());
      r = mixed_run(mm, *ws, clean);
      CHECK(r.cold);
      CHECK(r.status == Status::kOk);
    }
  }
}

TEST_CASE("review: X A Y C Z swept through A = 0: the sines and cosines of every damped evaluation",
          "[compensate][review]") {
  // Near A = 0 the undamped correction grows past kDampingStart of its bound: the damped pass
  // starts from the command (held at the bound) or, partly damped, between the command and the
  // undamped correction; its Jacobian there must have the sines and cosines of there.
  MixedMachine mm;
  auto ws = std::make_unique<Mixed::State>();
  int damped = 0, damped_away = 0, residual = 0;
  double worst = 0;
  for (int k = -1500; k <= 1500; ++k) {
    const MAxes command(10 + 0.01 * k, 2e-5 * k, -20, 0.3 + 1e-4 * k, -100);
    for (int s = 0; s < 2; ++s) {
      Mixed::State fresh;
      mm.worst_trig = 0;
      const MixedCall r = mixed_run(mm, s ? *ws : fresh, command);
      worst = std::max(worst, mm.worst_trig);
      REQUIRE((r.status == Status::kOk || r.status == Status::kResidual));
      residual += r.status == Status::kResidual;
      const Residual t = mixed_residual(mm, command, r.out.corrected);
      CHECK(std::abs(t.point - r.out.residual_point) <= 1e-9 + 1e-9 * t.point);
      CHECK(std::abs(t.direction - r.out.residual_direction) <= 1e-12 + 1e-9 * t.direction);
      if (!r.damped) continue;
      ++damped;
      // the damped pass' first Jacobian: the first 'J' after the pose at the command
      bool seen = false;
      for (const auto& call : mm.calls) {
        if (call.kind == 'E' && call.q == command) seen = true;
        if (seen && call.kind == 'J') {
          damped_away += !(call.q == command);
          break;
        }
      }
    }
  }
  INFO(damped << " damped calls, " << damped_away << " of them starting away from the command, " << residual
              << " residuals; worst sin/cos " << worst);
  CHECK(worst <= 4e-16);
  CHECK(damped_away > 0);
  CHECK(residual > 0);
}
