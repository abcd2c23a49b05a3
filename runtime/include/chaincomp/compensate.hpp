// Compensation: corrected axis commands such that the actual tool point (and tool
// direction, where the machine's rotary axes can correct it) equals the nominal one at the
// commanded axes. A fixed number of Gauss-Newton steps on the generated exact Jacobian:
// constant cost per call, no heap, no exceptions. Errors that vary along an axis (tables,
// polynomials: varying.hpp) are evaluated at the command and at every Newton iterate, and
// their slopes enter the Jacobian.
#pragma once

#include <Eigen/Core>
#include <Eigen/Cholesky>
#include <algorithm>
#include <cmath>
#include <limits>

#include "chaincomp/varying.hpp"

namespace chaincomp {

// Status codes of compensate(); the README lists them.
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

constexpr int kNewtonSteps = 2;
constexpr double kPointTolerance = 1e-7;      // mm: 0.1 nm
constexpr double kDirectionTolerance = 1e-9;  // rad
constexpr double kDirectionWeight = 100.0;    // mm per rad: a direction error counts as at 100 mm
// Largest correction compensate() will make, per axis kind: geometric errors need µm and
// arcsec; more means a singular configuration (e.g. the tool axis along the C axis), where
// the correction is bounded and the rest reported as residual.
constexpr double kMaxLinearCorrection = 1.0;      // mm
constexpr double kMaxAngularCorrection = 0.0175;  // rad, about 1 degree
constexpr int kMaxExtraSteps = 4;  // steps a call near a singular pose may add
constexpr double kConvergedStep = 1e-3;  // a last step above this fraction of the bound (1 µm, 3.6 arcsec): not converged yet
// A step larger than this fraction of the bound refreshes the Jacobian.
constexpr double kChordStepLimit = 0.05;

template <class K>
struct Result {
  typename K::Axes corrected;
  double residual_point = 0;      // mm
  double residual_direction = 0;  // rad (0 where the direction is not corrected)
};

template <class K>
struct Workspace {
  typename K::Pose target, pose;
  typename K::Jacobian jacobian;
  // With varying errors: the model with their values at the current axes, the error gain
  // matrix, and per varying error its table interval and slope at the current axes.
  typename K::Model model;
  typename K::Gain gain;
  int hint[kMaxVaryingErrors];
  double slope[kMaxVaryingErrors];
  double values[K::kNumParams];  // the varying errors' values; NaN for the others
};

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
  constexpr int rows = K::Jacobian::RowsAtCompileTime;
  for (int i = 0; i < v.count; ++i) {
    const VaryingError& e = v.items[i];
    double* col = J.data() + rows * e.axis;  // column-major, fixed size
    const double* g = gain.data() + rows * e.column;
    for (int r = 0; r < rows; ++r) col[r] += slope[i] * g[r];
  }
}

// The model to evaluate at `q`: `m` itself without varying errors, else `scratch` holding
// them at `q` (slopes into `slope`); nullptr where `q` lies outside a range that rejects.
template <class K>
const typename K::Model* model_at(const typename K::Model& m, const typename K::Axes& q,
                                  typename K::Model& scratch, double* slope) noexcept {
  if (m.varying == nullptr) return &m;
  scratch = m;
  double values[K::kNumParams];
  clear_values<K>(values);
  return set_varying<K>(*m.varying, scratch, q, nullptr, slope, values) ? &scratch : nullptr;
}

// K: the generated Kinematics of one machine (sizes, Model, pose_nominal, pose_jacobian).
// The number of linear axes.
template <class K>
constexpr int kLinearAxes() noexcept {
  int count = 0;
  for (int i = 0; i < K::kNumAxes; ++i) count += K::kAxisIsAngle[i] ? 0 : 1;
  return count;
}

// The residual with its direction rows zeroed.
template <class K, int Rows>
Eigen::Matrix<double, Rows, 1> point_rows(const Eigen::Matrix<double, Rows, 1>& r) noexcept {
  Eigen::Matrix<double, Rows, 1> out = r;
  out.template tail<Rows - 3>().setZero();
  return out;
}

// Whether every axis of q lies within its correction bound around the command.
template <class K>
bool within_bounds(const typename K::Axes& q, const typename K::Axes& command) noexcept {
  for (int i = 0; i < K::kNumAxes; ++i) {
    const double bound = K::kAxisIsAngle[i] ? kMaxAngularCorrection : kMaxLinearCorrection;
    if (std::abs(q[i] - command[i]) > bound) return false;
  }
  return true;
}

