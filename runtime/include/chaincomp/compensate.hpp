// Compensation: corrected axis commands such that the actual tool point (and tool
// direction, where the machine's rotary axes can correct it) equals the nominal one at the
// commanded axes. Gauss-Newton steps on the generated exact Jacobian until the residual is
// within tolerance, at most a fixed number: bounded cost per call, no heap, no exceptions.
// A workspace kept across a stream of commands lets a call start from the last correction
// (a warm start). Errors that vary along an axis (tables, polynomials: varying.hpp) are
// evaluated at the command and at every Newton iterate, and their slopes enter the Jacobian.
#pragma once

#include <Eigen/Core>
#include <algorithm>
#include <cmath>
#include <limits>
#include <type_traits>

#include "chaincomp/trig.hpp"
#include "chaincomp/varying.hpp"

namespace chaincomp {

// Status codes of compensate(); docs/guide/daemon.md ("Generated C++ and compensation") lists them.
enum class Status : int {
  kOk = 0,             // corrected: residual within tolerance
  kResidual = 1,       // best correction found, but a residual remains (fewer DOF than errors)
  kNonFiniteInput = 2, // the command holds NaN or Inf: nothing computed, output = command
  kSingular = 3,       // the Jacobian is singular at the command: output = command
  kNonFiniteOutput = 4, // the iteration produced NaN or Inf: output = command
  kOutsideTable = 5     // an axis lies outside a table (or polynomial range) whose `outside` is
                        // reject: output = command
};

inline const char* status_name(Status s) noexcept {
  switch (s) {
    case Status::kOk: return "ok";
    case Status::kResidual: return "residual";
    case Status::kNonFiniteInput: return "non_finite_input";
    case Status::kSingular: return "singular";
    case Status::kNonFiniteOutput: return "non_finite_output";
    case Status::kOutsideTable: return "outside_table";
  }
  return "unknown";
}

constexpr double kPointTolerance = 1e-7;      // mm: 0.1 nm
constexpr double kDirectionTolerance = 1e-9;  // rad
// The direction weight (mm per rad: a direction error counts as at this length from the tool
// point), a run-time argument of compensate() (the runtime config's direction_weight): its
// default and its range. Outside the range the normal equations lose the point's digits (the
// direction rows 1e8 times heavier) or the direction's: compensate() takes the nearest end.
constexpr double kDefaultDirectionWeight = 100.0;
constexpr double kMinDirectionWeight = 0.1;
constexpr double kMaxDirectionWeight = 10000.0;

constexpr double valid_direction_weight(double weight) noexcept {
  return !(weight >= kMinDirectionWeight) ? kMinDirectionWeight : weight > kMaxDirectionWeight ? kMaxDirectionWeight : weight;
}

// The objective compensation minimises (docs/guide/daemon.md, "The objective"): the point error
// (mm) squared plus the direction (orientation) error (rad) weighted as at `weight` mm.
constexpr double objective(double point, double direction, double weight = kDefaultDirectionWeight) noexcept {
  return point * point + weight * weight * direction * direction;
}
// Largest correction compensate() will make, per axis kind: geometric errors need µm and
// arcsec; more means a singular configuration (e.g. the tool axis along the C axis), where
// the correction is bounded and the rest reported as residual.
constexpr double kMaxLinearCorrection = 1.0;      // mm
constexpr double kMaxAngularCorrection = 0.0175;  // rad, about 1 degree
// Steps per pass: at µm and arcsec errors two reach the tolerance; near a singular pose the
// chord converges slowly and takes more. A call makes one pass, or two near a singular pose
// (undamped, then damped: below); the worst-case cost stays known.
constexpr int kMaxSteps = 6;
// Near a singular pose the least-squares correction grows without bound. There a second,
// damped pass follows (Levenberg-Marquardt on the total correction, each axis' damping
// scaled by its bound, D = diag(1 / bound^2)) with lambda = h |r|^2 / (4 kTrustRadius^2), r
// the weighted residual at the command: every singular mode of the damped correction is at
// most |r| / (2 sqrt(lambda)), so its bound-scaled norm, sqrt(sum (correction_i / bound_i)^2),
// stays within kTrustRadius, and it shrinks to zero along a mode whose gain does (a trust
// region of fixed radius would keep its full length there and flip its sign as the gain
// crosses zero: a jump). h rises smoothly (smoothstep) from 0 to 1 as the undamped
// correction's largest axis goes from kDampingStart of its bound to the bound: lambda = 0
// (the undamped answer, at the undamped cost) wherever every axis lies within
// kDampingStart, and the correction is a continuous function of the command.
constexpr double kTrustRadius = 1.0;
constexpr double kDampingStart = 0.75;
// In the damped pass the point keeps priority over the direction (orientation): its rows
// weigh up to this much more there (1 + (kPointPriority - 1) sqrt(h)); the point residual
// the damping leaves shrinks with the square of the weight.
constexpr double kPointPriority = 1e3;
// A step larger than this fraction of the bound (0.25 mm, 0.25 degree) refreshes the
// Jacobian: below it the chord gains at least two digits per step.
constexpr double kChordStepLimit = 0.25;
// A warm start only where the correction stays within half its bound: nearer a singular
// pose (a large rotary correction) the answer would depend on where the iteration starts.
constexpr double kWarmCorrectionLimit = 0.5;

// sin and cos of each angular axis (the entries of linear axes are not used).
template <int N>
struct AxisTrig {
  double s[N];
  double c[N];
};

// Bit i of an axis-kind mask: axis i is an angle.
constexpr bool is_angle_axis(unsigned angles, int i) noexcept { return ((angles >> i) & 1u) != 0; }
// Every one of n axes an angle (an arm): the trig loops below then test nothing per axis and
// gcc vectorises them (a test of the mask in the loop, even one known when compiling, keeps
// it from doing so: 6 % of a cold compensation on the UR5).
constexpr bool all_angles(unsigned angles, int n) noexcept { return angles == (n >= 32 ? ~0u : (1u << n) - 1); }

template <int N, unsigned Angles>
void axis_trig(const Eigen::Matrix<double, N, 1>& q, AxisTrig<N>& t) noexcept {
  if constexpr (Angles != 0) {
    bool reducible = true;  // every angle within kSinCosLimit (false for NaN)
    for (int i = 0; i < N; ++i) {
      if (is_angle_axis(Angles, i)) reducible &= std::abs(q[i]) <= kSinCosLimit;
    }
    if (reducible) {  // a loop without branches
      for (int i = 0; i < N; ++i) {
        if (all_angles(Angles, N) || is_angle_axis(Angles, i)) sin_cos_reduced(q[i], t.s[i], t.c[i]);
      }
      return;
    }
    for (int i = 0; i < N; ++i) {
      if (is_angle_axis(Angles, i)) {
        // One argument reduction for both (gcc merges the pair into sincos only when they
        // share a local).
        const double a = q[i];
        const double s = std::sin(a), c = std::cos(a);
        t.s[i] = s;
        t.c[i] = c;
      }
    }
  }
}

// K's axis kinds as a mask: bit i set where axis i is an angle.
template <class K>
constexpr unsigned angle_mask() noexcept {
  static_assert(K::kNumAxes <= 32, "the axis-kind mask has 32 bits");
  unsigned mask = 0;
  for (int i = 0; i < K::kNumAxes; ++i) mask |= K::kAxisIsAngle[i] ? 1u << i : 0u;
  return mask;
}

template <class K>
void axis_trig(const typename K::Axes& q, AxisTrig<K::kNumAxes>& t) noexcept {
  axis_trig<K::kNumAxes, angle_mask<K>()>(q, t);
}

// sin and cos at q from those at `base` (the angle-sum formulas): a Newton iterate differs
// from the command by at most the correction bound, where sin_small and cos_small are a
// short series and cost less than the library's sin and cos.
template <int N, unsigned Angles>
void axis_trig_near(const Eigen::Matrix<double, N, 1>& base, const AxisTrig<N>& base_trig,
                    const Eigen::Matrix<double, N, 1>& q, AxisTrig<N>& t) noexcept {
  if constexpr (Angles != 0) {
    bool small = true;  // every angle's step from the base below kSmallAngle: the series alone
    for (int i = 0; i < N; ++i) {
      if (is_angle_axis(Angles, i)) small &= std::abs(q[i] - base[i]) < kSmallAngle;
    }
    if (small) {  // a loop without branches
      for (int i = 0; i < N; ++i) {
        if (all_angles(Angles, N) || is_angle_axis(Angles, i)) {
          const double d = q[i] - base[i], sd = sin_small_series(d), cd = cos_small_series(d);
          t.s[i] = base_trig.s[i] * cd + base_trig.c[i] * sd;
          t.c[i] = base_trig.c[i] * cd - base_trig.s[i] * sd;
        }
      }
      return;
    }
    for (int i = 0; i < N; ++i) {
      if (is_angle_axis(Angles, i)) {
        const double d = q[i] - base[i], sd = sin_small(d), cd = cos_small(d);
        t.s[i] = base_trig.s[i] * cd + base_trig.c[i] * sd;
        t.c[i] = base_trig.c[i] * cd - base_trig.s[i] * sd;
      }
    }
  }
}

// Sets every varying error of `m` (a copy of the model) to its value at `q` and its slope
// into `slope`; false where an axis lies outside a range whose `outside` is reject (the
// value is then held at the end of the range). `values` (kNumParams) is NaN but for the
// varying errors, whose entries this overwrites.
template <class K, bool kSlope = true>
bool set_varying(const VaryingErrors& v, typename K::Model& m, const typename K::Axes& q, int* hint,
                 double* slope, double* values) noexcept {
  bool inside = true;
  for (int i = 0; i < v.count; ++i) {
    const VaryingError& e = v.items[i];
    inside &= evaluate<kSlope>(v, e, q[e.axis], hint ? hint + i : nullptr, values[e.param], slope[i]);
  }
  K::set_errors(m, values);
  return inside;
}

template <class K>
void clear_values(double* values) noexcept {
  for (int i = 0; i < K::kNumParams; ++i) values[i] = std::numeric_limits<double>::quiet_NaN();
}

// The Jacobian with respect to the axes of the pose with varying errors: the chain rule adds
// (d pose / d error) * (d error / d axis) to the column of the error's axis. d pose / d error
// is the first-order error gain matrix: exact at zero errors; the part it leaves out is of
// the order of the error times the slope (~1e-9 of the Jacobian at µm and arcsec).
template <class K>
void add_slopes(const VaryingErrors& v, const typename K::Gain& gain, const double* slope,
                typename K::Jacobian& J) noexcept {
  // Summed in registers per run of errors along the same axis (a file lists a slide's errors
  // together): adding each into J in turn made a chain of stores and reloads.
  for (int i = 0; i < v.count;) {
    const int axis = v.items[i].axis;
    typename K::Pose sum = slope[i] * gain.col(v.items[i].column);
    for (++i; i < v.count && v.items[i].axis == axis; ++i) sum += slope[i] * gain.col(v.items[i].column);
    J.col(axis) += sum;
  }
}

// The model to evaluate at `q`: `m` itself without varying errors, else `scratch` holding
// them at `q` (slopes into `slope`); nullptr where `q` lies outside a range that rejects,
// unless `held`: then the errors there are held at the range's end, as compensate's
// iterates see them.
template <class K>
const typename K::Model* model_at(const typename K::Model& m, const typename K::Axes& q,
                                  typename K::Model& scratch, double* slope, bool held = false) noexcept {
  if (m.varying == nullptr) return &m;
  scratch = m;
  double values[K::kNumParams];
  clear_values<K>(values);
  return set_varying<K>(*m.varying, scratch, q, nullptr, slope, values) || held ? &scratch : nullptr;
}

// LDL^T factorisation of a small symmetric positive definite matrix and its solve, plain
// loops of compile-time length and no square root: at 5x5, Eigen's LLT (generic triangular
// solver) cost more than every model evaluation of a call together.
template <int N>
class SmallLdlt {
 public:
  // Reads the lower triangle of A. False where A is not positive definite (a pivot not > 0,
  // or NaN). The loops here and in solve are unrolled: gcc keeps such short loops
  // otherwise, at twice to three times the cost.
  bool compute(const Eigen::Matrix<double, N, N>& A) noexcept {
#pragma GCC unroll 8
    for (int j = 0; j < N; ++j) {
      double w[N] = {};  // L(j, k) D(k)
      double d = A(j, j);
#pragma GCC unroll 8
      for (int k = 0; k < j; ++k) {
        w[k] = l_[j][k] * d_[k];
        d -= l_[j][k] * w[k];
      }
      if (!(d > 0)) return false;
      d_[j] = d;
      inv_d_[j] = 1.0 / d;
#pragma GCC unroll 8
      for (int i = j + 1; i < N; ++i) {
        double s = A(i, j);
#pragma GCC unroll 8
        for (int k = 0; k < j; ++k) s -= l_[i][k] * w[k];
        l_[i][j] = s * inv_d_[j];
      }
    }
    return true;
  }
  // X with A X = B: forward substitution with L, division by D, back substitution with
  // L^T, on every column of B at once (rows stored contiguously: the columns pipeline).
  template <int M>
  Eigen::Matrix<double, N, M> solve(const Eigen::Matrix<double, N, M>& b) const noexcept {
    Eigen::Matrix<double, N, M, M == 1 ? Eigen::ColMajor : Eigen::RowMajor> x = b;
#pragma GCC unroll 8
    for (int i = 1; i < N; ++i) {
#pragma GCC unroll 8
      for (int k = 0; k < i; ++k) x.row(i) -= l_[i][k] * x.row(k);
    }
#pragma GCC unroll 8
    for (int i = N - 1; i >= 0; --i) {
      x.row(i) *= inv_d_[i];
#pragma GCC unroll 8
      for (int k = i + 1; k < N; ++k) x.row(i) -= l_[k][i] * x.row(k);
    }
    return x;
  }

