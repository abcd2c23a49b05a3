// Loading a machine's compiled model and its parameter values from files (start-up only:
// uses yaml-cpp and the heap; never included by real-time code).
#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include "chaincomp/model_info.hpp"
#include "chaincomp/varying.hpp"

namespace chaincomp {

// A content hash as the 16 hex digits the generated files, messages and status show.
std::string hash_hex(std::uint64_t hash);
// The content hash of a file (FNV-1a 64), in hex; empty when it cannot be read.
std::string file_hash_hex(const std::string& path);

// The content of the machine file at `path` and its `name` (parsed as YAML); false with
// `error` naming the file.
bool read_machine_file(const std::string& path, std::string& text, std::string& name, std::string& error);

// The compiled-in model of machine `name` when it was generated from exactly `text` (by
// content hash), else nullptr.
const ModelEntry* find_compiled_model(const std::string& name, const std::string& text) noexcept;

// The compiled-in model for the machine file at `path`: reads its `name`, finds the model
// in the registry and checks the file's content hash against the one it was generated from.
// On failure returns nullptr and sets `error` to a message naming the file. (chaincompd and
// replay use open_model, which also takes models built at run time: open_model.hpp.)
const ModelEntry* open_machine(const std::string& path, std::string& error);

// Parameter values (internal units, kParams order) from a params file: nominal values for
// constants and 0 for errors the file does not list. Unknown names, axes, null or non-finite
// values, unparsable text and units of the wrong kind are errors naming file, line and key.
// An error may also vary along an axis (a table or a polynomial, docs/reference/varying.md, "Errors that
// vary along an axis"): it goes into `varying` (emptied first; its value in `values` is 0), and
// every mistake in a table is an error naming file, line and key as well.
bool load_params(const MachineInfo& info, const std::string& path, std::vector<double>& values,
                 VaryingErrors& varying, std::string& error);

// "18 errors vary along an axis: 18 tables (1818 points), 0 polynomials" (empty for none).
std::string describe_varying(const VaryingErrors& varying);

// Constant values only: a file with tables or polynomials is refused.
bool load_params(const MachineInfo& info, const std::string& path, std::vector<double>& values,
                 std::string& error);

}  // namespace chaincomp
