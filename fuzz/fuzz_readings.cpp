// A temperature message through the daemon's path (decode_readings, the thermal model's stream
// rule and lags, the values applied as an update), for five_axis_ac with its demo params and a
// two-sensor model: never a crash, every value applied finite; and after whatever the input
// was, a sensor clock that restarts is followed again within kRestartRun readings (issue 39: no
// message locks the readings out).
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <fstream>
#include <memory>
#include <string>
#include <unistd.h>

#include "chaincomp/params_update.hpp"
#include "chaincomp/stream_order.hpp"
#include "chaincomp/thermal.hpp"
#include "chaincomp_lcm/lcmt_temperatures.hpp"
#include "fuzz_model.hpp"

namespace {

const char* kThermal =
    "machine: five_axis_ac\n"
    "errors:\n"
    "  EXX:\n"
    "    unit: um\n"
    "    terms:\n"
    "      - {sensor: T_spindle, gain: 1.5, time_constant: 600}\n"
    "      - {sensor: T_column, gain: -0.4}\n";

chaincomp::ThermalModel load() {
  char name[] = "/tmp/chaincomp-fuzz-thermal-XXXXXX";
  const int fd = mkstemp(name);
  if (fd < 0) std::abort();
  close(fd);
  std::ofstream(name) << kThermal;
  chaincomp::ThermalModel model;
  std::string error;
  const bool ok = chaincomp::load_thermal_model(*chaincomp_fuzz::demo_model().entry->info, name, model, error);
  std::remove(name);
  if (!ok) {
    std::fprintf(stderr, "%s\n", error.c_str());
    std::abort();
  }
  return model;
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  chaincomp::LoadedModel& loaded = chaincomp_fuzz::demo_model();
  static std::unique_ptr<chaincomp::ThermalState> thermal;
  static std::unique_ptr<chaincomp::ParamsUpdater> updater;
  static std::int64_t clock = 0;
  if (!thermal) {
    thermal = std::make_unique<chaincomp::ThermalState>(load(), loaded.params);
    updater = std::make_unique<chaincomp::ParamsUpdater>(*loaded.entry, loaded.model, &loaded.varying, loaded.params,
                                                         loaded.config.params_updates);
  }
  chaincomp::Readings r;
  chaincomp::ParamsUpdate u;
  // commands idle: the receipt clock (1 s per message) holds nothing off
  clock += 1000000;
  if (!chaincomp::decode_readings(data, size, chaincomp_lcm::lcmt_temperatures::getHash(), r)) {
    thermal->count_undecodable();
  } else if (thermal->take(r, "five_axis_ac", u)) {
    updater->apply_values(u, chaincomp::CommandTime(0, false, clock));
  }
  // a sender whose clock restarted at the input's size (in seconds): its fifth reading is taken
  const std::int64_t base = static_cast<std::int64_t>(size) * 1000000;
  bool taken = false;
  for (int k = 1; k <= chaincomp::kRestartRun && !taken; ++k) {
    chaincomp::Readings good;
    good.utime = base + 1000000 * k;
    good.num_values = 2;
    good.names[0] = "T_spindle";
    good.names[1] = "T_column";
    good.values[0] = 25.0;
    good.values[1] = 21.0;
    taken = thermal->take(good, "five_axis_ac", u);
  }
  if (!taken) std::abort();
  for (int i = 0; i < u.num_values; ++i) {
    if (!std::isfinite(u.values[i])) std::abort();
  }
  for (double v : updater->params()) {
    if (!std::isfinite(v)) std::abort();
  }
  return 0;
}
