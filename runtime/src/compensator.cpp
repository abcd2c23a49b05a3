#include "chaincomp/compensator.hpp"

#include <algorithm>
#include <cmath>
#include <cstdint>

#include "chaincomp/compensate.hpp"

namespace chaincomp {

static_assert(CompensatorConfig{}.direction_weight == kDefaultDirectionWeight, "one default weight");

const char* reject_name(Reject r) noexcept {
  static const char* const kNames[kNumReasons] = {
      "undecodable", "wrong_machine", "wrong_axis_count", "non_finite", "out_of_limits",
      "step_too_large", "duplicate_seq", "out_of_order_seq", "compensation_failed"};
  const int i = static_cast<int>(r);
  return i >= 0 && i < kNumReasons ? kNames[i] : "unknown";
}

Compensator::Compensator(const ModelEntry& entry, const void* model, const CompensatorConfig& config)
    : entry_(entry),
      model_(model),
      config_(config),
      n_(entry.info->num_axes),
      enabled_(config.start_enabled),
      ramp_(config.start_enabled ? 1.0 : 0.0) {
  workspace_ = aligned_slot(workspace_storage_, entry.workspace_size, entry.workspace_align);
  entry.init_workspace(workspace_);
}

bool Compensator::reject(Reject r, Reject* why) noexcept {
  ++counters_.rejected[static_cast<int>(r)];
  if (in_gap_) ++refused_in_gap_;
  in_gap_ = false;
  if (why != nullptr) *why = r;
  return false;
}

bool Compensator::set_direction_weight(double mm) noexcept {
  if (!(mm >= kMinDirectionWeight && mm <= kMaxDirectionWeight)) return false;
  config_.direction_weight = mm;
  return true;
}

void Compensator::reset() noexcept {
  ++counters_.resets;
  order_.reset();
  have_seen_ = false;
  refused_in_gap_ = 0;
}

// Gaps, counted when a command is taken: the seq values between it and the last one taken,
// less the commands refused meanwhile that were ahead of that one (received, not missing: a
// NaN, a spike; a hostile seq refused far ahead, up to kMaxSeqJump, is one of them, so it
// neither skips 2^31 values nor hides the gaps after it). A restart or the first command of
// a stream is no gap.
void Compensator::count_gap(std::int64_t seq, bool restarting) noexcept {
  const std::uint64_t ahead = ahead_by(order_.last(), seq);
  const std::uint64_t refused = static_cast<std::uint64_t>(refused_in_gap_);
  refused_in_gap_ = 0;
  in_gap_ = false;
  if (restarting || !order_.known() || ahead <= 1 + refused) return;
  ++counters_.seq_gaps;
  const auto room = static_cast<std::uint64_t>(INT64_MAX - counters_.seq_missing);
  counters_.seq_missing += static_cast<std::int64_t>(std::min(ahead - 1 - refused, room));
}

// The stream rule (stream_order.hpp) on seq; a command continues a restart run when its utime
// does not go back and each axis steps within max_step from the run's last command.
bool Compensator::seq_ok(const Command& in, const std::array<double, kMaxAxes>& cmd, bool& restarting,
                         Reject* why) noexcept {
  bool continues = in.utime >= run_utime_;
  for (int i = 0; i < n_; ++i) continues = continues && std::abs(cmd[i] - run_axes_[i]) <= config_.axes[i].max_step;
  const StreamOrder::Verdict v = order_.judge(in.seq, continues);
  if (v == StreamOrder::Verdict::kNext) return true;
  const std::array<double, kMaxAxes> before = run_axes_;
  run_utime_ = in.utime;
  run_axes_ = cmd;
  if (v == StreamOrder::Verdict::kSame) return reject(Reject::kDuplicateSeq, why);
  if (v != StreamOrder::Verdict::kRestart) return reject(Reject::kOutOfOrderSeq, why);
  restarting = true;   // counted when the command is taken
  seen_axes_ = before;  // the run's own last step is the one the step check sees
  have_seen_ = true;
  return true;
}

// Point (mm) and direction (rad) error left at `target` (axis units) for the command at q
// (internal units): what a target whose correction was limited or ramped really leaves: the
// direction wherever the pose has one (corrected or not), with a frame corrected in full the
// orientation residual compensate() reports (compensate.hpp).
// Tables that reject beyond their end are held there, as compensate's iterates hold them: a
// target corrected a little past the end (the command inside) is a pose, not NaN.
void Compensator::residual_at(const double* q, const std::array<double, kMaxAxes>& target,
                              double* residual) const noexcept {
  double t[kMaxAxes], actual[9], nominal[9];  // pose_size is 3, 6 or 9
  for (int i = 0; i < n_; ++i) t[i] = target[i] * entry_.info->axes[i].to_internal;
  entry_.pose_exact_held(model_, t, actual);
  entry_.pose_nominal(model_, q, nominal);
  auto distance = [&](int from) {
    double s = 0;
    for (int k = from; k < from + 3; ++k) s += (actual[k] - nominal[k]) * (actual[k] - nominal[k]);
    return std::sqrt(s);
  };
  residual[0] = distance(0);
  residual[1] = 0.0;
  if (entry_.info->pose_size < 6) return;
  if (!entry_.info->corrects_orientation) {
    residual[1] = distance(3);
    return;
  }
  // the residual compensate() measures (compensate.hpp), with yt = zt x xt
  using V = Eigen::Map<const Eigen::Vector3d>;
  const Eigen::Vector3d zt = V(nominal + 3);
  residual[1] = orientation_residual(zt, cross3(zt, V(nominal + 6)), V(actual + 3), V(actual + 6)).norm();
}


bool Compensator::process(const Command& in, Target& out, Reject* why) noexcept {
  ++counters_.received;
  const AxisInfo* info = entry_.info->axes;
  if (in.machine != std::string_view(entry_.info->name)) return reject(Reject::kWrongMachine, why);
  if (in.num_axes != n_) return reject(Reject::kWrongAxisCount, why);
  const std::uint64_t ahead = ahead_by(order_.last(), in.seq);
  in_gap_ = order_.known() && ahead >= 1 && ahead <= kMaxSeqJump;
  std::array<double, kMaxAxes> cmd = in.axes;
  for (int i = 0; i < n_; ++i) {
    if (!std::isfinite(cmd[i])) return reject(Reject::kNonFinite, why);
  }
  int flags = 0;
  for (int i = 0; i < n_; ++i) {
    const AxisLimits& lim = config_.axes[i];
    if (cmd[i] < lim.lower || cmd[i] > lim.upper) {
      if (!config_.clamp_out_of_limits) return reject(Reject::kOutOfLimits, why);
      cmd[i] = std::clamp(cmd[i], lim.lower, lim.upper);
      flags |= kFlagClampedInput;
    }
  }
  bool restarting = false;
  if (!seq_ok(in, cmd, restarting, why)) return false;
  // A jump is measured from the previous valid command, accepted or not: a lone spike is
  // rejected (and the command after it), while a stream that really moved on after a gap
  // is followed again from its second command instead of being rejected for ever.
  bool jumped = false;
  for (int i = 0; i < n_ && have_seen_; ++i) jumped = jumped || std::abs(cmd[i] - seen_axes_[i]) > config_.axes[i].max_step;
  have_seen_ = true;
  seen_axes_ = cmd;
  if (jumped) return reject(Reject::kStepTooLarge, why);

  // Full correction at this command, in axis units.
  double q[kMaxAxes], corrected[kMaxAxes], residual[2] = {0, 0}, before[2] = {0, 0};
  for (int i = 0; i < n_; ++i) q[i] = cmd[i] * info[i].to_internal;
  const auto status = static_cast<Status>(
      entry_.compensate(model_, workspace_, q, config_.direction_weight, corrected, residual, before));
  // outside a table whose `outside` is reject: the errors are not known there
  if (status == Status::kOutsideTable) return reject(Reject::kOutOfLimits, why);
  if (status != Status::kOk && status != Status::kResidual) return reject(Reject::kCompensationFailed, why);

  // Ramp towards on (1) or off (0) over ramp_time of command time: bumpless switching.
  const double goal = enabled_ ? 1.0 : 0.0;
  if (ramp_ != goal) {
    // (utime is the sender's: any int64, the difference taken without overflow)
    const double dt = have_last_ ? std::min(ahead_by(last_utime_, in.utime) * 1e-6, config_.ramp_time_s) : 0.0;
    const double step = config_.ramp_time_s > 0 ? dt / config_.ramp_time_s : 1.0;
    ramp_ = goal > ramp_ ? std::min(goal, ramp_ + step) : std::max(goal, ramp_ - step);
  }
  if (enabled_ || ramp_ > 0) flags |= kFlagCompensating;
  if (ramp_ != goal) flags |= kFlagRamping;

  // The limits scale the whole correction (or its change) rather than clamping each axis:
  // the axes' corrections keep their proportions, which near a singular pose hold the tool
  // far better than any axis alone (an arm's elbow and wrist corrections cancel each
  // other's motion of the tool). Each axis stays within its limits all the same.
  std::array<double, kMaxAxes> wanted{}, prev{};
  double size_scale = 1.0, rate_scale = 1.0, back_scale = 1.0;
  for (int i = 0; i < n_; ++i) {
    const AxisLimits& lim = config_.axes[i];
    wanted[i] = ramp_ * (corrected[i] - q[i]) / info[i].to_internal;
    prev[i] = have_last_ ? last_correction_[i] : 0.0;
    if (std::abs(wanted[i]) > lim.max_correction) size_scale = std::min(size_scale, lim.max_correction / std::abs(wanted[i]));
  }
  for (int i = 0; i < n_; ++i) {
    const double step = config_.axes[i].max_correction_step;
    const double change = std::abs(size_scale * wanted[i] - prev[i]);
    if (change > step) rate_scale = std::min(rate_scale, step / change);
    if (std::abs(prev[i]) > step) back_scale = std::min(back_scale, step / std::abs(prev[i]));
  }
  bool clamped = size_scale < 1.0 || rate_scale < 1.0;
  // The correction published, and the one the rate limit allows back towards none.
  std::array<double, kMaxAxes> correction{}, back{};
  for (int i = 0; i < n_; ++i) {
    const AxisLimits& lim = config_.axes[i];
    const double sized = size_scale * wanted[i];
    // (the clamps only take the rounding of the scaling off)
    const double rated = std::clamp(prev[i] + rate_scale * (sized - prev[i]), prev[i] - lim.max_correction_step,
                                    prev[i] + lim.max_correction_step);
    // the target itself stays within the command limits
    const double target = std::clamp(cmd[i] + rated, lim.lower, lim.upper);
    clamped = clamped || target != cmd[i] + rated;
    correction[i] = target - cmd[i];
    const double towards_none = std::clamp(prev[i] * (1.0 - back_scale), prev[i] - lim.max_correction_step,
                                           prev[i] + lim.max_correction_step);
    back[i] = std::clamp(cmd[i] + towards_none, lim.lower, lim.upper) - cmd[i];
  }
  if (clamped) {
    flags |= kFlagClamped;
    ++counters_.clamped;
  }
  if (flags & kFlagClampedInput) ++counters_.clamped_input;
  // The target's residual and status describe the target published: where the correction
  // was limited or is ramped (or off), the model is evaluated at that target.
  Status published = status;
  std::array<double, kMaxAxes> target_axes{};
  for (int i = 0; i < n_; ++i) target_axes[i] = cmd[i] + correction[i];
  // The error a residual (point, direction) stands for, weighted as compensate() weighs it.
  auto weighted_error = [&](const double* r) { return objective(r[0], r[1], config_.direction_weight); };
  if (clamped || ramp_ < 1.0) {
    residual_at(q, target_axes, residual);
    // A limited correction may leave the tool further off than none (the wanted one moved
    // faster than the rate limit follows): then the better of it and the step back towards
    // none, both within the rate limit.
    if (clamped && std::isfinite(residual[0]) && std::isfinite(residual[1])) {
      std::array<double, kMaxAxes> none{};
      double none_residual[2], back_residual[2];
      for (int i = 0; i < n_; ++i) none[i] = cmd[i];
      residual_at(q, none, none_residual);
      if (weighted_error(residual) > weighted_error(none_residual)) {
        std::array<double, kMaxAxes> back_axes{};
        for (int i = 0; i < n_; ++i) back_axes[i] = cmd[i] + back[i];
        residual_at(q, back_axes, back_residual);
        if (weighted_error(back_residual) < weighted_error(residual)) {
          correction = back;
          target_axes = back_axes;
          residual[0] = back_residual[0];
          residual[1] = back_residual[1];
          ++counters_.held_back;
        }
      }
    }
    if (!std::isfinite(residual[0]) || !std::isfinite(residual[1])) return reject(Reject::kCompensationFailed, why);
    published = residual[0] <= kPointTolerance && residual[1] <= kDirectionTolerance ? Status::kOk : Status::kResidual;
  }
  if (published == Status::kResidual) flags |= kFlagResidual;
  bool corrected_any = false;
  for (int i = 0; i < n_; ++i) corrected_any = corrected_any || correction[i] != 0.0;
  const double before_objective = weighted_error(before), after_objective = weighted_error(residual);

  out.utime = in.utime;
  out.seq = in.seq;
  out.num_axes = n_;
  for (int i = 0; i < kMaxAxes; ++i) {
    out.axes[i] = i < n_ ? target_axes[i] : 0.0;
    out.correction[i] = i < n_ ? correction[i] : 0.0;
  }
  out.residual_point = residual[0];
  out.residual_direction = residual[1];
  out.flags = flags;
  out.status = static_cast<int>(published);
  for (int i = 0; i < n_; ++i) {
    if (!std::isfinite(out.axes[i])) return reject(Reject::kCompensationFailed, why);
  }

  have_last_ = true;
  count_gap(in.seq, restarting);
  order_.accept(in.seq);
  if (restarting) ++counters_.stream_restarts;
  ++(published == Status::kOk ? counters_.targets_full
     : corrected_any          ? counters_.targets_partial
                              : counters_.targets_uncorrected);
  // (beyond rounding: a ramped or limited target's residual is evaluated apart from compensate's)
  if (after_objective > before_objective * (1 + 1e-9) + 1e-24) ++counters_.targets_worse;
  counters_.objective_before += before_objective;
  counters_.objective_after += after_objective;
  last_utime_ = in.utime;
  last_correction_ = correction;
  return true;
}

}  // namespace chaincomp
