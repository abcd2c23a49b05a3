// The C++ half of the realtime HAL component chaincomp_rt: one machine's generated model
// with its params (baked in by `chaincomp build --linuxcnc`, chaincomp_rt_model.hpp) and
// chaincompd's own per-command logic (compensator.cpp: bumpless enable, ramp, limits on the
// size and per-cycle change of the correction). Built -fno-exceptions -fno-rtti. Everything
// that allocates runs in ccrt_init() at module load; ccrt_step(), called in the servo
// thread, does not allocate.
#include <cmath>
#include <cstdio>
#include <new>

#include "chaincomp/compensator.hpp"
#include "chaincomp/params_update.hpp"
#include "chaincomp_rt.h"
#include "chaincomp_rt_model.hpp"  // generated: the model's namespace, params and limits

namespace {

using chaincomp::Command;
using chaincomp::Compensator;
using chaincomp::Target;
namespace model = ccrt_model;

constexpr int kN = model::kNumAxes;
static_assert(kN <= chaincomp::kMaxAxes, "the compensator takes at most kMaxAxes axes");

alignas(model::Model) unsigned char g_model_storage[sizeof(model::Model)];
alignas(Compensator) unsigned char g_comp_storage[sizeof(Compensator)];
Compensator* g_comp = nullptr;
alignas(chaincomp::ParamsUpdater) unsigned char g_updater_storage[sizeof(chaincomp::ParamsUpdater)];
chaincomp::ParamsUpdater* g_updater = nullptr;
// The errors the pins set: kParams indices (at most kMaxUpdateValues, as an update carries).
int g_num_errors = 0;
int g_error_param[chaincomp::kMaxUpdateValues];
// LinuxCNC joint units (mm, deg) -> the machine file's axis units (the compensator's).
double g_to_axis[kN];
std::int64_t g_seq = 0;

}  // namespace

extern "C" int ccrt_init(char* error, int size) {
  const chaincomp::ModelEntry& entry = model::kEntry;
  entry.prepare(ccrt_params::kValues, g_model_storage);
  chaincomp::CompensatorConfig config;
  for (int i = 0; i < kN; ++i) {
    const chaincomp::AxisInfo& a = entry.info->axes[i];
    const double joint_to_internal = a.kind == chaincomp::UnitKind::kAngle ? M_PI / 180.0 : 1.0;
    g_to_axis[i] = joint_to_internal / a.to_internal;
    config.axes[i] = ccrt_params::kLimits[i];
  }
  config.ramp_time_s = ccrt_params::kRampTime;
  config.clamp_out_of_limits = ccrt_params::kClampOutOfLimits;
  config.start_enabled = false;  // the enable pin decides, and the correction ramps in from 0
  g_comp = new (g_comp_storage) Compensator(entry, g_model_storage, config);
  // Module load may allocate: the updater's copies of the params.
  const std::vector<double> params(ccrt_params::kValues, ccrt_params::kValues + entry.info->num_params);
  g_updater = new (g_updater_storage) chaincomp::ParamsUpdater(entry, g_model_storage, nullptr, params,
                                                               chaincomp::ParamsUpdateLimits{});
  g_num_errors = 0;
  for (int i = 0; i < entry.info->num_params; ++i) {
    if (entry.info->params[i].role != chaincomp::ParamRole::kError) continue;
    if (g_num_errors == chaincomp::kMaxUpdateValues) {
      std::snprintf(error, size, "machine %s: more than %d errors; HAL pins set at most %d", model::kName,
                    chaincomp::kMaxUpdateValues, chaincomp::kMaxUpdateValues);
      return -1;
    }
    g_error_param[g_num_errors++] = i;
  }
  // The model must give a pose at the zero command: a check that prepare() took the params.
  double q[kN] = {}, pose[6];
  entry.pose_exact(g_model_storage, q, pose);
  if (!std::isfinite(pose[0])) {
    std::snprintf(error, size, "machine %s: the model gives no finite pose at zero axes", model::kName);
    return -1;
  }
  return 0;
}

extern "C" void ccrt_fini(void) {
  if (g_comp != nullptr) g_comp->~Compensator();
  g_comp = nullptr;
  if (g_updater != nullptr) g_updater->~ParamsUpdater();
  g_updater = nullptr;
}

extern "C" int ccrt_num_errors(void) { return g_num_errors; }
extern "C" const char* ccrt_error_name(int i) {
  return i >= 0 && i < g_num_errors ? model::kEntry.info->params[g_error_param[i]].name : "";
}
extern "C" const char* ccrt_error_unit(int i) {
  return i >= 0 && i < g_num_errors ? model::kEntry.info->params[g_error_param[i]].unit : "";
}
extern "C" double ccrt_error_value(int i) {
  if (i < 0 || i >= g_num_errors) return 0.0;
  const chaincomp::ParamInfo& p = model::kEntry.info->params[g_error_param[i]];
  return ccrt_params::kValues[g_error_param[i]] / p.to_internal;
}

extern "C" int ccrt_set_errors(const double* values, long long utime_us) {
  chaincomp::ParamsUpdate u;
  u.num_values = g_num_errors;
  for (int i = 0; i < g_num_errors; ++i) {
    const chaincomp::ParamInfo& p = model::kEntry.info->params[g_error_param[i]];
    u.names[i] = p.name;
    u.values[i] = values[i] * p.to_internal;
  }
  chaincomp::Refuse why = chaincomp::Refuse::kUndecodable;
  return g_updater->apply_values(u, utime_us, &why) ? -1 : static_cast<int>(why);
}

extern "C" int ccrt_set_direction_weight(double mm) { return g_comp->set_direction_weight(mm) ? 0 : -1; }
extern "C" double ccrt_direction_weight(void) { return g_comp->direction_weight(); }

extern "C" int ccrt_num_axes(void) { return kN; }
extern "C" const char* ccrt_machine(void) { return model::kName; }
extern "C" const char* ccrt_params_file(void) { return ccrt_params::kParamsFile; }
extern "C" const char* ccrt_axis_name(int i) { return i >= 0 && i < kN ? model::kEntry.info->axes[i].name : ""; }

extern "C" int ccrt_step(const double* joint_cmd, int enable, long long utime_us, double* correction,
                         struct ccrt_result* result) {
  Command cmd;
  cmd.utime = utime_us;
  cmd.seq = ++g_seq;
  cmd.machine = model::kName;
  cmd.num_axes = kN;
  for (int i = 0; i < kN; ++i) cmd.axes[i] = joint_cmd[i] * g_to_axis[i];
  g_comp->set_enabled(enable != 0);
  Target t;
  chaincomp::Reject why = chaincomp::Reject::kUndecodable;
  const bool ok = g_comp->process(cmd, t, &why);
  result->ramp = g_comp->ramp();
  if (!ok) {  // the caller holds the last correction and raises fault
    result->reject = static_cast<int>(why);
    return 0;
  }
  for (int i = 0; i < kN; ++i) correction[i] = t.correction[i] / g_to_axis[i];
  result->reject = -1;
  result->flags = t.flags;
  result->status = t.status;
  result->residual_point = t.residual_point;
  result->residual_direction = t.residual_direction;
  return 1;
}
