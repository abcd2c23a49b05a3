// five_axis_ac's compensate on the solver before issue #40's never-worse rule
// (compensate_before_40.hpp), compiled as the models are (the build's -O3, not the bench's -O2),
// called cold (a fresh workspace) as the registry's compensate is with a null workspace, or
// with one kept across the calls (`warm`): the other half of bench_codegen's side-by-side timing.
#include "compensate_before_40.hpp"
#include "five_axis_ac.hpp"

namespace model = chaincomp::models::five_axis_ac;
using K = model::Kinematics;

int before40_compensate_five_axis_ac(const void* m, const double* command, double* corrected, double* residual,
                                     bool warm) noexcept {
  static chaincomp_before40::Workspace<K> kept;  // zero-initialised, as init_workspace's
  chaincomp_before40::Workspace<K> fresh;
  chaincomp_before40::Workspace<K>& ws = warm ? kept : fresh;
  chaincomp_before40::Result<K> r;
  const auto s = chaincomp_before40::compensate<K>(*static_cast<const model::Model*>(m), ws,
                                                   Eigen::Map<const model::Axes>(command), r);
  Eigen::Map<model::Axes> corrected_out(corrected);
  corrected_out = r.corrected;
  residual[0] = r.residual_point;
  residual[1] = r.residual_direction;
  return static_cast<int>(s);
}
