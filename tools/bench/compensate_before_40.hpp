// compensate.hpp's solver as it was before the never-worse rule of issue #40 (git show
// e22529c^:runtime/include/chaincomp/compensate.hpp: Core, solve, compensate and the
// wrappers for a generated model), for tools/bench_codegen's side-by-side timing only
// (issue #40's acceptance: compensate's median on five_axis_ac within 1.2x of this). The
// helpers that did not change (sin and cos, varying errors, SmallLdlt, bounds) are
// chaincomp's own; nothing else uses this file.
#pragma once

#include "chaincomp/compensate.hpp"

namespace chaincomp_before40 {

using namespace chaincomp;  // the unchanged helpers; the names below hide chaincomp's

constexpr double kDirectionWeight = 100.0;  // then compiled in

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
    double residual_direction = 0;  // rad: the direction (with a frame: orientation) residual; 0 where not corrected
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
    Trig command_trig, trig;  // at the command, at the current axes
  };

  // The warm start's rules, then solve(); see compensate<K> below.
  static Status compensate(const Machine& m, State& ws, const Axes& command, Result& out) noexcept;
  // One compensation from `start` (a warm start: the factorisation in ws is used) or, where
  // null, cold from the command. `clean`: the call ended undamped with every axis within
  // its bound.
  static Status solve(const Machine& m, State& ws, const Axes& command, const Axes* start, Result& out,
                      bool& clean) noexcept;
};

