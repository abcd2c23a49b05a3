// The runtime-config loader on any bytes, for the five_axis_ac model: a clean refusal naming
// the file, or settings within their documented bounds.
#include <cmath>
#include <cstdint>
#include <cstdlib>

#include "chaincomp/daemon_config.hpp"
#include "chaincomp/model_info.hpp"
#include "fuzz_file.hpp"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  static const chaincomp::ModelEntry* entry = chaincomp::find_model("five_axis_ac");
  if (entry == nullptr) std::abort();
  const std::string path = chaincomp_fuzz::as_file(data, size);
  chaincomp::DaemonConfig config;
  std::string error;
  if (chaincomp::load_daemon_config(*entry->info, path, config, error)) {
    if (!(config.status_period_s >= 0.001) || !std::isfinite(config.status_period_s)) std::abort();
    if (config.latency_window < 1 || config.latency_window > 1000000) std::abort();
    for (int i = 0; i < entry->info->num_axes; ++i) {
      const auto& a = config.compensator.axes[i];
      if (!(a.lower < a.upper) || !(a.max_step >= 0) || !(a.max_correction >= 0)) std::abort();
    }
  } else if (error.rfind(path + ":", 0) != 0) {
    std::abort();  // every refusal names the file
  }
  return 0;
}
