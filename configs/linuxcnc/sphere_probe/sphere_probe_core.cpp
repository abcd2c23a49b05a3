// The C++ half of sphere_probe: the machine's generated exact model, prepared once at module
// load with the true errors (chaincomp_rt_model.hpp, written by sphere_probe.py), evaluated
// in the servo thread without allocating.
#include <cmath>

#include "chaincomp_rt_model.hpp"  // generated: the model's namespace and the true params

namespace {
namespace model = ccrt_model;
constexpr int kN = model::kNumAxes;
alignas(model::Model) unsigned char g_model[sizeof(model::Model)];
double g_to_internal[kN];  // LinuxCNC joint units (mm, deg) -> internal (mm, rad)
}  // namespace

extern "C" int sp_init(void) {
  const chaincomp::ModelEntry& entry = model::kEntry;
  entry.prepare(ccrt_params::kValues, g_model);
  for (int i = 0; i < kN; ++i)
    g_to_internal[i] = entry.info->axes[i].kind == chaincomp::UnitKind::kAngle ? M_PI / 180.0 : 1.0;
  return kN;
}

extern "C" void sp_tool_point(const double* joints, double* point) {
  double q[kN], pose[9];
  for (int i = 0; i < kN; ++i) q[i] = joints[i] * g_to_internal[i];
  model::kEntry.pose_exact(g_model, q, pose);
  for (int i = 0; i < 3; ++i) point[i] = pose[i];
}
