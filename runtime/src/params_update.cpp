#include "chaincomp/params_update.hpp"

#include <algorithm>
#include <cmath>
#include <cstring>

namespace chaincomp {

namespace {

constexpr std::int32_t kMaxNameBytes = 255;

// LCM's encoding: big-endian integers and doubles, strings as int32 length (with the NUL),
// the bytes and the NUL.
struct Reader {
  const unsigned char* p;
  std::size_t left;

  bool u64(std::uint64_t& v) noexcept {
    if (left < 8) return false;
    v = 0;
    for (int i = 0; i < 8; ++i) v = (v << 8) | p[i];
    p += 8;
    left -= 8;
    return true;
  }
  bool i64(std::int64_t& v) noexcept {
    std::uint64_t u;
    if (!u64(u)) return false;
    v = static_cast<std::int64_t>(u);
    return true;
  }
  bool i32(std::int32_t& v) noexcept {
    if (left < 4) return false;
    v = static_cast<std::int32_t>((std::uint32_t(p[0]) << 24) | (std::uint32_t(p[1]) << 16) |
                                  (std::uint32_t(p[2]) << 8) | std::uint32_t(p[3]));
    p += 4;
    left -= 4;
    return true;
  }
  bool f64(double& v) noexcept {
    std::uint64_t u;
    if (!u64(u)) return false;
    std::memcpy(&v, &u, sizeof v);
    return true;
  }
  bool str(std::string_view& s) noexcept {
    std::int32_t len;
    if (!i32(len) || len < 1 || len > kMaxNameBytes + 1 || static_cast<std::size_t>(len) > left || p[len - 1] != 0)
      return false;
    s = std::string_view(reinterpret_cast<const char*>(p), static_cast<std::size_t>(len - 1));
    p += len;
    left -= static_cast<std::size_t>(len);
    return true;
  }
};

}  // namespace

const char* refuse_name(Refuse r) noexcept {
  switch (r) {
    case Refuse::kUndecodable: return "undecodable";
    case Refuse::kWrongMachine: return "wrong machine";
    case Refuse::kOtherInstance: return "another instance";
    case Refuse::kBadCount: return "bad count";
    case Refuse::kUnknownName: return "unknown name";
    case Refuse::kNotAnError: return "not an error";
    case Refuse::kRepeatedName: return "repeated name";
    case Refuse::kNonFinite: return "non-finite";
    case Refuse::kOutOfBound: return "out of bound";
    case Refuse::kStaleSeq: return "stale seq";
    case Refuse::kTooFrequent: return "too frequent";
  }
  return "?";
}

bool decode_params_update(const void* data, std::size_t size, std::int64_t fingerprint, ParamsUpdate& out) noexcept {
  Reader r{static_cast<const unsigned char*>(data), size};
  std::int64_t hash;
  std::int32_t n;
  if (!r.i64(hash) || hash != fingerprint || !r.i64(out.utime) || !r.i64(out.seq) || !r.str(out.machine) ||
      !r.i64(out.instance_id) || !r.i32(n) || n < 0 || n > kMaxUpdateValues)
    return false;
  out.num_values = n;
  for (int i = 0; i < n; ++i) {
    if (!r.str(out.names[i])) return false;
  }
  for (int i = 0; i < n; ++i) {
    if (!r.f64(out.values[i])) return false;
  }
  return r.left == 0;
}

ParamsUpdater::ParamsUpdater(const ModelEntry& entry, void* model, const VaryingErrors* varying,
                             const std::vector<double>& params, const ParamsUpdateLimits& limits)
    : entry_(entry), model_(model), varying_(varying), limits_(limits), params_(params), scratch_(params),
      updatable_(params.size(), 0) {
  for (int i = 0; i < entry.info->num_params; ++i) {
    updatable_[i] = entry.info->params[i].role == ParamRole::kError;
  }
  if (varying != nullptr) {
    for (int k = 0; k < varying->count; ++k) updatable_[varying->items[k].param] = 0;
  }
}

bool ParamsUpdater::refuse(Refuse r, Refuse* why) noexcept {
  ++refused_[static_cast<int>(r)];
  if (why) *why = r;
  return false;
}

void ParamsUpdater::count_undecodable() noexcept {
  ++received_;
  refuse(Refuse::kUndecodable, nullptr);
}

bool ParamsUpdater::apply(const ParamsUpdate& u, std::int64_t instance_id, std::int64_t command_utime,
                          Refuse* why) noexcept {
  ++received_;
  const MachineInfo& info = *entry_.info;
  if (u.machine != std::string_view(info.name)) return refuse(Refuse::kWrongMachine, why);
  if (u.instance_id != 0 && u.instance_id != instance_id) return refuse(Refuse::kOtherInstance, why);
  if (u.num_values < 1 || u.num_values > kMaxUpdateValues) return refuse(Refuse::kBadCount, why);
  if (applied_any_ && u.seq <= last_seq_) return refuse(Refuse::kStaleSeq, why);
  // (a command stream that goes back in time, a new one, does not hold updates off)
  if (applied_any_ && command_utime >= applied_utime_ &&
      static_cast<double>(command_utime - applied_utime_) < limits_.min_interval_s * 1e6)
    return refuse(Refuse::kTooFrequent, why);
  for (int i = 0; i < u.num_values; ++i) {
    int j = 0;
    while (j < info.num_params && u.names[i] != std::string_view(info.params[j].name)) ++j;
    if (j == info.num_params) return refuse(Refuse::kUnknownName, why);
    if (!updatable_[j]) return refuse(Refuse::kNotAnError, why);
    for (int k = 0; k < i; ++k) {
      if (index_[k] == j) return refuse(Refuse::kRepeatedName, why);
    }
    const double v = u.values[i];
    if (!std::isfinite(v)) return refuse(Refuse::kNonFinite, why);
    const UnitKind kind = info.params[j].kind;
    const double bound = kind == UnitKind::kLength ? limits_.max_length
                         : kind == UnitKind::kAngle ? limits_.max_angle : limits_.max_ratio;
    if (std::abs(v) > bound) return refuse(Refuse::kOutOfBound, why);
    index_[i] = j;
  }
  std::copy(params_.begin(), params_.end(), scratch_.begin());
  for (int i = 0; i < u.num_values; ++i) scratch_[index_[i]] = u.values[i];
  entry_.prepare(scratch_.data(), model_);
  if (varying_ != nullptr && varying_->count > 0) entry_.attach_varying(model_, varying_);
  params_.swap(scratch_);
  ++version_;
  last_seq_ = u.seq;
  applied_utime_ = command_utime;
  applied_any_ = true;
  return true;
}

}  // namespace chaincomp
