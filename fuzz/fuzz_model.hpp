// The model the daemon-path fuzzers run: five_axis_ac with its demo params, loaded once per
// process as chaincompd loads it (a failure to load is the harness's bug: abort).
#pragma once

#include <cstdio>
#include <cstdlib>
#include <string>

#include "chaincomp/loaded_model.hpp"

namespace chaincomp_fuzz {

inline chaincomp::LoadedModel& demo_model() {
  static chaincomp::LoadedModel loaded;
  static bool ready = false;
  if (!ready) {
    std::string error;
    const std::string dir = CHAINCOMP_SOURCE_DIR "/configs/";
    if (!chaincomp::load_model(dir + "machines/five_axis_ac.yaml", "", dir + "params/five_axis_ac-demo.yaml", "",
                               loaded, error)) {
      std::fprintf(stderr, "%s\n", error.c_str());
      std::abort();
    }
    ready = true;
  }
  return loaded;
}

}  // namespace chaincomp_fuzz
