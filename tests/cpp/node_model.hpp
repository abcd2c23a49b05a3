// The set-up of the node tests: a machine's generated model prepared with its constants at
// their nominal values and every error at `error` (internal units), and the daemon's default
// configuration for it.
#pragma once

#include <catch2/catch.hpp>

#include <string>
#include <vector>

#include "chaincomp/daemon_config.hpp"
#include "chaincomp/model_info.hpp"

inline void prepare_node_model(const chaincomp::ModelEntry& entry, unsigned char* model,
                               chaincomp::DaemonConfig& config, double error = 0.0) {
  std::vector<double> params(entry.info->num_params);
  for (int i = 0; i < entry.info->num_params; ++i) {
    params[i] = entry.info->params[i].role == chaincomp::ParamRole::kError ? error : entry.info->params[i].nominal;
  }
  entry.prepare(params.data(), model);
  std::string why;
  REQUIRE(chaincomp::load_daemon_config(*entry.info, "", config, why));
}
