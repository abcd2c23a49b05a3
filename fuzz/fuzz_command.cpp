// A command payload through the daemon's decode-and-validate path (decode_command, then the
// compensator's checks and solve) for five_axis_ac with its demo params: never a crash, and a
// published target is finite.
#include <cmath>
#include <cstdint>
#include <cstdlib>
#include <cstdio>
#include <memory>

#include "chaincomp/compensator.hpp"
#include "chaincomp/lcm_node.hpp"
#include "fuzz_model.hpp"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  static std::unique_ptr<chaincomp::Compensator> comp;
  static chaincomp_lcm::lcmt_axis_command scratch;
  if (!comp) {
    chaincomp::LoadedModel& loaded = chaincomp_fuzz::demo_model();
    comp = std::make_unique<chaincomp::Compensator>(*loaded.entry, loaded.model, loaded.config.compensator);
    scratch.machine.reserve(chaincomp::LcmNode::kMaxMachineName + 1);
  }
  chaincomp::Command cmd;
  chaincomp::Target target;
  if (!chaincomp::decode_command(data, size, scratch, cmd)) return 0;
  if (comp->process(cmd, target)) {
    for (int i = 0; i < target.num_axes; ++i) {
      if (!std::isfinite(target.axes[i]) || !std::isfinite(target.correction[i])) std::abort();
    }
  }
  return 0;
}
