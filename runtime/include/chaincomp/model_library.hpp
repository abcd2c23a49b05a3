// A model built at run time (`chaincomp build`): a shared library with one C entry point,
// chaincomp_model_library(), returning what identifies it and the same function table the
// compiled-in registry holds. Read by open_model() (model_library.cpp) before the first
// command; the table's functions are then called exactly as the registry's are.
#pragma once

#include <cstddef>
#include <cstdint>

#include "chaincomp/model_info.hpp"
#include "chaincomp/varying.hpp"

namespace chaincomp {

// Bump when ModelEntry, MachineInfo, AxisInfo, ParamInfo, VaryingErrors or ModelLibrary
// change meaning. The sizes in kModelLayout also refuse a library whose structures changed
// size while the number was forgotten. tools (CMake, chaincomp build) read this line.
// 3: compensate takes the direction weight and returns the command's own residual (before).
constexpr int kModelAbi = 3;

struct ModelLayout {
  std::uint32_t entry, info, axis, param, varying, varying_item;
};
constexpr ModelLayout kModelLayout = {sizeof(ModelEntry), sizeof(MachineInfo), sizeof(AxisInfo),
                                      sizeof(ParamInfo),  sizeof(VaryingErrors), sizeof(VaryingError)};

// `abi` first: a reader checks it before trusting anything after it.
struct ModelLibrary {
  int abi;
  ModelLayout layout;
  const char* name;            // the machine's name
  std::uint64_t source_hash;   // FNV-1a 64 of its machine file
  const char* source_text;     // the machine file, byte for byte (a load compares it whole)
  std::size_t source_size;
  const char* toolchain;       // model_toolchain() of the build: ABI, compiler, flags
  const ModelEntry* entry;
};

}  // namespace chaincomp

#define CHAINCOMP_MODEL_LIBRARY_SYMBOL "chaincomp_model_library"
extern "C" const chaincomp::ModelLibrary* chaincomp_model_library() noexcept;
