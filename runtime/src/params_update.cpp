#include "chaincomp/params_update.hpp"

#include "chaincomp/lcm_wire.hpp"

#include <algorithm>
#include <cmath>
#include <cstring>

namespace chaincomp {


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
  WireReader r{static_cast<const unsigned char*>(data), size};
  std::int64_t hash;
  std::int32_t n;
  if (!r.i64(hash) || hash != fingerprint || !r.i64(out.utime) || !r.i64(out.seq) || !r.str(out.machine) ||
      !r.i64(out.instance_id) || !r.i32(n) || n < 0 || n > kMaxUpdateValues)
    return false;
  out.num_values = n;
  return r.names_then_values(n, out.names.data(), out.values.data());
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

void ParamsUpdater::reset() noexcept {
  order_.reset();
  applied_any_ = false;
}

bool ParamsUpdater::apply(const ParamsUpdate& u, std::int64_t instance_id, CommandTime now, Refuse* why) noexcept {
  ++received_;
  const MachineInfo& info = *entry_.info;
  if (u.machine != std::string_view(info.name)) return refuse(Refuse::kWrongMachine, why);
  if (u.instance_id != 0 && u.instance_id != instance_id) return refuse(Refuse::kOtherInstance, why);
  if (u.num_values < 1 || u.num_values > kMaxUpdateValues) return refuse(Refuse::kBadCount, why);
  if (!StreamOrder::taken(order_.judge(u.seq))) return refuse(Refuse::kStaleSeq, why);
  if (!check_and_apply(u, now, why)) return false;
  order_.accept(u.seq);
  return true;
}

bool ParamsUpdater::apply_values(const ParamsUpdate& u, CommandTime now, Refuse* why) noexcept {
  ++received_;
  return check_and_apply(u, now, why);
}

bool ParamsUpdater::check_and_apply(const ParamsUpdate& u, CommandTime now, Refuse* why) noexcept {
  const MachineInfo& info = *entry_.info;
  if (u.num_values < 1 || u.num_values > kMaxUpdateValues) return refuse(Refuse::kBadCount, why);
  // Within min_interval of command time while commands flow (a command stream that went back
  // in time, a new one, holds nothing off), of receipt time while they do not. (Both clocks
  // any int64: differences without overflow.)
  const std::int64_t at = now.flowing ? now.utime : now.received_us;
  const std::int64_t since = now.flowing ? applied_utime_ : applied_received_;
  if (applied_any_ && at >= since && static_cast<double>(ahead_by(since, at)) < limits_.min_interval_s * 1e6)
    return refuse(Refuse::kTooFrequent, why);
  for (int i = 0; i < u.num_values; ++i) {
    int j = 0;
    while (j < info.num_params && u.names[i] != std::string_view(info.params[j].name)) ++j;
    if (j == info.num_params) {
      // an axis is a symbol of the machine too, but not an error
      bool axis = false;
      for (int a = 0; a < info.num_axes; ++a) axis = axis || u.names[i] == std::string_view(info.axes[a].name);
      return refuse(axis ? Refuse::kNotAnError : Refuse::kUnknownName, why);
    }
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
  applied_utime_ = now.utime;
  applied_received_ = now.received_us;
  applied_any_ = true;
  return true;
}

}  // namespace chaincomp
