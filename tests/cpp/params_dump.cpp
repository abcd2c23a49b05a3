// chaincomp_params_dump: what the C++ loaders make of a params file (or a runtime config) for a
// compiled-in machine, for tests/python/model/test_conformance.py to compare with the Python loaders.
//   chaincomp_params_dump MACHINE params FILE   ->  NAME VALUE (internal units, 17 digits) per line
//   chaincomp_params_dump MACHINE config FILE   ->  ok
//   chaincomp_params_dump MACHINE thermal FILE  ->  reference, then per error its offset and
//                                                   terms (internal units per K, s)
// A refusal is the loader's message on stderr, exit 2.
#include <cstdio>
#include <string>
#include <vector>

#include "chaincomp/daemon_config.hpp"
#include "chaincomp/params_io.hpp"
#include "chaincomp/thermal.hpp"

int main(int argc, char** argv) {
  if (argc != 4) {
    std::fprintf(stderr, "usage: chaincomp_params_dump MACHINE params|config|thermal FILE\n");
    return 2;
  }
  const chaincomp::ModelEntry* entry = chaincomp::find_model(argv[1]);
  if (entry == nullptr) {
    std::fprintf(stderr, "no compiled model %s\n", argv[1]);
    return 2;
  }
  const chaincomp::MachineInfo& info = *entry->info;
  std::string error;
  if (std::string(argv[2]) == "config") {
    chaincomp::DaemonConfig config;
    if (!chaincomp::load_daemon_config(info, argv[3], config, error)) {
      std::fprintf(stderr, "%s\n", error.c_str());
      return 2;
    }
    std::printf("ok\ndirection_weight %.17g\n", config.compensator.direction_weight);
    return 0;
  }
  if (std::string(argv[2]) == "thermal") {
    chaincomp::ThermalModel model;
    if (!chaincomp::load_thermal_model(info, argv[3], model, error)) {
      std::fprintf(stderr, "%s\n", error.c_str());
      return 2;
    }
    std::printf("reference %.17g\n", model.reference);
    for (int e = 0; e < model.num_errors; ++e) {
      const auto& err = model.errors[e];
      std::printf("%s %.17g", err.name, err.offset);
      for (int k = 0; k < err.num_terms; ++k)
        std::printf(" %s:%.17g:%.17g", model.sensors[err.terms[k].sensor].c_str(), err.terms[k].gain,
                    err.terms[k].time_constant);
      std::printf("\n");
    }
    return 0;
  }
  std::vector<double> values;
  chaincomp::VaryingErrors varying;
  if (!chaincomp::load_params(info, argv[3], values, varying, error)) {
    std::fprintf(stderr, "%s\n", error.c_str());
    return 2;
  }
  for (int i = 0; i < info.num_params; ++i) std::printf("%s %.17g\n", info.params[i].name, values[i]);
  for (int i = 0; i < varying.count; ++i) std::printf("varying %s\n", info.params[varying.items[i].param].name);
  return 0;
}