 private:
  double l_[N][N];  // strictly lower triangle of the unit lower triangular L
  double d_[N], inv_d_[N];
};

// a x b (Eigen's cross needs the Geometry module).
template <class A, class B>
Eigen::Vector3d cross3(const A& a, const B& b) noexcept {
  return Eigen::Vector3d(a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]);
}

// The orientation residual of an actual frame (za, xa) against the target (zt, xt, yt = zt x
// xt): zt x za (the rotation vector's part orthogonal to zt) + (yt . xa) zt (its part about
// zt). It equals the rotation vector omega of R_actual R_target^T to first order and is zero
// exactly where the frames agree; its Jacobian is [zt]x Jz + zt (yt^T Jx).
template <class Z, class X>
Eigen::Vector3d orientation_residual(const Eigen::Vector3d& zt, const Eigen::Vector3d& yt, const Z& za,
                                     const X& xa) noexcept {
  return cross3(zt, za) + yt.dot(xa) * zt;
}

// The compensation solver, on a machine's shape alone: N axes, Angles their kinds (bit i set: axis i
// is an angle, so its bound and its sin and cos are known when compiling); pose size P (3: the tool point;
// 6: and the tool direction; 9: and a frame's x axis); R residual rows (3: the point; 6: and the
// direction, or with O the orientation, corrected). The model enters through three functions
// (Machine), so one compiled solver serves every machine of a shape: chaincomp build compiles
// it once per shape (its cached object; emit.py's solvers() for programs of one's own) and
// declares it extern in each model (CHAINCOMP_PREBUILT_CORE): a model's compile no longer
// includes it. Without that macro (the bundled build) a model instantiates it here,
// self-contained, and the calls through Machine go straight to its functions.
template <int N, unsigned Angles, int P, int R, bool O>
struct Core {
  static_assert(R == 3 || R == 6, "rows: the point, or the point and the direction/orientation");
  static_assert(!O || (P == 9 && R == 6), "the orientation needs a frame (pose size 9)");
  using Axes = Eigen::Matrix<double, N, 1>;
  using Pose = Eigen::Matrix<double, P, 1>;
  using Jacobian = Eigen::Matrix<double, P, N>;
  using Trig = AxisTrig<N>;
  using Eval = void (*)(void* context, const Axes& q, const Trig& t, Pose& out) noexcept;
  using EvalJacobian = void (*)(void* context, const Axes& q, const Trig& t, Pose& out, Jacobian& J) noexcept;

