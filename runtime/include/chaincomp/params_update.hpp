// Error values updated while the daemon runs (lcmt_params_update): checked all together,
// then applied all or none to the model between two commands. LCM-free, allocation-free
// after construction, deterministic (its clock is the command stream's utime).
#pragma once

#include <array>
#include <cstddef>
#include <cstdint>
#include <string_view>
#include <vector>

#include "chaincomp/model_info.hpp"
#include "chaincomp/stream_order.hpp"
#include "chaincomp/varying.hpp"

namespace chaincomp {

constexpr int kMaxUpdateValues = 64;   // lcmt_params_update.MAX_VALUES

enum class Refuse : int {
  kUndecodable = 0,   // not an lcmt_params_update of this version, or past its bounds
  kWrongMachine = 1,
  kOtherInstance = 2, // addressed to another daemon of this machine
  kBadCount = 3,      // no values, or more than kMaxUpdateValues
  kUnknownName = 4,   // not a symbol of the machine
  kNotAnError = 5,    // an axis, a constant, or an error given as a table or polynomial
  kRepeatedName = 6,
  kNonFinite = 7,
  kOutOfBound = 8,    // |value| above the bound of its kind (params_updates in the runtime settings)
  kStaleSeq = 9,      // seq at or below the last applied update's, or more than kMaxSeqJump above it
                      // (the stream rule, stream_order.hpp: a restart run of kRestartRun is taken)
  kTooFrequent = 10,  // within min_interval of command time after the last applied update
};
constexpr int kNumRefusals = 11;
const char* refuse_name(Refuse r) noexcept;

struct ParamsUpdateLimits {
  double max_length = 1.0;     // mm: |value| of a length error
  double max_angle = 0.01;     // rad (about 34 arcmin)
  double max_ratio = 0.01;     // a scale error
  double min_interval_s = 0.01;  // of command time between two applied updates
};

// No command accepted for this long (of the caller's receipt clock, µs): the command stream
// is idle, and updates are held off on that clock instead of the commands' frozen time.
constexpr std::int64_t kCommandsIdleUs = 1000000;

// The updates' clock: the last accepted command's utime (µs, the sender's clock); whether
// commands flow (one was accepted within kCommandsIdleUs); and, for when they do not, the
// update's receipt time (µs, the caller's clock). A bare utime: commands flow.
struct CommandTime {
  std::int64_t utime = 0;
  bool flowing = true;
  std::int64_t received_us = 0;
  CommandTime(std::int64_t u = 0, bool f = true, std::int64_t r = 0) noexcept  // NOLINT: implicit
      : utime(u), flowing(f), received_us(r) {}
};
// Whether commands flow at `now_us`, the last accepted one received at `last_us` (either
// clock may be any int64; a clock that went back counts as flowing).
constexpr bool commands_flowing(bool any, std::int64_t last_us, std::int64_t now_us) noexcept {
  return any && ahead_by(last_us, now_us) < static_cast<std::uint64_t>(kCommandsIdleUs);
}

struct ParamsUpdate {
  std::int64_t utime = 0, seq = 0, instance_id = 0;
  std::string_view machine;
  int num_values = 0;
  std::array<std::string_view, kMaxUpdateValues> names{};
  std::array<double, kMaxUpdateValues> values{};
};

// An lcmt_params_update payload into `out` (names point into `data`); false for anything
// that is not one of this version or breaks its bounds (a name longer than 255 bytes, more
// than kMaxUpdateValues values, trailing bytes).
bool decode_params_update(const void* data, std::size_t size, std::int64_t fingerprint, ParamsUpdate& out) noexcept;

class ParamsUpdater {
 public:
  // `model` prepared from `params` (internal units, kParams order), with `varying` attached
  // when it holds any; all outlive the updater.
  ParamsUpdater(const ModelEntry& entry, void* model, const VaryingErrors* varying, const std::vector<double>& params,
                const ParamsUpdateLimits& limits);

  // Checks every value, then applies them all (true) or none (false, counted by reason).
  // `instance_id`: this daemon's; `now`: the command stream's time.
  bool apply(const ParamsUpdate& u, std::int64_t instance_id, CommandTime now, Refuse* why = nullptr) noexcept;
  // The same checks and application for values from inside the daemon (a thermal model): no
  // machine, instance or seq to check; counted as updates (received, refused, version).
  bool apply_values(const ParamsUpdate& u, CommandTime now, Refuse* why = nullptr) noexcept;
  void count_undecodable() noexcept;
  // A new stream (a control message's reset): the next update is taken whatever its seq,
  // and none is held off by the last one's time. The values applied stay.
  void reset() noexcept;

  std::int64_t received() const noexcept { return received_; }
  std::int64_t version() const noexcept { return version_; }   // updates applied (0: the file's values)
  std::int64_t last_seq() const noexcept { return order_.known() ? order_.last() : 0; }
  const std::array<std::int64_t, kNumRefusals>& refused() const noexcept { return refused_; }
  const std::vector<double>& params() const noexcept { return params_; }

 private:
  bool refuse(Refuse r, Refuse* why) noexcept;
  bool check_and_apply(const ParamsUpdate& u, CommandTime now, Refuse* why) noexcept;

  const ModelEntry& entry_;
  void* model_;
  const VaryingErrors* varying_;
  ParamsUpdateLimits limits_;
  std::vector<double> params_, scratch_;
  std::vector<unsigned char> updatable_;   // per parameter: an error given as a constant
  std::array<int, kMaxUpdateValues> index_{};
  std::int64_t received_ = 0, version_ = 0, applied_utime_ = 0, applied_received_ = 0;
  StreamOrder order_{kMaxSeqJump};   // of the updates' seq
  bool applied_any_ = false;         // since the start or the last reset (min_interval)
  std::array<std::int64_t, kNumRefusals> refused_{};
};

}  // namespace chaincomp
