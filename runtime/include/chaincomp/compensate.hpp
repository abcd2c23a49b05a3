// Compensation: corrected axis commands such that the actual tool point (and tool
// direction, where the machine's rotary axes can correct it) equals the nominal one at the
// commanded axes. A fixed number of Gauss-Newton steps on the generated exact Jacobian:
// constant cost per call, no heap, no exceptions.
#pragma once

#include <Eigen/Core>
#include <Eigen/Cholesky>
#include <algorithm>
#include <cmath>

namespace chaincomp {

// Status codes of compensate(); the README lists them.
enum class Status : int {
  kOk = 0,             // corrected: residual within tolerance
  kResidual = 1,       // best correction found, but a residual remains (fewer DOF than errors)
  kNonFiniteInput = 2, // the command holds NaN or Inf: nothing computed, output = command
  kSingular = 3,       // the Jacobian is singular at the command: output = command
  kNonFiniteOutput = 4 // the iteration produced NaN or Inf: output = command
};

inline const char* status_name(Status s) noexcept {
  switch (s) {
    case Status::kOk: return "ok";
    case Status::kResidual: return "residual";
    case Status::kNonFiniteInput: return "non_finite_input";
    case Status::kSingular: return "singular";
    case Status::kNonFiniteOutput: return "non_finite_output";
  }
  return "unknown";
}

constexpr int kNewtonSteps = 3;
constexpr double kPointTolerance = 1e-7;      // mm: 0.1 nm
constexpr double kDirectionTolerance = 1e-9;  // rad
constexpr double kDirectionWeight = 100.0;    // mm per rad: a direction error counts as at 100 mm
// Largest correction compensate() will make, per axis kind: geometric errors need µm and
// arcsec; more means a singular configuration (e.g. the tool axis along the C axis), where
// the correction is bounded and the rest reported as residual.
constexpr double kMaxLinearCorrection = 1.0;      // mm
constexpr double kMaxAngularCorrection = 0.0175;  // rad, about 1 degree

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
};

// K: the generated Kinematics of one machine (sizes, Model, pose_nominal, pose_jacobian).
template <class K>
Status compensate(const typename K::Model& model, Workspace<K>& ws, const typename K::Axes& command,
                  Result<K>& out) noexcept {
  constexpr int n = K::kNumAxes;
  constexpr int rows = K::kCorrectsDirection ? 6 : 3;
  out.corrected = command;
  out.residual_point = out.residual_direction = 0;
  if (!command.allFinite()) return Status::kNonFiniteInput;

  K::pose_nominal(model, command, ws.target);
  typename K::Axes q = command;
  Eigen::Matrix<double, rows, 1> r;
  Eigen::Matrix<double, rows, n> J;
  for (int step = 0; step <= kNewtonSteps; ++step) {
    K::pose_jacobian(model, q, ws.pose, ws.jacobian);
    r.template head<3>() = ws.pose.template head<3>() - ws.target.template head<3>();
    J.template topRows<3>() = ws.jacobian.template topRows<3>();
    if constexpr (K::kCorrectsDirection) {
      r.template tail<3>() = kDirectionWeight * (ws.pose.template tail<3>() - ws.target.template tail<3>());
      J.template bottomRows<3>() = kDirectionWeight * ws.jacobian.template bottomRows<3>();
    }
    if (step == kNewtonSteps) break;
    Eigen::Matrix<double, n, n> A = J.transpose() * J;
    // A tiny Levenberg term keeps the step defined where an axis has no effect.
    A.diagonal().array() += 1e-14 * (1.0 + A.diagonal().maxCoeff());
    Eigen::LLT<Eigen::Matrix<double, n, n>> llt(A);
    if (llt.info() != Eigen::Success) return Status::kSingular;
    q -= llt.solve(J.transpose() * r);
    // Keep the total correction within its bound per axis (a trust region near singularities).
    for (int i = 0; i < n; ++i) {
      const double bound = K::kAxisIsAngle[i] ? kMaxAngularCorrection : kMaxLinearCorrection;
      q[i] = std::clamp(q[i], command[i] - bound, command[i] + bound);
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