  // The model as the solver sees it: its pose (and Jacobian) at q from the axes' sin and cos.
  struct Machine {
    const void* identity;        // the model: a warm start only follows a call on the same one
    void* context;               // passed to the functions below
    Eval pose_nominal, pose_exact;
    EvalJacobian pose_jacobian;
  };

  struct Result {
    Axes corrected;
    double residual_point = 0;      // mm
    double residual_direction = 0;  // rad: the direction (with a frame: orientation) residual
    // the same of the command itself (no correction): the objective before, beside the one after
    double before_point = 0, before_direction = 0;
  };

  // Kept by a caller across the commands of a stream (of one model): a command near the last
  // one starts from the last correction with the last factorisation (a warm start), which
  // usually leaves one or two model evaluations. A fresh state, a command far from the last,
  // or another model starts cold. Trivially destructible.
  struct State {
    Pose target, pose;
    Jacobian jacobian;
    Eigen::Matrix<double, R, N> weighted;  // the Jacobian as factorised
    // J^T J + levenberg I, factorised: a step solves it for J^T r (+ levenberg (q - command)
    // on a redundant machine: the pull towards the command). (In a damped pass these stay
    // those of the undamped one: a damped call never leads to a warm start.)
    SmallLdlt<N> factor;
    double levenberg = 0;
    bool warm = false;  // the last call ended corrected (ok), with every axis free
    const void* warm_model = nullptr;  // the model of that call
    Axes last_command, last_corrected;
    Axes last_correction_change = Axes::Zero();  // from the command before
    Axes jacobian_axes;  // where the factorised Jacobian was taken
    double warm_weight = 0;  // the direction weight the factorisation was taken with
    Trig command_trig, trig;  // at the command, at the current axes
  };