// Gauss-Newton (chord) steps on |W r(q)|^2 (W the row weights: the direction or orientation
// rows as at kDirectionWeight mm per rad); near a singular pose a second, damped pass
// (kTrustRadius above). Where the Jacobian has a null space (a seven-joint arm; a six-joint
// arm holding point and direction, which leaves the turn about the tool axis free) every
// step removes the correction's part along it: of all corrections equally good, the one of
// least bound-scaled norm, i.e. the one closest to the command, whatever the iteration
// starts from (the null-space rule).
template <int N, unsigned Angles, int P, int R, bool O>
Status Core<N, Angles, P, R, O>::solve(const Machine& m, State& ws, const Axes& command, const Axes* start, Result& out,
                               bool& clean) noexcept {
  constexpr int n = N;
  constexpr int rows = R;
  constexpr bool kDirection = R == 6;  // the direction (or orientation) rows are corrected
  using Square = Eigen::Matrix<double, n, n>;
  // More axes than the conditions they are to meet (a seven-joint arm; a six-joint arm holding
  // point and direction only): a set of equally good corrections.
  constexpr int dof = O ? 6 : kDirection ? 5 : 3;
  constexpr bool kRedundant = n > dof;
  clean = false;
  out.corrected = command;
  out.residual_point = out.residual_direction = 0;
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
  Square A;  // J^T J (lower triangle, with the tiny Levenberg term) of the last Jacobian
  bool damping = false;  // the steps are damped ones (the second pass)
  bool damped_factored = false;  // damped_ldlt holds A + lambda D of this Jacobian
  auto factorise = [&]() {
    J.template topRows<3>() = ws.jacobian.template topRows<3>();
    if constexpr (O) {
      for (int i = 0; i < n; ++i) {
        const Eigen::Vector3d jz = ws.jacobian.col(i).template segment<3>(3);
        const Eigen::Vector3d jx = ws.jacobian.col(i).template segment<3>(6);
        J.col(i).template tail<3>() = kDirectionWeight * orientation_residual(target_z, target_y, jz, jx);
      }
    } else if constexpr (kDirection) {
      J.template bottomRows<3>() = kDirectionWeight * ws.jacobian.template middleRows<3>(3);
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
  Axes q = command;
  if (start != nullptr) {
    q = *start;
    pose_at(q);
  } else {
    jacobian_at(command, ws.command_trig);
    if (!factorise()) return Status::kSingular;
  }
  Eigen::Matrix<double, rows, 1> r;
  // Within tolerance: the point, and the direction where it is being corrected.
  auto converged = [&](const Eigen::Matrix<double, rows, 1>& v, double fraction) {
    const double point = fraction * kPointTolerance;
    bool ok = v.template head<3>().squaredNorm() <= point * point;
    if constexpr (kDirection) {
      const double direction = fraction * kDirectionTolerance * kDirectionWeight;
      ok = ok && v.template tail<3>().squaredNorm() <= direction * direction;
    }
    return ok;
  };
  auto set_residual = [&]() {
    r.template head<3>() = ws.pose.template head<3>() - ws.target.template head<3>();
    if constexpr (O) {
      r.template tail<3>() = kDirectionWeight * orientation_residual(target_z, target_y, ws.pose.template segment<3>(3),
                                                                      ws.pose.template segment<3>(6));
    } else if constexpr (kDirection) {
      r.template tail<3>() = kDirectionWeight * (ws.pose.template segment<3>(3) - ws.target.template segment<3>(3));
    }
  };
  bool clamped = false;  // an axis was held at its bound
  // (a tenth of the smaller tolerance in weighted units: they are equal, 1e-7)^2
  constexpr double kSettled = 0.1 * std::min(kPointTolerance, kDirectionTolerance * kDirectionWeight);
  constexpr double kSettledChange = kSettled * kSettled;
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
        if constexpr (kRedundant) g += ws.levenberg * (q - command);
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
  out.residual_point = r.template head<3>().norm();
  if constexpr (kDirection) {
    out.residual_direction = r.template tail<3>().norm() / kDirectionWeight;
  }
  const bool ok = out.residual_point <= kPointTolerance && out.residual_direction <= kDirectionTolerance;
  clean = !damped && !clamped;
  return ok ? Status::kOk : Status::kResidual;
}

template <int N, unsigned Angles, int P, int R, bool O>
Status Core<N, Angles, P, R, O>::compensate(const Machine& m, State& ws, const Axes& command, Result& out) noexcept {
  // Warm: the same model, near the last command, within the correction bound of where the
  // factorised Jacobian was taken (the chord still gains about two digits per step), and the
  // last correction extrapolated linearly (the start) within kWarmCorrectionLimit of the
  // bound. A command holding NaN fails these tests and is refused by solve().
  Axes start;
  bool warm = ws.warm && ws.warm_model == m.identity &&
              within_bounds<N, Angles>(command, ws.last_command, kChordStepLimit) &&
              within_bounds<N, Angles>(command, ws.jacobian_axes);
  if (warm) {
    start = command + (ws.last_corrected - ws.last_command) + ws.last_correction_change;
    warm = within_bounds<N, Angles>(start, command, kWarmCorrectionLimit);
  }
  ws.warm = false;
  bool clean = false;
  Status s = solve(m, ws, command, warm ? &start : nullptr, out, clean);
  // A warm start that ends short of the tolerance is redone cold: a residual (fewer DOF than
  // errors, a singular pose) or a failure never depends on the commands before.
  const bool warm_result = warm && s == Status::kOk;
  if (warm && !warm_result) s = solve(m, ws, command, nullptr, out, clean);
  // The next call may start warm from a unique solution (none where a residual is left: the
  // chord's fixed point there depends on where its Jacobian was taken) of the whole problem.
  if (s != Status::kOk || !clean) return s;
  ws.warm = true;
  ws.warm_model = m.identity;
  if (warm_result) {
    ws.last_correction_change = (out.corrected - command) - (ws.last_corrected - ws.last_command);
  } else {
    ws.last_correction_change.setZero();
  }
  ws.last_command = command;
  ws.last_corrected = out.corrected;
  return s;
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
template <class K>
Status compensate(const typename K::Model& model, Workspace<K>& ws, const typename K::Axes& command,
                  Result<K>& out) noexcept {
  using C = CoreOf<K>;
  const VaryingErrors* varying = model.varying;
  if (varying != nullptr && command.allFinite()) {
    if (!within_ranges(*varying, command.data())) {
      ws.core.warm = false;
      out.corrected = command;
      out.residual_point = out.residual_direction = 0;
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
  return C::compensate(machine, ws.core, command, out);
}

}  // namespace chaincomp_before40
