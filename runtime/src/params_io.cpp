#include "chaincomp/params_io.hpp"

#include <yaml-cpp/yaml.h>

#include <sys/stat.h>

#include <cerrno>
#include <cmath>
#include <cstring>
#include <regex>
#include <cstdio>
#include <cstdlib>
#include <fstream>
#include <sstream>

#include "chaincomp/hash.hpp"
#include "chaincomp/yaml_strict.hpp"

namespace chaincomp {

namespace {

std::string where(const std::string& path, const YAML::Node& node, const std::string& key) {
  std::string s = path;
  if (node.Mark().line >= 0) s += ":" + std::to_string(node.Mark().line + 1);
  return s + ": " + key + ": ";
}

const char* kind_name(UnitKind k) {
  return k == UnitKind::kLength ? "length" : k == UnitKind::kAngle ? "angle" : "ratio";
}

// "12.5", "12.5 um", "-3arcsec", 12.5: the value in internal units of a parameter, with the
// checks and messages of chaincomp/model/params.py's parse_value, in its order.
bool parse_value(const ParamInfo& p, const YAML::Node& node, double& out, std::string& why) {
  static const std::regex value_re(
      "\\s*([-+]?(?:[0-9]+\\.?[0-9]*|\\.[0-9]+)(?:[eE][-+]?[0-9]+)?)\\s*([^\\s0-9].*?)?\\s*");
  const Yaml11 kind = resolve(node);
  double v = 0, factor = p.to_internal;
  UnitKind unit_kind = p.kind;
  std::string unit_name = p.unit;
  if (kind == Yaml11::kBool) {
    why = "expected a number, got " + py_repr(node);
    return false;
  }
  if (!yaml_number(node, v)) {
    std::smatch m;
    const std::string& text = node.Scalar();
    if (!std::regex_match(text, m, value_re)) {
      why = "expected a number optionally followed by a unit, got " + py_repr(node);
      return false;
    }
    v = std::strtod(m[1].str().c_str(), nullptr);
    if (m[2].matched) {
      const UnitInfo* u = find_unit(m[2].str().c_str());
      if (u == nullptr) {
        why = "unknown unit '" + m[2].str() + "'";
        return false;
      }
      factor = u->to_internal;
      unit_kind = u->kind;
      unit_name = u->name;
    }
  }
  if (!std::isfinite(v)) {
    why = "expected a finite number, got " + py_repr(node);
    return false;
  }
  if (unit_kind != p.kind) {
    why = std::string("unit '") + unit_name + (unit_kind == UnitKind::kAngle ? "' is an " : "' is a ") +
          kind_name(unit_kind) + " unit but " + p.name +
          " is declared in '" + p.unit + "' (" + kind_name(p.kind) + ")";
    return false;
  }
  out = v * factor;
  // the Python loader's bound on any number (chaincomp/model/expressions.py MAX_LITERAL): it also
  // refuses values that overflow in the conversion (1e308 m)
  if (!(std::fabs(out) <= 1e15)) {
    why = py_repr(node) + " is larger than 1e+15 " +
          (p.kind == UnitKind::kLength ? "mm" : p.kind == UnitKind::kAngle ? "rad" : "1") + " in magnitude";
    return false;
  }
  return true;
}

const char* a_kind(UnitKind k) {
  return k == UnitKind::kLength ? "a length" : k == UnitKind::kAngle ? "an angle" : "a ratio";
}

// A mapping key as Python's str() shows it (load_strict_yaml let only scalar keys through).
std::string key_text(const YAML::Node& key) { return key.IsScalar() ? key.Scalar() : "None"; }

int line_of(const YAML::Node& n) { return n.Mark().line >= 0 ? n.Mark().line + 1 : 0; }

std::string at(const std::string& path, int line, const std::string& key) {
  return path + (line > 0 ? ":" + std::to_string(line) : std::string()) + ": " + key + ": ";
}

// A plain YAML number, as chaincomp/model/varying.py's _number takes it.
bool number(const YAML::Node& n, double& out, std::string& why) {
  if (!yaml_number(n, out)) {
    why = "expected a number, got " + describe(n);
    return false;
  }
  if (!std::isfinite(out)) {
    why = "expected finite numbers, got " + py_repr(n);
    return false;
  }
  return true;
}

// One error given as a table or a polynomial over one axis (the Python loader,
// chaincomp/model/varying.py, takes the same format with the same messages).
bool load_varying(const MachineInfo& info, int param, const std::string& path, const YAML::Node& keynode,
                  const YAML::Node& node, VaryingErrors& varying, std::string& error) {
  const ParamInfo& p = info.params[param];
  const std::string base = std::string("values.") + p.name;
  auto fail = [&](const YAML::Node& where_node, const std::string& key, const std::string& why) {
    error = at(path, line_of(where_node), key) + why;
    return false;
  };
  if (p.role != ParamRole::kError) {
    return fail(keynode, base, std::string("only error symbols may vary along an axis; '") + p.name +
                                   "' is a constant");
  }
  const bool is_table = static_cast<bool>(node["table"]), is_poly = static_cast<bool>(node["polynomial"]);
  if (is_table == is_poly) {
    return fail(keynode, base, is_table ? "give either 'table' or 'polynomial', not both"
                                        : "expected a number, or a mapping with 'table' or 'polynomial'");
  }
  const char* const table_keys[] = {"axis", "units", "interpolation", "outside", "table"};
  const char* const poly_keys[] = {"axis", "units", "polynomial", "range", "outside"};
  for (const auto& kv : node) {
    const std::string key = key_text(kv.first);
    bool known = false;
    for (const char* k : is_table ? table_keys : poly_keys) known = known || key == k;
    if (!known) {
      return fail(kv.first, base + "." + key,
                  "unknown field " + py_repr(kv.first) + " (expected one of: " +
                      (is_table ? "axis, interpolation, outside, table, units" : "axis, outside, polynomial, range, units") +
                      ")");
    }
  }
  auto key_node = [&](const char* key) {
    for (const auto& kv : node) {
      if (key_text(kv.first) == key) return kv.first;
    }
    return keynode;
  };
  // axis
  if (!node["axis"]) return fail(keynode, base, "missing required field 'axis'");
  const bool axis_text = resolve(node["axis"]) == Yaml11::kStr;
  const std::string axis_name = axis_text ? node["axis"].Scalar() : "";
  int axis = -1;
  std::string names;
  for (int i = 0; i < info.num_axes; ++i) {
    if (axis_name == info.axes[i].name) axis = i;
    names += std::string(i ? ", " : "") + info.axes[i].name;
  }
  if (axis < 0) {
    return fail(key_node("axis"), base + ".axis", (axis_text ? py_repr(node["axis"]) : describe(node["axis"])) +
                                                       " is not an axis of " + info.name + " (axes: " + names + ")");
  }
  const AxisInfo& a = info.axes[axis];
  // units: [position unit, value unit]
  const YAML::Node units = node["units"];
  if (!units) return fail(keynode, base, "missing required field 'units' ([position unit, value unit], e.g. [mm, um])");
  if (!units.IsSequence() || units.size() != 2 || resolve(units[0]) != Yaml11::kStr ||
      resolve(units[1]) != Yaml11::kStr) {
    return fail(key_node("units"), base + ".units",
                "expected [position unit, value unit], e.g. [mm, um], got " + describe(units));
  }
  const UnitInfo* pu = find_unit(units[0].Scalar().c_str());
  const UnitInfo* vu = find_unit(units[1].Scalar().c_str());
  if (pu == nullptr || vu == nullptr) {
    return fail(key_node("units"), base + ".units", "unknown unit '" + (pu ? units[1] : units[0]).Scalar() + "'");
  }
  if (pu->kind != a.kind) {
    return fail(key_node("units"), base + ".units",
                std::string("position unit '") + pu->name + "' is " + a_kind(pu->kind) + " unit, but axis " + a.name +
                    " is " + a_kind(a.kind) + " (declared in '" + a.unit + "')");
  }
  if (vu->kind != p.kind) {
    return fail(key_node("units"), base + ".units",
                std::string("value unit '") + vu->name + "' is " + a_kind(vu->kind) + " unit, but " + p.name + " is " +
                    a_kind(p.kind) + " (declared in '" + p.unit + "')");
  }
  int column = 0;
  for (int i = 0; i < param; ++i) column += info.params[i].role == ParamRole::kError;
  // outside
  Outside outside = Outside::kHold;
  const bool has_range = is_poly && node["range"];
  if (is_table || has_range) {
    if (!node["outside"]) return fail(keynode, base, "missing required field 'outside' (hold or reject)");
    const std::string o = resolve(node["outside"]) == Yaml11::kStr ? node["outside"].Scalar() : "";
    if (o != "hold" && o != "reject") {
      return fail(key_node("outside"), base + ".outside", "outside must be hold or reject, got " + describe(node["outside"]));
    }
    outside = o == "hold" ? Outside::kHold : Outside::kReject;
  } else if (node["outside"]) {
    return fail(key_node("outside"), base + ".outside",
                "'outside' applies to a polynomial's 'range' (give range: [low, high] in the position unit)");
  }
  std::string why;
  int bad = -1;
  if (is_table) {
    if (!node["interpolation"]) {
      return fail(keynode, base, "missing required field 'interpolation' (linear or monotone_cubic)");
    }
    const std::string it = resolve(node["interpolation"]) == Yaml11::kStr ? node["interpolation"].Scalar() : "";
    if (it != "linear" && it != "monotone_cubic") {
      return fail(key_node("interpolation"), base + ".interpolation",
                  "interpolation must be linear or monotone_cubic, got " + describe(node["interpolation"]));
    }
    const YAML::Node rows = node["table"];
    if (!rows.IsSequence()) {
      return fail(key_node("table"), base + ".table", "expected a list of [position, value] rows, got " + describe(rows));
    }
    const int n = static_cast<int>(rows.size());
    if (n < 2 || n > kMaxTableKnots) {
      return fail(key_node("table"), base + ".table",
                  n < 2 ? "a table needs at least 2 points, got " + std::to_string(n)
                        : "a table holds at most " + std::to_string(kMaxTableKnots) + " points, got " + std::to_string(n));
    }
    std::vector<double> x(n), y(n);
    for (int i = 0; i < n; ++i) {
      const YAML::Node row = rows[i];
      const std::string key = base + ".table[" + std::to_string(i) + "]";
      if (!row.IsSequence() || row.size() != 2) return fail(row, key, "expected [position, value], got " + describe(row));
      if (!number(row[0], x[i], why) || !number(row[1], y[i], why)) return fail(row, key, why);
      x[i] *= pu->to_internal;
      y[i] *= vu->to_internal;
      if (!std::isfinite(x[i]) || !std::isfinite(y[i])) return fail(row, key, "not finite in internal units (mm, rad)");
    }
    if (!add_table(varying, param, column, axis, x.data(), y.data(), n,
                   it == "linear" ? Interpolation::kLinear : Interpolation::kMonotoneCubic, outside, why, bad)) {
      // back to the declared units for the message
      if (bad >= 0) {
        const YAML::Node row = rows[bad];
        if (why.rfind("duplicate", 0) == 0) why = "duplicate position " + py_repr(row[0]);
        else if (why.rfind("positions", 0) == 0) why = "positions must increase: " + py_repr(row[0]) + " follows " +
                                                       py_repr(rows[bad - 1][0]);
        return fail(row, base + ".table[" + std::to_string(bad) + "]", why);
      }
      return fail(key_node("table"), base + ".table", why);
    }
    return true;
  }
  const YAML::Node coeffs = node["polynomial"];
  if (!coeffs.IsSequence() || coeffs.size() < 1 || coeffs.size() > static_cast<std::size_t>(kMaxPolynomialCoefficients)) {
    return fail(key_node("polynomial"), base + ".polynomial",
                "expected a list of 1 to " + std::to_string(kMaxPolynomialCoefficients) +
                    " coefficients [c0, c1, ...] (c0 + c1*x + ...), got " + describe(coeffs));
  }
  std::vector<double> c(coeffs.size());
  for (std::size_t i = 0; i < coeffs.size(); ++i) {
    if (!number(coeffs[i], c[i], why)) return fail(coeffs[i], base + ".polynomial[" + std::to_string(i) + "]", why);
  }
  double lower = -INFINITY, upper = INFINITY;
  if (has_range) {
    const YAML::Node r = node["range"];
    if (!r.IsSequence() || r.size() != 2) {
      return fail(key_node("range"), base + ".range", "expected [low, high] in the position unit, got " + describe(r));
    }
    if (!number(r[0], lower, why) || !number(r[1], upper, why)) return fail(key_node("range"), base + ".range", why);
    if (!(lower < upper)) {
      return fail(key_node("range"), base + ".range", "low " + py_repr(r[0]) + " must be below high " + py_repr(r[1]));
    }
    lower *= pu->to_internal;
    upper *= pu->to_internal;
  }
  if (!add_polynomial(varying, param, column, axis, c.data(), static_cast<int>(c.size()), 1.0 / pu->to_internal,
                      vu->to_internal, lower, upper, outside, why, bad)) {
    return fail(key_node("polynomial"), base + ".polynomial", why);
  }
  return true;
}

}  // namespace

std::string hash_hex(std::uint64_t hash) {
  char buf[17];
  std::snprintf(buf, sizeof buf, "%016llx", static_cast<unsigned long long>(hash));
  return buf;
}

std::string file_hash_hex(const std::string& path) {
  std::string text, error;
  if (!read_input_file(path, text, error)) return "";
  return hash_hex(fnv1a64(reinterpret_cast<const unsigned char*>(text.data()), text.size()));
}

bool read_machine_file(const std::string& path, std::string& text, std::string& name, std::string& error) {
  YAML::Node doc;
  if (!read_input_file(path, text, error) || !load_strict_yaml(path, text, doc, error)) return false;
  if (!doc.IsMap() || !doc["name"] || !doc["name"].IsScalar()) {
    error = path + ": name: missing machine name";
    return false;
  }
  name = doc["name"].as<std::string>();
  return true;
}

const ModelEntry* find_compiled_model(const std::string& name, const std::string& text) noexcept {
  const ModelEntry* entry = find_model(name.c_str());
  const auto hash = fnv1a64(reinterpret_cast<const unsigned char*>(text.data()), text.size());
  return entry != nullptr && entry->info->source_hash == hash ? entry : nullptr;
}

const ModelEntry* open_machine(const std::string& path, std::string& error) {
  std::string text, name;
  if (!read_machine_file(path, text, name, error)) return nullptr;
  const ModelEntry* entry = find_model(name.c_str());
  if (entry == nullptr) {
    error = path + ": name: no compiled model for machine '" + name + "' (build one with chaincomp build)";
    return nullptr;
  }
  const auto hash = fnv1a64(reinterpret_cast<const unsigned char*>(text.data()), text.size());
  if (hash != entry->info->source_hash) {
    error = path + ": the machine file changed since its model was compiled (hash " + hash_hex(hash) +
            " differs from the compiled " + entry->info->source_file +
            "): rebuild with tools/setup, or build its model at run time with chaincomp build";
    return nullptr;
  }
  return entry;
}

bool load_params(const MachineInfo& info, const std::string& path, std::vector<double>& values,
                 VaryingErrors& varying, std::string& error) {
  varying.count = 0;
  varying.storage.clear();
  values.assign(info.num_params, 0.0);
  for (int i = 0; i < info.num_params; ++i) values[i] = info.params[i].nominal;
  std::string text;
  YAML::Node doc;
  if (!read_input_file(path, text, error) || !load_strict_yaml(path, text, doc, error)) return false;
  if (!doc.IsMap()) {
    error = path + ":1: expected a mapping with 'values'";
    return false;
  }
  auto key_of = [&](const char* name) {  // the key node, for its line
    for (const auto& kv : doc) {
      if (key_text(kv.first) == name) return kv.first;
    }
    return YAML::Node();
  };
  for (const auto& kv : doc) {
    const std::string key = key_text(kv.first);
    if (key != "machine" && key != "values" && key != "description") {
      error = where(path, kv.first, key) + "unknown field " + py_repr(kv.first) +
              " (expected machine, values, description)";
      return false;
    }
  }
  if (const YAML::Node m = doc["machine"]) {
    if (resolve(m) != Yaml11::kStr) {
      error = where(path, key_of("machine"), "machine") + "expected the machine's name, got " + describe(m);
      return false;
    }
    if (m.Scalar() != info.name) {
      error = where(path, key_of("machine"), "machine") + "params are for machine " + py_repr(m) + ", not '" +
              info.name + "'";
      return false;
    }
  }
  const YAML::Node vals = doc["values"];
  if (!vals || !vals.IsMap()) {
    error = path + ":" + std::to_string(vals ? line_of(key_of("values")) : 1) +
            ": values: expected a mapping of symbol names to values";
    return false;
  }
  for (const auto& kv : vals) {
    const std::string name = key_text(kv.first);
    const std::string key = "values." + name;
    const bool text = resolve(kv.first) == Yaml11::kStr;
    int index = -1;
    bool is_axis = false;
    for (int i = 0; i < info.num_params; ++i) {
      if (text && name == info.params[i].name) index = i;
    }
    for (int i = 0; i < info.num_axes; ++i) is_axis = is_axis || (text && name == info.axes[i].name);
    if (index < 0) {
      error = where(path, kv.first, key) +
              (is_axis ? py_repr(kv.first) + " is an axis: axis values are commands, not parameters"
                       : "unknown symbol " + py_repr(kv.first) + " for machine '" + info.name + "'");
      return false;
    }
    if (kv.second.IsMap()) {
      if (!load_varying(info, index, path, kv.first, kv.second, varying, error)) return false;
      values[index] = 0.0;
      continue;
    }
    if (kv.second.IsSequence()) {
      error = where(path, kv.first, key) + "expected a number, or a mapping with 'table' or 'polynomial'";
      return false;
    }
    if (!kv.second.IsScalar()) {
      error = where(path, kv.first, key) + "missing value";
      return false;
    }
    std::string why;
    if (!parse_value(info.params[index], kv.second, values[index], why)) {
      error = where(path, kv.first, key) + why;
      return false;
    }
  }
  return true;
}

std::string describe_varying(const VaryingErrors& varying) {
  if (varying.count == 0) return "";
  int tables = 0, points = 0;
  for (int i = 0; i < varying.count; ++i) {
    if (varying.items[i].kind == VaryingKind::kTable) {
      ++tables;
      points += varying.items[i].count;
    }
  }
  const int polys = varying.count - tables;
  return std::to_string(varying.count) + (varying.count == 1 ? " error varies" : " errors vary") +
         " along an axis: " + std::to_string(tables) + (tables == 1 ? " table (" : " tables (") +
         std::to_string(points) + " points), " + std::to_string(polys) + (polys == 1 ? " polynomial" : " polynomials");
}

bool load_params(const MachineInfo& info, const std::string& path, std::vector<double>& values,
                 std::string& error) {
  VaryingErrors varying;
  if (!load_params(info, path, values, varying, error)) return false;
  if (varying.count > 0) {
    error = path + ": values." + info.params[varying.items[0].param].name +
            ": an error that varies along an axis needs a loader that keeps it (VaryingErrors)";
    return false;
  }
  return true;
}

}  // namespace chaincomp