  // The warm start's rules, then solve(); see compensate<K> below.
  // `direction_weight`: the objective's (valid_direction_weight() of it is taken).
  static Status compensate(const Machine& m, State& ws, const Axes& command, Result& out,
                           double direction_weight = kDefaultDirectionWeight) noexcept;
  // One compensation from `start` (a warm start: the factorisation in ws is used) or, where
  // null, cold from the command. `clean`: the call ended undamped with every axis within
  // its bound.
  static Status solve(const Machine& m, State& ws, const Axes& command, const Axes* start, Result& out,
                      bool& clean, double weight) noexcept;
};

// The correction bound of an axis: per axis kind.
inline double correction_bound(bool is_angle) noexcept {
  return is_angle ? kMaxAngularCorrection : kMaxLinearCorrection;
}

// Whether every axis of q lies within `fraction` of its correction bound around `command`.
template <int N, unsigned Angles>
bool within_bounds(const Eigen::Matrix<double, N, 1>& q, const Eigen::Matrix<double, N, 1>& command,
                   double fraction = 1.0) noexcept {
  for (int i = 0; i < N; ++i) {
    if (!(std::abs(q[i] - command[i]) <= fraction * correction_bound(is_angle_axis(Angles, i)))) return false;
  }
  return true;
}

// Gauss-Newton (chord) steps on |W r(q)|^2 (W the row weights: the direction or orientation
// rows as at `weight` mm per rad); near a singular pose a second, damped pass
// (kTrustRadius above). Where the Jacobian has a null space (a seven-joint arm; a six-joint
// arm holding point and direction, which leaves the turn about the tool axis free) every
// step removes the correction's part along it: of all corrections equally good, the one of
// least bound-scaled norm, i.e. the one closest to the command, whatever the iteration
// starts from (the null-space rule).
template <int N, unsigned Angles, int P, int R, bool O>
Status Core<N, Angles, P, R, O>::solve(const Machine& m, State& ws, const Axes& command, const Axes* start, Result& out,
                               bool& clean, double weight) noexcept {
  constexpr int n = N;
  constexpr int rows = R;
  constexpr bool kDirection = R == 6;  // the direction (or orientation) rows are corrected
  using Square = Eigen::Matrix<double, n, n>;
  // More axes than the conditions they are to meet (a seven-joint arm; a six-joint arm holding
  // point and direction only): a set of equally good corrections.
  constexpr int dof = O ? 6 : kDirection ? 5 : 3;
  constexpr bool kRedundant = n > dof;
  // The pull towards the command (below) also where fewer axes than conditions may leave a
  // null space all the same (a table's C axis about the tool direction moves the point only).
  constexpr bool kPull = kRedundant || (kDirection && n < dof);
  clean = false;
  out.corrected = command;
  out.residual_point = out.residual_direction = out.before_point = out.before_direction = 0;
  if (!command.allFinite()) return Status::kNonFiniteInput;
  // per axis: the correction bound and its inverse (constants: no division)
  Axes bound, inv_bound;
  for (int i = 0; i < n; ++i) {
    bound[i] = correction_bound(is_angle_axis(Angles, i));
    inv_bound[i] = is_angle_axis(Angles, i) ? 1.0 / kMaxAngularCorrection : 1.0 / kMaxLinearCorrection;
  }
  const Axes lowest = command - bound, highest = command + bound;  // every iterate within
  // The actual pose (and its Jacobian) at q. sin and cos of the angular axes at the command
  // once per call (axis_trig), the iterates' from them (axis_trig_near: at q = command it
  // gives the command's exactly).
  axis_trig<N, Angles>(command, ws.command_trig);
  auto trig_at = [&](const Axes& q) -> const Trig& {
    axis_trig_near<N, Angles>(command, ws.command_trig, q, ws.trig);
    return ws.trig;
  };
  auto pose_at = [&](const Axes& q) { m.pose_exact(m.context, q, trig_at(q), ws.pose); };
  auto pose_at_command = [&]() { m.pose_exact(m.context, command, ws.command_trig, ws.pose); };
  auto jacobian_at = [&](const Axes& q, const Trig& t) {
    ws.jacobian_axes = q;
    m.pose_jacobian(m.context, q, t, ws.pose, ws.jacobian);
  };

  m.pose_nominal(m.context, command, ws.command_trig, ws.target);
  // Chord Newton: the Jacobian at the command (or, warm, at the last command) serves the
  // following steps as long as they stay small (µm, arcsec: it then differs from the one at
  // the solution by about the correction in rad, ~1e-3 relative, so each step gains about
  // three digits) and one factorisation per call, or none, keeps the cost low. A large step
  // (near a singular pose) takes a fresh Jacobian.
  auto& J = ws.weighted;
  // With a frame: the target's z and y axes, which the orientation rows are taken against.
  Eigen::Vector3d target_z = Eigen::Vector3d::Zero(), target_y = Eigen::Vector3d::Zero();
  if constexpr (O) {
    target_z = ws.target.template segment<3>(3);
    target_y = cross3(target_z, ws.target.template segment<3>(6));
  }
  // The error left at the pose in ws.pose: the point, and the direction (orientation) wherever
  // the pose has one, corrected by this shape or not (a three-axis machine's tilt is reported,
  // never hidden as 0).
  auto pose_error = [&](double& point, double& direction) {
    point = (ws.pose.template head<3>() - ws.target.template head<3>()).norm();
    direction = 0;
    if constexpr (O) {
      direction = orientation_residual(target_z, target_y, ws.pose.template segment<3>(3),
                                       ws.pose.template segment<3>(6)).norm();
    } else if constexpr (P >= 6) {
      direction = (ws.pose.template segment<3>(3) - ws.target.template segment<3>(3)).norm();
    }
  };
  Square A;  // J^T J (lower triangle, with the tiny Levenberg term) of the last Jacobian
  bool damping = false;  // the steps are damped ones (the second pass)
  bool damped_factored = false;  // damped_ldlt holds A + lambda D of this Jacobian
  auto factorise = [&]() {
    J.template topRows<3>() = ws.jacobian.template topRows<3>();
    if constexpr (O) {
      for (int i = 0; i < n; ++i) {
        const Eigen::Vector3d jz = ws.jacobian.col(i).template segment<3>(3);
        const Eigen::Vector3d jx = ws.jacobian.col(i).template segment<3>(6);
        J.col(i).template tail<3>() = weight * orientation_residual(target_z, target_y, jz, jx);
      }
    } else if constexpr (kDirection) {
      J.template bottomRows<3>() = weight * ws.jacobian.template middleRows<3>(3);
    }
    damped_factored = false;
    if (damping) return true;  // a damped step factorises its own matrix
    for (int j = 0; j < n; ++j) {
      for (int i = j; i < n; ++i) A(i, j) = J.col(i).dot(J.col(j));
    }
    // A tiny Levenberg term keeps the step defined where an axis has no effect.
    ws.levenberg = 1e-14 * (1.0 + A.diagonal().maxCoeff());
    A.diagonal().array() += ws.levenberg;
    return ws.factor.compute(A);
  };
  // A damped step: the correction d minimising |P (J (d - (q - c)) + r)|^2 + lambda d^T D d of
  // the model linearised at q (above), lambda kept for the pass. P weights the point rows by
  // up to kPointPriority where the axes can hold the whole pose: the damping gives up the
  // direction (orientation) before the point. (There the undamped answer is the same with
  // or without P, so the correction stays continuous as lambda leaves 0.)
  constexpr bool kPrioritised = kDirection && n >= dof;
  Eigen::Matrix<double, rows, 1> priority = Eigen::Matrix<double, rows, 1>::Ones();  // set with lambda
  Axes dw;  // the diagonal of D: 1 / bound^2 (the correction's bound-scaled norm)
  for (int i = 0; i < n; ++i) dw[i] = inv_bound[i] * inv_bound[i];
  Eigen::Matrix<double, rows, n> Jp;  // P J
  SmallLdlt<n> damped_ldlt;
  double lambda = 0;
  auto damped_correction = [&](const Axes& q, const Eigen::Matrix<double, rows, 1>& r, Axes& d) {
    if (!damped_factored) {
      Jp = priority.asDiagonal() * J;
      Square damped;
      for (int j = 0; j < n; ++j) {
        for (int i = j; i < n; ++i) damped(i, j) = Jp.col(i).dot(Jp.col(j));
      }
      const double levenberg = 1e-14 * (1.0 + damped.diagonal().maxCoeff());
      damped.diagonal() += (lambda * dw.array() + levenberg).matrix();
      if (!damped_ldlt.compute(damped)) return false;
      damped_factored = true;
    }
    const Axes g = Jp.transpose() * (Jp * (q - command) - priority.cwiseProduct(r));
    d = damped_ldlt.solve(Eigen::Matrix<double, n, 1>(g));
    return true;
  };
  // The command's own error (the objective before) from the pose there: cold, the Jacobian's.
  Axes q = command;
  if (start != nullptr) {
    pose_at_command();
    pose_error(out.before_point, out.before_direction);
    q = *start;
    pose_at(q);
  } else {
    jacobian_at(command, ws.command_trig);
    pose_error(out.before_point, out.before_direction);
    if (!factorise()) return Status::kSingular;
  }
  Eigen::Matrix<double, rows, 1> r;
  // Within tolerance: the point, and the direction where it is being corrected.
  auto converged = [&](const Eigen::Matrix<double, rows, 1>& v, double fraction) {
    const double point = fraction * kPointTolerance;
    bool ok = v.template head<3>().squaredNorm() <= point * point;
    if constexpr (kDirection) {
      const double direction = fraction * kDirectionTolerance * weight;
      ok = ok && v.template tail<3>().squaredNorm() <= direction * direction;
    }
    return ok;
  };
  auto set_residual = [&]() {
    r.template head<3>() = ws.pose.template head<3>() - ws.target.template head<3>();
    if constexpr (O) {
      r.template tail<3>() = weight * orientation_residual(target_z, target_y, ws.pose.template segment<3>(3),
                                                                      ws.pose.template segment<3>(6));
    } else if constexpr (kDirection) {
      r.template tail<3>() = weight * (ws.pose.template segment<3>(3) - ws.target.template segment<3>(3));
    }
  };
  bool clamped = false;  // an axis was held at its bound
  // (a tenth of the smaller tolerance in weighted units: equal, 1e-7, at the default weight)^2
  const double kSettled = 0.1 * std::min(kPointTolerance, kDirectionTolerance * weight);
  const double kSettledChange = kSettled * kSettled;
  bool settled = false;  // the last pass ended within tolerance or on a step too small to matter
  // One pass of steps from q (ws.pose at q, a factorisation in ws.factor or from the
  // command), undamped or with `lambda`; kOk, or the failure.
  auto run = [&]() {
    double last_move = std::numeric_limits<double>::infinity();  // the last step's largest axis move, as a fraction of its bound
    bool slow = false;  // the chord gained less than a digit on the last step
    settled = false;
    for (int step = 0;; ++step) {
      set_residual();
      if (converged(r, 1.0)) settled = true;
      if (settled || step == kMaxSteps) break;
      if (slow) {  // not converged yet: a fresh Jacobian for the next step
        jacobian_at(q, trig_at(q));
        if (!factorise()) return Status::kSingular;
        set_residual();
      }
      // The step to the next iterate, q - delta.
      Axes delta;
      double step_change = 0;  // |J delta|^2, undamped
      if (damping) {
        Axes d;
        if (!damped_correction(q, r, d)) return Status::kSingular;
        delta = (q - command) - d;
      } else {
        // More axes than conditions: the Levenberg term's pull, (A + l I)^-1 l (q - c), removes
        // the correction's part along the Jacobian's null space, so that the iteration ends
        // on the correction closest to the command whatever it starts from.
        Axes g = J.transpose() * r;
        if constexpr (kPull) g += ws.levenberg * (q - command);
        delta = ws.factor.solve(g);
        // |J delta|^2 from (J^T J + l I) delta = g, without forming J delta
        step_change = delta.dot(g) - ws.levenberg * delta.squaredNorm();
      }
      // A step that would move the pose by less than a tenth of the tolerance: what is left
      // cannot be corrected (fewer correctable DOF than errors, or a damped singular pose).
      // (Undamped: the pose's whole change, within a tenth of either tolerance.)
      if (damping ? converged((J * delta).eval(), 0.1) : step_change <= kSettledChange) {
        settled = true;
        break;
      }
      bool held = false;
      for (int i = 0; i < n; ++i) {
        // Every correction within its bound per axis (a trust region near singular poses).
        const double wanted = q[i] - delta[i];
        q[i] = std::clamp(wanted, lowest[i], highest[i]);
        held = held || q[i] != wanted;
      }
      const double move = delta.cwiseAbs().cwiseProduct(inv_bound).maxCoeff();
      clamped = clamped || held;
      // Held at a bound undamped: h = 1 whatever the pass would do next, and the damped pass
      // starts from the command, so the rest of this pass is not needed.
      if (!damping && clamped) return Status::kOk;
      // A fresh Jacobian after a large step.
      const bool refresh = held || move > kChordStepLimit;
      slow = !refresh && move > 0.1 * last_move;
      last_move = move;
      if (refresh) {
        jacobian_at(q, trig_at(q));
        if (!factorise()) return Status::kSingular;
      } else {
        pose_at(q);
      }
    }
    return Status::kOk;
  };
  Status failed = run();
  if (failed != Status::kOk) return failed;
  // An axis of the undamped correction beyond kDampingStart of its bound (or held at it):
  // near a singular pose. Then a damped pass, lambda from how far beyond (h above).
  double largest = 0;  // of the undamped correction's axes, as fractions of their bounds
  for (int i = 0; i < n; ++i) largest = std::max(largest, std::abs(q[i] - command[i]) * inv_bound[i]);
  const double x = (largest - kDampingStart) * (1.0 / (1.0 - kDampingStart));
  const double h = clamped ? 1.0 : !(x > 0) ? 0.0 : x >= 1 ? 1.0 : x * x * (3 - 2 * x);
  const bool damped = h > 0;
  if (damped) {
    // lambda from the residual at the command. The pass starts from the undamped correction
    // scaled by 1 - h: where lambda is small it barely moves from there (continuous as h
    // leaves 0), and from the command where the undamped one lies far off (at a bound).
    const Axes undamped = q;
    pose_at_command();
    set_residual();
    lambda = h * r.squaredNorm() * (0.25 / (kTrustRadius * kTrustRadius));
    // the point's priority grows with h too (the Levenberg term scales with it)
    if (kPrioritised) priority.template head<3>().setConstant(1 + (kPointPriority - 1) * std::sqrt(h));
    q = command + (1 - h) * (undamped - command);
    clamped = false;
    damping = true;
    jacobian_at(q, trig_at(q));
    if (!factorise()) return Status::kSingular;
    failed = run();
    if (failed != Status::kOk) return failed;
  }
  if (!q.allFinite() || !r.allFinite()) return Status::kNonFiniteOutput;
  out.corrected = q;
  pose_error(out.residual_point, out.residual_direction);
  const bool ok = out.residual_point <= kPointTolerance && out.residual_direction <= kDirectionTolerance;
  clean = !damped && !clamped;
  if (ok) return Status::kOk;
  // Never worse than no correction, by the objective the steps minimise: where the command
  // itself scores no worse, it is the answer.
  const double none_point = out.before_point, none_direction = out.before_direction;
  if (std::isfinite(none_point) && std::isfinite(none_direction) &&
      objective(none_point, none_direction, weight) <= objective(out.residual_point, out.residual_direction, weight)) {
    out.corrected = command;
    out.residual_point = none_point;
    out.residual_direction = none_direction;
    clean = false;
  }
  return Status::kResidual;
}

