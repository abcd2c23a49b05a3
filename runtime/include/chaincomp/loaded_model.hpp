// The start shared by chaincompd and chaincomp_replay: a machine's compiled model filled
// with its parameters, and the runtime settings, loaded from files. Start-up only.
#pragma once

#include <string>
#include <vector>

#include "chaincomp/daemon_config.hpp"
#include "chaincomp/params_io.hpp"

namespace chaincomp {

struct LoadedModel {
  const ModelEntry* entry = nullptr;
  std::vector<double> params;         // internal units, kParams order
  VaryingErrors varying;              // tables and polynomials: the model points at it
  DaemonConfig config;
  std::vector<unsigned char> storage;  // the model object, sized and aligned for it
  void* model = nullptr;

  LoadedModel() = default;
  LoadedModel(const LoadedModel&) = delete;  // the model holds a pointer into `varying`
  LoadedModel& operator=(const LoadedModel&) = delete;
};

// Opens the machine's model (open_model.hpp: compiled in, cached or built now, or the library
// `model_path` when not empty), loads the params and the runtime config (empty path:
// defaults) and prepares the model. On failure returns false with `error` naming the file.
bool load_model(const std::string& machine_path, const std::string& model_path, const std::string& params_path,
                const std::string& config_path, LoadedModel& out, std::string& error);

}  // namespace chaincomp
