#include "chaincomp/params_io.hpp"

#include <yaml-cpp/yaml.h>

#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <fstream>
#include <sstream>

#include "chaincomp/hash.hpp"

namespace chaincomp {

namespace {

std::string where(const std::string& path, const YAML::Node& node, const std::string& key) {
  std::string s = path;
  if (node.Mark().line >= 0) s += ":" + std::to_string(node.Mark().line + 1);
  return s + ": " + key + ": ";
}

bool read_file(const std::string& path, std::string& text, std::string& error) {
  std::ifstream in(path, std::ios::binary);
  if (!in) {
    error = path + ": cannot read file";
    return false;
  }
  std::ostringstream ss;
  ss << in.rdbuf();
  text = ss.str();
  return true;
}

bool load_yaml(const std::string& path, const std::string& text, YAML::Node& doc, std::string& error) {
  try {
    doc = YAML::Load(text);
  } catch (const YAML::Exception& e) {
    error = path + ":" + std::to_string(e.mark.line + 1) + ": YAML syntax error: " + e.msg;
    return false;
  }
  return true;
}

const char* kind_name(UnitKind k) {
  return k == UnitKind::kLength ? "length" : k == UnitKind::kAngle ? "angle" : "ratio";
}

// "12.5", "12.5 um", "-3arcsec": the value in internal units of a parameter.
bool parse_value(const ParamInfo& p, const std::string& text, double& out, std::string& why) {
  const char* s = text.c_str();
  char* end = nullptr;
  const double v = std::strtod(s, &end);
  if (end == s) {
    why = "expected a number optionally followed by a unit, got '" + text + "'";
    return false;
  }
  std::string unit(end);
  unit.erase(0, unit.find_first_not_of(" \t"));
  unit.erase(unit.find_last_not_of(" \t") + 1);
  double factor = p.to_internal;
  if (!unit.empty()) {
    const UnitInfo* u = find_unit(unit.c_str());
    if (u == nullptr) {
      why = "unknown unit '" + unit + "'";
      return false;
    }
    if (u->kind != p.kind) {
      why = std::string("unit '") + unit + "' is a " + kind_name(u->kind) + " unit but " + p.name +
            " is declared in '" + p.unit + "' (" + kind_name(p.kind) + ")";
      return false;
    }
    factor = u->to_internal;
  }
  if (!std::isfinite(v)) {
    why = "expected a finite number, got '" + text + "'";
    return false;
  }
  out = v * factor;
  return true;
}

}  // namespace

const ModelEntry* open_machine(const std::string& path, std::string& error) {
  std::string text;
  YAML::Node doc;
  if (!read_file(path, text, error) || !load_yaml(path, text, doc, error)) return nullptr;
  if (!doc.IsMap() || !doc["name"] || !doc["name"].IsScalar()) {
    error = path + ": name: missing machine name";
    return nullptr;
  }
  const std::string name = doc["name"].as<std::string>();
  const ModelEntry* entry = find_model(name.c_str());
  if (entry == nullptr) {
    error = where(path, doc["name"], "name") + "no compiled model for machine '" + name +
            "' (models are generated from configs/machines/ at build time: add the file there and rebuild)";
    return nullptr;
  }
  const auto hash = fnv1a64(reinterpret_cast<const unsigned char*>(text.data()), text.size());
  if (hash != entry->info->source_hash) {
    char buf[64];
    std::snprintf(buf, sizeof buf, "%016llx", static_cast<unsigned long long>(hash));
    error = path + ": the machine file changed since its model was compiled (hash " + buf +
            " differs from the compiled " + entry->info->source_file + "); rebuild with tools/setup";
    return nullptr;
  }
  return entry;
}

bool load_params(const MachineInfo& info, const std::string& path, std::vector<double>& values,
                 std::string& error) {
  values.assign(info.num_params, 0.0);
  for (int i = 0; i < info.num_params; ++i) values[i] = info.params[i].nominal;
  std::string text;
  YAML::Node doc;
  if (!read_file(path, text, error) || !load_yaml(path, text, doc, error)) return false;
  if (!doc.IsMap()) {
    error = path + ": expected a mapping with 'values'";
    return false;
  }
  for (const auto& kv : doc) {
    const std::string key = kv.first.as<std::string>();
    if (key != "machine" && key != "values" && key != "description") {
      error = where(path, kv.first, key) + "unknown field (expected machine, values, description)";
      return false;
    }
  }
  if (doc["machine"] && doc["machine"].as<std::string>() != info.name) {
    error = where(path, doc["machine"], "machine") + "params are for machine '" +
            doc["machine"].as<std::string>() + "', not '" + info.name + "'";
    return false;
  }
  const YAML::Node vals = doc["values"];
  if (!vals || !vals.IsMap()) {
    error = path + ": values: expected a mapping of symbol names to values";
    return false;
  }
  for (const auto& kv : vals) {
    const std::string name = kv.first.as<std::string>();
    const std::string key = "values." + name;
    int index = -1;
    for (int i = 0; i < info.num_params; ++i) {
      if (name == info.params[i].name) index = i;
    }
    if (index < 0) {
      bool is_axis = false;
      for (int i = 0; i < info.num_axes; ++i) is_axis = is_axis || name == info.axes[i].name;
      error = where(path, kv.first, key) +
              (is_axis ? "'" + name + "' is an axis: axis values are commands, not parameters"
                       : "unknown symbol '" + name + "' for machine '" + info.name + "'");
      return false;
    }
    if (!kv.second.IsScalar() || kv.second.IsNull()) {
      error = where(path, kv.first, key) + "missing value";
      return false;
    }
    std::string why;
    if (!parse_value(info.params[index], kv.second.Scalar(), values[index], why)) {
      error = where(path, kv.first, key) + why;
      return false;
    }
  }
  return true;
}

}  // namespace chaincomp
