// One message on one of chaincompd's input channels, chosen by the input's first byte (control,
// command, params, temperatures; the rest is the payload), through the daemon's own LcmNode on
// memq://: never a crash; and whatever came before, a command stream that restarts is answered
// again within kRestartRun commands, and a control reset is honoured at once (issue 39: no
// message locks a stream out, and a reset clears every stream).
#include <lcm/lcm.h>

#include <cstdint>
#include <cstdlib>
#include <cstring>
#include <memory>
#include <vector>

#include "chaincomp/lcm_node.hpp"
#include "chaincomp/stream_order.hpp"
#include "chaincomp/thermal.hpp"
#include "fuzz_model.hpp"

namespace {

void publish_command(lcm_t* lcm, chaincomp::LcmNode& node, std::int64_t seq) {
  chaincomp_lcm::lcmt_axis_command c{};
  c.utime = seq;   // any int64: the daemon takes differences without overflow
  c.seq = seq;
  c.machine = "five_axis_ac";
  c.num_axes = 5;
  const double axes[8] = {10.0, -20.0, -100.0, 30.0, -45.0, 0, 0, 0};
  std::memcpy(c.axes, axes, sizeof axes);
  std::vector<unsigned char> b(c.getEncodedSize());
  c.encode(b.data(), 0, static_cast<int>(b.size()));
  lcm_publish(lcm, "CHAINCOMP_COMMAND", b.data(), static_cast<unsigned>(b.size()));
  node.handle_until_idle();
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  static const char* const kChannels[] = {"CHAINCOMP_CONTROL", "CHAINCOMP_COMMAND", "CHAINCOMP_PARAMS",
                                          "CHAINCOMP_TEMPERATURES"};
  chaincomp::LoadedModel& loaded = chaincomp_fuzz::demo_model();
  static lcm_t* lcm = lcm_create("memq://");
  static std::unique_ptr<chaincomp::LcmNode> node;
  static std::unique_ptr<chaincomp::ParamsUpdater> updater;
  static std::unique_ptr<chaincomp::ThermalState> thermal;
  static chaincomp::ThermalModel thermal_model;
  if (!node) {
    if (lcm == nullptr) std::abort();
    node = std::make_unique<chaincomp::LcmNode>(lcm, *loaded.entry, loaded.model, loaded.config, "p.yaml", "0",
                                                chaincomp::RealtimeObtained{});
    updater = std::make_unique<chaincomp::ParamsUpdater>(*loaded.entry, loaded.model, &loaded.varying, loaded.params,
                                                         loaded.config.params_updates);
    node->accept_params_updates(*updater);
    thermal = std::make_unique<chaincomp::ThermalState>(thermal_model, loaded.params);   // no sensors
    node->accept_temperatures(*thermal);
  }
  if (size == 0) return 0;
  lcm_publish(lcm, kChannels[data[0] % 4], data + 1, static_cast<unsigned>(size - 1));
  node->handle_until_idle();
  // a command stream restarting at a seq of the input's (a reset's next command is taken at once)
  std::int64_t base = 0;
  std::memcpy(&base, data + 1, std::min<std::size_t>(size - 1, sizeof base));
  const std::int64_t published = node->counters().published;
  for (int k = 0; k < chaincomp::kRestartRun && node->counters().published == published; ++k) {
    publish_command(lcm, *node, base < INT64_MAX - 8 ? base + k : base - 8 + k);
  }
  if (node->counters().published == published) std::abort();
  node->publish_status(false);
  node->handle_until_idle();
  return 0;
}