template <int N, unsigned Angles, int P, int R, bool O>
Status Core<N, Angles, P, R, O>::compensate(const Machine& m, State& ws, const Axes& command, Result& out,
                                             double direction_weight) noexcept {
  const double weight = valid_direction_weight(direction_weight);
  // Warm: the same model, near the last command, within the correction bound of where the
  // factorised Jacobian was taken (the chord still gains about two digits per step), and the
  // last correction extrapolated linearly (the start) within kWarmCorrectionLimit of the
  // bound. A command holding NaN fails these tests and is refused by solve().
  Axes start;
  // (and the same weight: the factorisation was taken with it)
  bool warm = ws.warm && ws.warm_model == m.identity && ws.warm_weight == weight &&
              within_bounds<N, Angles>(command, ws.last_command, kChordStepLimit) &&
              within_bounds<N, Angles>(command, ws.jacobian_axes);
  if (warm) {
    start = command + (ws.last_corrected - ws.last_command) + ws.last_correction_change;
    warm = within_bounds<N, Angles>(start, command, kWarmCorrectionLimit);
  }
  ws.warm = false;
  bool clean = false;
  Status s = solve(m, ws, command, warm ? &start : nullptr, out, clean, weight);
  // A warm start that ends short of the tolerance is redone cold: a residual (fewer DOF than
  // errors, a singular pose) or a failure never depends on the commands before.
  const bool warm_result = warm && s == Status::kOk;
  if (warm && !warm_result) s = solve(m, ws, command, nullptr, out, clean, weight);
  // The next call may start warm from a unique solution (none where a residual is left: the
  // chord's fixed point there depends on where its Jacobian was taken) of the whole problem.
  if (s != Status::kOk || !clean) return s;
  ws.warm = true;
  ws.warm_model = m.identity;
  ws.warm_weight = weight;
  if (warm_result) {
    ws.last_correction_change = (out.corrected - command) - (ws.last_corrected - ws.last_command);
  } else {
    ws.last_correction_change.setZero();
  }
  ws.last_command = command;
  ws.last_corrected = out.corrected;
  return s;
}

