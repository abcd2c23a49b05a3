// YAML read the one way both of the project's loaders read it: the Python one
// (codegen/chaincomp/model/yamlsource.py, PyYAML, YAML 1.1) and this one (yaml-cpp, YAML 1.2) take
// the same documents to the same values, or refuse them with the same file:line: message.
// Refused here, before any value is read: explicit tags (!!str 12), merge keys (<<), keys
// that are lists or mappings, duplicate keys, numbers the two YAML versions read differently
// (0170 is octal 120 in YAML 1.1 and 170 in 1.2; 0x1f, 1_000, 1:30, +0b11 alike), duplicate
// or recursive anchors, more than one document, nesting deeper than 64 and alias bombs.
// Start-up only (heap, exceptions inside).
#pragma once

#include <yaml-cpp/yaml.h>

#include <string>

namespace chaincomp {

// The largest input file (yamlsource.MAX_FILE_BYTES).
constexpr std::size_t kMaxFileBytes = 16u << 20;
// An input file's text, as yamlsource.read_text reads it: a regular file (not a device, a FIFO
// or a folder) of at most kMaxFileBytes, read no further; false with `error` = "path: message".
bool read_input_file(const std::string& path, std::string& text, std::string& error);

// Parses `text` (read from `path`) into `doc`; false with `error` = "path:line: message".
bool load_strict_yaml(const std::string& path, const std::string& text, YAML::Node& doc, std::string& error);

// What PyYAML makes of a node: plain text resolved as YAML 1.1 does, quoted text a string;
// a list or a mapping is a collection.
enum class Yaml11 { kNull, kBool, kInt, kFloat, kStr, kCollection };
Yaml11 resolve(const YAML::Node& scalar);

// Python's repr() of what PyYAML makes of a scalar node ('text', 12, 1.5, inf, True, None),
// so messages that quote a value read the same from both loaders.
std::string py_repr(const YAML::Node& node);
// Python's repr() of a float (shortest text that reads back: 1e+16, 0.0001, 1e-05, inf).
std::string py_float_repr(double v);
// yamlsource.describe(): "a mapping", "a list of 2 items", "nothing", "str '12'", "bool True".
std::string describe(const YAML::Node& node);
// The scalar's value when PyYAML reads it as a number (int or float, .inf and .nan included).
bool yaml_number(const YAML::Node& node, double& out);

}  // namespace chaincomp
