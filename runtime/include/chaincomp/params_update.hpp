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
#include "chaincomp/varying.hpp"

namespace chaincomp {

constexpr int kMaxUpdateValues = 64;   // lcmt_params_update.MAX_VALUES

enum class Refuse : int {
  kUndecodable = 0,   // not an lcmt_params_update of this version, or past its bounds
  kWrongMachine = 1,
  kOtherInstance = 2, // addressed to another daemon of this machine
  kBadCount = 3,      // no values, or more than kMaxUpdateValues
  kUnknownName = 4,   // not a symbol of the machine
  kNotAnError = 5,    // a constant, or an error given as a table or polynomial
  kRepeatedName = 6,
  kNonFinite = 7,
  kOutOfBound = 8,    // |value| above the bound of its kind (params_updates in the runtime settings)
  kStaleSeq = 9,      // seq at or below the last applied update's
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
  // `instance_id`: this daemon's; `command_utime`: the last accepted command's (µs).
  bool apply(const ParamsUpdate& u, std::int64_t instance_id, std::int64_t command_utime,
             Refuse* why = nullptr) noexcept;
  // The same checks and application for values from inside the daemon (a thermal model): no
  // machine, instance or seq to check; counted as updates (received, refused, version).
  bool apply_values(const ParamsUpdate& u, std::int64_t command_utime, Refuse* why = nullptr) noexcept;
  void count_undecodable() noexcept;

  std::int64_t received() const noexcept { return received_; }
  std::int64_t version() const noexcept { return version_; }   // updates applied (0: the file's values)
  std::int64_t last_seq() const noexcept { return last_seq_; }
  const std::array<std::int64_t, kNumRefusals>& refused() const noexcept { return refused_; }
  const std::vector<double>& params() const noexcept { return params_; }

 private:
  bool refuse(Refuse r, Refuse* why) noexcept;
  bool check_and_apply(const ParamsUpdate& u, std::int64_t command_utime, Refuse* why) noexcept;

  const ModelEntry& entry_;
  void* model_;
  const VaryingErrors* varying_;
  ParamsUpdateLimits limits_;
  std::vector<double> params_, scratch_;
  std::vector<unsigned char> updatable_;   // per parameter: an error given as a constant
  std::array<int, kMaxUpdateValues> index_{};
  std::int64_t received_ = 0, version_ = 0, last_seq_ = 0, applied_utime_ = 0;
  bool applied_any_ = false;
  std::array<std::int64_t, kNumRefusals> refused_{};
};

}  // namespace chaincomp