template <class K>
Status compensate(const typename K::Model& model, Workspace<K>& ws, const typename K::Axes& command,
                  Result<K>& out) noexcept {
  constexpr int n = K::kNumAxes;
  constexpr int rows = K::kCorrectsDirection ? 6 : 3;
  out.corrected = command;
  out.residual_point = out.residual_direction = 0;
  if (!command.allFinite()) return Status::kNonFiniteInput;
  const VaryingErrors* varying = model.varying;
  if (varying != nullptr) {
    if (!within_ranges(*varying, command.data())) return Status::kOutsideTable;
    ws.model = model;
    for (int i = 0; i < varying->count; ++i) ws.hint[i] = -1;
    clear_values<K>(ws.values);
  }
  // The actual pose (and its Jacobian) at q, varying errors evaluated at q. Newton iterates
  // that step past the end of a rejecting table by the correction are evaluated held there.
  auto pose_at = [&](const typename K::Axes& q) {
    if (varying == nullptr) {
      K::pose_exact(model, q, ws.pose);
    } else {
      set_varying<K, false>(*varying, ws.model, q, ws.hint, ws.slope, ws.values);
      K::pose_exact(ws.model, q, ws.pose);
    }
  };
  auto jacobian_at = [&](const typename K::Axes& q) {
    if (varying == nullptr) {
      K::pose_jacobian(model, q, ws.pose, ws.jacobian);
    } else {
      set_varying<K>(*varying, ws.model, q, ws.hint, ws.slope, ws.values);
      K::pose_jacobian_gain(ws.model, q, ws.pose, ws.jacobian, ws.gain);
      add_slopes<K>(*varying, ws.gain, ws.slope, ws.jacobian);
    }
  };

  K::pose_nominal(model, command, ws.target);
  // Chord Newton: the Jacobian at the command serves the following steps as long as they
  // stay small (µm, arcsec: it then differs from the one at the solution by ~1e-4 relative,
  // so each step gains about four digits) and one factorisation per call keeps the cost low.
  // A large step (near a singular pose) takes a fresh Jacobian: the cost stays bounded.
  Eigen::Matrix<double, rows, n> J;
  Eigen::LLT<Eigen::Matrix<double, n, n>> llt;
  bool at_bound[n] = {};  // axes whose correction reached its bound stay there
  // Near a singular pose (the tool along a rotary axis) the direction cannot be corrected
  // within the trust region: the point alone is corrected then, by the linear axes where
  // the machine has three, and the direction error is reported.
  bool point_only = false;
  auto factorise = [&]() {
    J.template topRows<3>() = ws.jacobian.template topRows<3>();
    if constexpr (K::kCorrectsDirection) {
      J.template bottomRows<3>() = kDirectionWeight * ws.jacobian.template bottomRows<3>();
      if (point_only) J.template bottomRows<3>().setZero();
    }
    for (int i = 0; i < n; ++i) {
      if (at_bound[i] || (point_only && K::kAxisIsAngle[i] && kLinearAxes<K>() >= 3)) J.col(i).setZero();
    }
    Eigen::Matrix<double, n, n> A = J.transpose() * J;
    // A tiny Levenberg term keeps the step defined where an axis has no effect.
    A.diagonal().array() += 1e-14 * (1.0 + A.diagonal().maxCoeff());
    llt.compute(A);
    return llt.info() == Eigen::Success;
  };
  jacobian_at(command);
  if (!factorise()) return Status::kSingular;

  typename K::Axes q = command;
  Eigen::Matrix<double, rows, 1> r;
  // An axis reaching its bound costs one more step (at most n): the cost stays bounded.
  int steps = kNewtonSteps;
  double last_step = 0;  // the last step's largest axis move, as a fraction of its bound
  for (int step = 0;; ++step) {
    r.template head<3>() = ws.pose.template head<3>() - ws.target.template head<3>();
    if constexpr (K::kCorrectsDirection) {
      r.template tail<3>() = kDirectionWeight * (ws.pose.template tail<3>() - ws.target.template tail<3>());
    }
    // Near a singular pose the steps are large and the chord converges slowly: a few more
    // steps (bounded, so the worst-case cost is known) until the point is corrected.
    if (step == steps && steps < kNewtonSteps + kMaxExtraSteps && last_step > kConvergedStep) ++steps;
    if (step == steps) break;
    typename K::Axes delta = llt.solve(J.transpose() * (point_only ? point_rows<K, rows>(r) : r));
    if (K::kCorrectsDirection && !point_only && !within_bounds<K>(q - delta, command)) {
      point_only = true;  // one more step for the switch: the cost stays bounded
      ++steps;
      if (!factorise()) return Status::kSingular;
      delta = llt.solve(J.transpose() * point_rows<K, rows>(r));
    }
    bool large = false;
    last_step = 0;
    for (int i = 0; i < n; ++i) {
      // Keep the total correction within its bound per axis (a trust region near singular
      // poses); an axis that reaches it is held there and the others correct what they can.
      const double bound = K::kAxisIsAngle[i] ? kMaxAngularCorrection : kMaxLinearCorrection;
      const double wanted = q[i] - delta[i];
      q[i] = std::clamp(wanted, command[i] - bound, command[i] + bound);
      if (q[i] != wanted && !at_bound[i]) {
        at_bound[i] = true;
        ++steps;
      }
      large = large || q[i] != wanted || std::abs(delta[i]) > kChordStepLimit * bound;
      last_step = std::max(last_step, std::abs(delta[i]) / bound);
    }
    if (large) {
      jacobian_at(q);
      if (!factorise()) return Status::kSingular;
    } else {
      pose_at(q);
    }
  }
  if (!q.allFinite() || !r.allFinite()) return Status::kNonFiniteOutput;
  out.corrected = q;
  out.residual_point = r.template head<3>().norm();
  if constexpr (K::kCorrectsDirection) {
    out.residual_direction = r.template tail<3>().norm() / kDirectionWeight;
  }
  const bool ok = out.residual_point <= kPointTolerance && out.residual_direction <= kDirectionTolerance;
  return ok ? Status::kOk : Status::kResidual;
}

}  // namespace chaincomp
