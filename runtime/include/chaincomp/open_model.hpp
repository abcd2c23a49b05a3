// Finding the model of a machine file at start-up: compiled in, cached from an earlier
// `chaincomp build`, built now, or given as a prebuilt library (--model). Start-up only:
// reads files, runs the compiler and the code generator, allocates.
#pragma once

#include <string>

#include "chaincomp/model_info.hpp"

namespace chaincomp {

// The key of runtime-built models besides the machine file: "chaincomp model abi N", the
// first line of `CXX --version` and the flags, one per line (the Python build writes the
// same). Empty, with `error`, when the compiler is missing.
std::string model_toolchain(std::string& error);

// Where runtime-built models are cached: $XDG_CACHE_HOME/chaincomp, default ~/.cache/chaincomp.
std::string model_cache_root(std::string& error);

// The cached library for machine `name` with file content `text` built by `toolchain`:
// ROOT/NAME-HASH-TOOLCHAINHASH/NAME.so.
std::string model_cache_path(const std::string& root, const std::string& name, const std::string& text,
                             const std::string& toolchain);

// dlopens the library at `path` and checks it is the model of the machine file
// `machine_path` whose content is `text` and name `name`: ABI, structure sizes, name, hash and the whole
// text, and the toolchain unless `toolchain` is null. It stays loaded for the process.
// On failure returns nullptr with one line in `error` naming the library.
const ModelEntry* load_model_library(const std::string& path, const std::string& machine_path,
                                     const std::string& name, const std::string& text, const std::string* toolchain,
                                     std::string& error);

// The model of the machine file at `machine_path`: with `library_path` (--model) that
// prebuilt library; otherwise the compiled-in model when name and content hash match, else
// the cached runtime-built one, built first by `chaincomp build` (progress on stderr) when
// the cache has none.
const ModelEntry* open_model(const std::string& machine_path, const std::string& library_path, std::string& error);

}  // namespace chaincomp
