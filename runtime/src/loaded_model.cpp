#include "chaincomp/loaded_model.hpp"

#include "chaincomp/open_model.hpp"

namespace chaincomp {

bool load_model(const std::string& machine_path, const std::string& model_path, const std::string& params_path,
                const std::string& config_path, LoadedModel& out, std::string& error) {
  out.entry = open_model(machine_path, model_path, error);
  if (out.entry == nullptr) return false;
  const ModelEntry& e = *out.entry;
  if (!load_params(*e.info, params_path, out.params, out.varying, error)) return false;
  if (!load_daemon_config(*e.info, config_path, out.config, error)) return false;
  out.model = aligned_slot(out.storage, e.model_size, e.model_align);
  e.prepare(out.params.data(), out.model);
  if (out.varying.count > 0) e.attach_varying(out.model, &out.varying);
  return true;
}

}  // namespace chaincomp