// ---- A generated model on the solver (K: its Kinematics: sizes, Model, pose functions) ----

// The number of linear axes.
template <class K>
constexpr int kLinearAxes() noexcept {
  int count = 0;
  for (int i = 0; i < K::kNumAxes; ++i) count += K::kAxisIsAngle[i] ? 0 : 1;
  return count;
}

// With a tool frame (Pose: point, direction z, the frame's x axis) and at least three rotary
// axes, the orientation is corrected in full: rows 3..5 are then the rotation-vector
// residual, not the change of the direction.
template <class K>
constexpr bool kCorrectsOrientation() noexcept {
  return K::Pose::RowsAtCompileTime == 9 && K::kCorrectsDirection && K::kNumAxes - kLinearAxes<K>() >= 3;
}

// The solver of K's shape.
template <class K>
using CoreOf = Core<K::kNumAxes, angle_mask<K>(), K::Pose::RowsAtCompileTime, K::kCorrectsDirection ? 6 : 3, kCorrectsOrientation<K>()>;

template <class K>
using Result = typename CoreOf<K>::Result;

// The solver's state and, with varying errors, the model with their values at the current
// axes, the error gain matrix, and per varying error its table interval and slope there.
template <class K>
struct Workspace {
  typename CoreOf<K>::State core;
  typename K::Model model;
  typename K::Gain gain;
  int hint[kMaxVaryingErrors];
  double slope[kMaxVaryingErrors];
  double values[K::kNumParams];  // the varying errors' values; NaN for the others
};

