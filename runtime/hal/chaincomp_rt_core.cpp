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
}

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
