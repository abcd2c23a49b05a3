// A params update payload through the daemon's path (decode_params_update, the updater's
// checks, the model prepared again), then a command through the compensator, for five_axis_ac
// with its demo params: never a crash; whatever is applied, the target stays finite and its
// correction within max_correction.
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <memory>

#include "chaincomp/compensator.hpp"
#include "fuzz_model.hpp"
#include "chaincomp/params_update.hpp"
#include "chaincomp_lcm/lcmt_params_update.hpp"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  chaincomp::LoadedModel& loaded = chaincomp_fuzz::demo_model();
  static std::unique_ptr<chaincomp::Compensator> comp;
  static std::unique_ptr<chaincomp::ParamsUpdater> updater;
  static std::int64_t seq = 0;
  if (!comp) {
    comp = std::make_unique<chaincomp::Compensator>(*loaded.entry, loaded.model, loaded.config.compensator);
    updater = std::make_unique<chaincomp::ParamsUpdater>(*loaded.entry, loaded.model, &loaded.varying, loaded.params,
                                                         loaded.config.params_updates);
  }
  chaincomp::ParamsUpdate u;
  if (chaincomp::decode_params_update(data, size, chaincomp_lcm::lcmt_params_update::getHash(), u)) {
    updater->apply(u, 1, comp->last_utime());
  }
  for (double v : updater->params()) {
    if (!std::isfinite(v)) std::abort();
  }
  chaincomp::Command cmd;
  ++seq;
  cmd.seq = seq;
  cmd.utime = 20000 * seq;   // 20 ms: every update may be applied
  cmd.machine = "five_axis_ac";
  cmd.num_axes = 5;
  cmd.axes = {10.0, -20.0, -100.0, 30.0, -45.0, 0, 0, 0};
  chaincomp::Target target;
  if (comp->process(cmd, target)) {
    for (int i = 0; i < target.num_axes; ++i) {
      if (!std::isfinite(target.axes[i]) || !std::isfinite(target.correction[i]) ||
          std::abs(target.correction[i]) > loaded.config.compensator.axes[i].max_correction * (1 + 1e-12))
        std::abort();
    }
  }
  return 0;
}