// K's pose functions as the solver calls them; varying errors evaluated at every q (and
// their slopes entering the Jacobian).
template <class K>
struct ModelCalls {
  using C = CoreOf<K>;
  struct Context {
    const typename K::Model* model;
    Workspace<K>* ws;
  };
  static void pose_nominal(void* context, const typename C::Axes& q, const typename C::Trig& t,
                           typename C::Pose& out) noexcept {
    K::pose_nominal(*static_cast<Context*>(context)->model, q, t, out);
  }
  static void pose_exact(void* context, const typename C::Axes& q, const typename C::Trig& t,
                         typename C::Pose& out) noexcept {
    K::pose_exact(*static_cast<Context*>(context)->model, q, t, out);
  }
  static void pose_jacobian(void* context, const typename C::Axes& q, const typename C::Trig& t,
                            typename C::Pose& out, typename C::Jacobian& J) noexcept {
    K::pose_jacobian(*static_cast<Context*>(context)->model, q, t, out, J);
  }
  // With varying errors:
  static void pose_exact_varying(void* context, const typename C::Axes& q, const typename C::Trig& t,
                                 typename C::Pose& out) noexcept {
    const Context& c = *static_cast<Context*>(context);
    // Newton iterates that step past the end of a rejecting table by the correction are
    // evaluated held there.
    Workspace<K>& ws = *c.ws;
    set_varying<K, false>(*c.model->varying, ws.model, q, ws.hint, ws.slope, ws.values);
    K::pose_exact(ws.model, q, t, out);
  }
  static void pose_jacobian_varying(void* context, const typename C::Axes& q, const typename C::Trig& t,
                                    typename C::Pose& out, typename C::Jacobian& J) noexcept {
    const Context& c = *static_cast<Context*>(context);
    Workspace<K>& ws = *c.ws;
    set_varying<K>(*c.model->varying, ws.model, q, ws.hint, ws.slope, ws.values);
    K::pose_jacobian_gain(ws.model, q, t, out, J, ws.gain);
    add_slopes<K>(*c.model->varying, ws.gain, ws.slope, J);
  }
};

