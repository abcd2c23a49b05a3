// The daemon's per-message logic, free of LCM and I/O: validates a command, compensates it,
// ramps the correction in and out (bumpless switching), enforces per-axis limits on the
// size and the per-cycle change of the correction, and counts every rejection by reason.
// Allocation-free after construction; deterministic (time comes from the command's utime).
#pragma once

#include <array>
#include <cstdint>
#include <string_view>
#include <vector>

#include "chaincomp/model_info.hpp"
#include "chaincomp/stream_order.hpp"

namespace chaincomp {

constexpr int kMaxAxes = 8;

enum class Reject : int {
  kUndecodable = 0,
  kWrongMachine = 1,
  kWrongAxisCount = 2,
  kNonFinite = 3,
  kOutOfLimits = 4,    // outside the axis limits, or outside a table whose `outside` is reject
  kStepTooLarge = 5,
  kDuplicateSeq = 6,
  kOutOfOrderSeq = 7,
  kCompensationFailed = 8,
};
constexpr int kNumReasons = 9;
const char* reject_name(Reject r) noexcept;

// Flags of a corrected target (the same bits as lcmt_corrected_target.FLAG_*).
enum : int {
  kFlagCompensating = 1,
  kFlagRamping = 2,
  kFlagClamped = 4,
  kFlagResidual = 8,
  kFlagClampedInput = 16,
};

struct AxisLimits {
  double lower = 0, upper = 0;        // command limits, axis unit (mm or deg)
  double max_step = 0;                // largest change from the previous valid command
  double max_correction = 0;          // largest |correction|
  double max_correction_step = 0;     // largest change of the correction per command
};

struct CompensatorConfig {
  std::array<AxisLimits, kMaxAxes> axes{};
  double ramp_time_s = 0.5;           // 0 -> 1 (and back) over this much command time
  bool clamp_out_of_limits = false;   // clamp commands into limits instead of rejecting them
  bool start_enabled = true;
  // mm per rad: the objective's weight of the direction (compensate.hpp, kDefaultDirectionWeight)
  double direction_weight = 100.0;
};

// The stream rule (stream_order.hpp): commands in order by seq, at most kMaxSeqJump ahead; a
// restart run of kRestartRun commands behind (or far ahead of) the last accepted seq, in order
// among themselves (seq increasing, utime not decreasing, each step within max_step), is a new
// stream, the last of them accepted. One message (e.g. seq 2^63-1) cannot lock the stream out,
// and a CNC that restarts its numbering is followed again after at most kRestartRun commands.

struct Command {
  std::int64_t utime = 0, seq = 0;
  std::string_view machine;           // compared exactly (length and bytes) with the model's
  int num_axes = 0;
  std::array<double, kMaxAxes> axes{};  // axis units (mm, deg)
};

struct Target {
  std::int64_t utime = 0, seq = 0;
  int num_axes = 0;
  std::array<double, kMaxAxes> axes{}, correction{};
  double residual_point = 0, residual_direction = 0;
  int flags = 0, status = 0;
};

struct Counters {
  std::int64_t received = 0, published = 0, clamped = 0, clamped_input = 0;
  std::int64_t seq_gaps = 0;         // forward jumps of seq (for this machine): commands never received
  std::int64_t seq_missing = 0;      // the seq values those jumps skipped (saturates at 2^63-1)
  std::int64_t stream_restarts = 0;  // restarts taken by the kRestartRun rule
  std::int64_t resets = 0;           // restarts asked for by reset()
  std::int64_t held_back = 0;        // limited corrections worse than none, stepped back towards none instead
  // Targets published by what they correct: the whole pose within tolerance (status ok); a
  // residual left with a correction made; a residual left and no correction (none scores
  // better: compensate.hpp's never-worse rule, or compensation off). `worse`: scoring worse
  // than the command by the objective (only where a limit holds the correction back).
  std::int64_t targets_full = 0, targets_partial = 0, targets_uncorrected = 0, targets_worse = 0;
  // The objective (mm^2, compensate.hpp's objective at the config's direction_weight) summed
  // over the targets published: of the command itself (before) and of the target (after).
  double objective_before = 0, objective_after = 0;
  std::array<std::int64_t, kNumReasons> rejected{};
};

class Compensator {
 public:
  // `model` must have been filled by entry.prepare(); both must outlive the compensator.
  Compensator(const ModelEntry& entry, const void* model, const CompensatorConfig& config);
  Compensator(const Compensator&) = delete;  // points into its own workspace storage
  Compensator& operator=(const Compensator&) = delete;

  // true: `out` holds a target to publish; false: rejected (counted, reason in *why).
  bool process(const Command& in, Target& out, Reject* why = nullptr) noexcept;
  void count_undecodable() noexcept {
    ++counters_.received;
    reject(Reject::kUndecodable, nullptr);
  }
  void set_enabled(bool on) noexcept { enabled_ = on; }
  // The objective's direction weight from the next command on (mm per rad); false, unchanged,
  // outside kMinDirectionWeight..kMaxDirectionWeight (compensate.hpp).
  bool set_direction_weight(double mm) noexcept;
  double direction_weight() const noexcept { return config_.direction_weight; }
  // A new stream (a control message's reset): the next command is accepted whatever its seq
  // and wherever it starts; the correction keeps its rate limit from the last one.
  void reset() noexcept;
  bool enabled() const noexcept { return enabled_; }
  double ramp() const noexcept { return ramp_; }
  const Counters& counters() const noexcept { return counters_; }
  // The last accepted command's utime (µs; 0 before the first): the params updates' clock.
  std::int64_t last_utime() const noexcept { return have_last_ ? last_utime_ : 0; }
  void count_published() noexcept { ++counters_.published; }

 private:
  bool reject(Reject r, Reject* why) noexcept;
  bool seq_ok(const Command& in, const std::array<double, kMaxAxes>& cmd, bool& restarting, Reject* why) noexcept;
  void count_gap(std::int64_t seq, bool restarting) noexcept;
  void residual_at(const double* q, const std::array<double, kMaxAxes>& target, double* residual) const noexcept;

  const ModelEntry& entry_;
  const void* model_;
  // compensate's workspace, kept from command to command: each starts from the last
  // correction (a warm start); sized and aligned at construction.
  std::vector<unsigned char> workspace_storage_;
  void* workspace_;
  CompensatorConfig config_;
  int n_;
  bool enabled_;
  double ramp_;
  bool have_last_ = false;  // a command has been accepted (ramp time, rate limit)
  StreamOrder order_{kMaxSeqJump};  // by seq
  bool have_seen_ = false;  // a valid command has been seen (for the step check)
  std::int64_t last_utime_ = 0;
  std::array<double, kMaxAxes> seen_axes_{}, last_correction_{};
  // Gap counting: the command in process is 1 .. kMaxSeqJump ahead of the last taken one, and
  // how many such were refused since that one (received: not missing).
  bool in_gap_ = false;
  std::int64_t refused_in_gap_ = 0;
  std::int64_t run_utime_ = 0;  // the restart run's last command (its own tests: utime, step)
  std::array<double, kMaxAxes> run_axes_{};
  Counters counters_;
};

}  // namespace chaincomp
