// The params loader on any bytes, for the five_axis_ac model: either a clean refusal naming
// the file, or values that are all finite and within 1e15 internal units.
#include <cmath>
#include <cstdint>
#include <cstdlib>

#include "chaincomp/model_info.hpp"
#include "chaincomp/params_io.hpp"
#include "fuzz_file.hpp"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  static const chaincomp::ModelEntry* entry = chaincomp::find_model("five_axis_ac");
  if (entry == nullptr) std::abort();
  const std::string path = chaincomp_fuzz::as_file(data, size);
  std::vector<double> values;
  chaincomp::VaryingErrors varying;
  std::string error;
  if (chaincomp::load_params(*entry->info, path, values, varying, error)) {
    for (double v : values) {
      if (!(std::fabs(v) <= 1e15)) std::abort();  // finite, and within the loaders' bound
    }
  } else if (error.rfind(path + ":", 0) != 0) {
    std::abort();  // every refusal names the file (a key written with "\n" in it still
                   // breaks the line, in the Python loader's messages too)
  }
  return 0;
}