// Corrected axis commands such that the actual tool pose equals the nominal one at `command`
// (the file's first lines); warm from the last call on `ws` where the rules in Core allow.
// `direction_weight` (mm per rad): the objective's weight of the direction (orientation).
template <class K>
Status compensate(const typename K::Model& model, Workspace<K>& ws, const typename K::Axes& command,
                  Result<K>& out, double direction_weight = kDefaultDirectionWeight) noexcept {
  using C = CoreOf<K>;
  const VaryingErrors* varying = model.varying;
  if (varying != nullptr && command.allFinite()) {
    if (!within_ranges(*varying, command.data())) {
      ws.core.warm = false;
      out.corrected = command;
      out.residual_point = out.residual_direction = out.before_point = out.before_direction = 0;
      return Status::kOutsideTable;
    }
    ws.model = model;
    for (int i = 0; i < varying->count; ++i) ws.hint[i] = -1;
    clear_values<K>(ws.values);
  }
  typename ModelCalls<K>::Context context{&model, &ws};
  using Calls = ModelCalls<K>;
  const typename C::Machine machine{&model, &context, &Calls::pose_nominal,
                                    varying ? &Calls::pose_exact_varying : &Calls::pose_exact,
                                    varying ? &Calls::pose_jacobian_varying : &Calls::pose_jacobian};
  return C::compensate(machine, ws.core, command, out, direction_weight);
}

}  // namespace chaincomp
