#include "chaincomp/thermal.hpp"

#include <cmath>
#include <cstdio>
#include <fstream>
#include <regex>
#include <sstream>

#include "chaincomp/lcm_wire.hpp"
#include "chaincomp/yaml_strict.hpp"

namespace chaincomp {

namespace {

// measure/thermal.py's bounds
constexpr double kMaxTimeConstant = 1e6;
constexpr double kMaxGain = 1e6;
constexpr double kMaxLiteral = 1e15;
constexpr double kLowest = -100.0, kHighest = 300.0;   // degC

std::string g(double v) {   // Python's format(v, 'g')
  char buf[32];
  std::snprintf(buf, sizeof buf, "%g", v);
  return buf;
}

std::string key_text(const YAML::Node& key) { return key.IsScalar() ? key.Scalar() : "None"; }

int line_of(const YAML::Node& n) { return n.Mark().line >= 0 ? n.Mark().line + 1 : 0; }

// The messages of measure/thermal.py's load_model, word for word.
struct Loader {
  const std::string& path;
  std::string& error;

  bool fail(int line, const std::string& field, const std::string& why) {
    error = path + (line > 0 ? ":" + std::to_string(line) : std::string()) + ": " + (field.empty() ? "" : field + ": ") + why;
    return false;
  }
  YAML::Node key(const YAML::Node& map, const std::string& name) {
    for (const auto& kv : map) {
      if (key_text(kv.first) == name) return kv.first;
    }
    return map;
  }
  bool keys(const YAML::Node& map, std::initializer_list<const char*> allowed, std::initializer_list<const char*> required,
            const std::string& where) {
    std::string list;
    for (const char* a : allowed) list += (list.empty() ? "" : ", ") + std::string(a);
    for (const auto& kv : map) {
      bool known = false;
      for (const char* a : allowed) known = known || (resolve(kv.first) == Yaml11::kStr && kv.first.Scalar() == a);
      if (!known)
        return fail(line_of(kv.first), key_text(kv.first),
                    "unknown key " + py_repr(kv.first) + " in " + where + " (expected: " + list + ")");
    }
    for (const char* r : required) {
      if (!map[r]) return fail(line_of(map), "", where + " needs '" + r + "'");
    }
    return true;
  }
  bool number(const YAML::Node& map, const char* name, const std::string& what, double lo, double hi, double& out) {
    const YAML::Node v = map[name];
    const int line = line_of(key(map, name));
    if (!yaml_number(v, out)) return fail(line, name, "expected a number (" + what + "), got " + describe(v));
    if (!(lo <= out && out <= hi))
      return fail(line, name, py_float_repr(out) + " is outside [" + g(lo) + ", " + g(hi) + "] (" + what + ")");
    return true;
  }
};

const char* kind_word(UnitKind k) { return k == UnitKind::kLength ? "length" : k == UnitKind::kAngle ? "angle" : "ratio"; }
const char* article(UnitKind k) { return k == UnitKind::kAngle ? "an" : "a"; }

}  // namespace

bool load_thermal_model(const MachineInfo& info, const std::string& path, ThermalModel& out, std::string& error) {
  out = ThermalModel{};
  std::string text;
  YAML::Node doc;
  if (!read_input_file(path, text, error) || !load_strict_yaml(path, text, doc, error)) return false;
  Loader L{path, error};
  if (!doc.IsMap()) return L.fail(1, "", "expected a mapping with 'machine' and 'errors', got " + describe(doc));
  if (!L.keys(doc, {"machine", "reference_temperature", "errors"}, {"machine", "errors"}, "a thermal model")) return false;
  const YAML::Node name = doc["machine"];
  if (resolve(name) != Yaml11::kStr)
    return L.fail(line_of(L.key(doc, "machine")), "machine", "expected the machine's name, got " + describe(name));
  if (name.Scalar() != info.name)
    return L.fail(line_of(L.key(doc, "machine")), "machine",
                  "the model is of machine " + py_repr(name) + ", not '" + info.name + "'");
  out.machine = name.Scalar();
  if (doc["reference_temperature"] &&
      !L.number(doc, "reference_temperature", "degC", kLowest, kHighest, out.reference))
    return false;
  const YAML::Node errors = doc["errors"];
  const int errors_line = line_of(L.key(doc, "errors"));
  if (!errors.IsMap() || errors.size() == 0)
    return L.fail(errors_line, "errors", "expected a mapping of error names to their models, got " +
                                             (errors.IsMap() ? std::string("an empty mapping") : describe(errors)));
  if (errors.size() > static_cast<std::size_t>(kMaxThermalErrors))
    return L.fail(errors_line, "errors", std::to_string(errors.size()) + " errors: a thermal model holds at most " +
                                             std::to_string(kMaxThermalErrors));
  for (const auto& kv : errors) {
    const std::string err = key_text(kv.first);
    const int line = line_of(kv.first);
    int param = -1;
    for (int i = 0; i < info.num_params; ++i) {
      if (resolve(kv.first) == Yaml11::kStr && err == info.params[i].name && info.params[i].role == ParamRole::kError)
        param = i;
    }
    if (param < 0) return L.fail(line, err, py_repr(kv.first) + " is not an error of " + info.name);
    const YAML::Node node = kv.second;
    if (!node.IsMap())
      return L.fail(line, err, "expected a mapping with unit, offset and terms, got " + describe(node));
    if (!L.keys(node, {"unit", "offset", "terms"}, {"unit", "terms"}, "error " + err)) return false;
    const YAML::Node unit_node = node["unit"];
    const UnitInfo* unit = resolve(unit_node) == Yaml11::kStr ? find_unit(unit_node.Scalar().c_str()) : nullptr;
    const int unit_line = line_of(L.key(node, "unit"));
    if (unit == nullptr) return L.fail(unit_line, "unit", "expected a unit (um, arcsec, ppm, ...), got " + describe(unit_node));
    const ParamInfo& p = info.params[param];
    if (p.kind != unit->kind)
      return L.fail(unit_line, "unit", err + " is " + article(p.kind) + " " + kind_word(p.kind) + " in " + info.name +
                                           ", not " + article(unit->kind) + " " + kind_word(unit->kind));
    ThermalError& e = out.errors[out.num_errors++];
    e.param = param;
    e.name = p.name;
    const double limit = kMaxLiteral / unit->to_internal;
    double offset = 0;
    if (node["offset"] && !L.number(node, "offset", unit->name, -limit, limit, offset)) return false;
    e.offset = offset * unit->to_internal;
    const YAML::Node terms = node["terms"];
    if (!terms.IsSequence() || terms.size() < 1 || terms.size() > static_cast<std::size_t>(kMaxThermalTerms))
      return L.fail(line_of(L.key(node, "terms")), "terms", "expected a list of 1 to " + std::to_string(kMaxThermalTerms) +
                                                                " terms, got " + describe(terms));
    static const std::regex sensor_name("[A-Za-z_][A-Za-z0-9_]{0,31}");
    std::vector<std::pair<std::string, int>> seen;
    for (std::size_t i = 0; i < terms.size(); ++i) {
      const YAML::Node term = terms[i];
      const int tline = line_of(term);
      if (!term.IsMap())
        return L.fail(tline, "terms", "expected a term {sensor, gain, time_constant}, got " + describe(term));
      if (!L.keys(term, {"sensor", "gain", "time_constant"}, {"sensor", "gain"}, "a term")) return false;
      const YAML::Node sensor = term["sensor"];
      if (resolve(sensor) != Yaml11::kStr || !std::regex_match(sensor.Scalar(), sensor_name))
        return L.fail(line_of(L.key(term, "sensor")), "sensor",
                      "expected a sensor name (a letter or _, then letters, digits or _, at most 32), got " + describe(sensor));
      double gain, tau = 0;
      if (!L.number(term, "gain", std::string(unit->name) + "/K", -kMaxGain, kMaxGain, gain)) return false;
      if (term["time_constant"] && !L.number(term, "time_constant", "s, 0 for no lag", 0.0, kMaxTimeConstant, tau))
        return false;
      const std::string key = sensor.Scalar() + "@" + py_float_repr(tau);
      for (const auto& s : seen) {
        if (s.first == key)
          return L.fail(tline, "terms", "a second term of sensor " + sensor.Scalar() + " with time constant " + g(tau) +
                                            " s (the first on line " + std::to_string(s.second) + "): add their gains");
      }
      seen.emplace_back(key, tline);
      int index = 0;
      while (index < static_cast<int>(out.sensors.size()) && out.sensors[index] != sensor.Scalar()) ++index;
      if (index == static_cast<int>(out.sensors.size())) out.sensors.push_back(sensor.Scalar());
      ThermalTerm& t = e.terms[e.num_terms++];
      t.sensor = index;
      t.gain = gain * unit->to_internal;
      t.time_constant = tau;
    }
    if (out.sensors.size() > static_cast<std::size_t>(kMaxSensors))
      return L.fail(line, err, "more than " + std::to_string(kMaxSensors) + " sensors in the model");
  }
  return true;
}

bool decode_readings(const void* data, std::size_t size, std::int64_t fingerprint, Readings& out) noexcept {
  WireReader r{static_cast<const unsigned char*>(data), size};
  std::int64_t hash;
  std::int32_t n;
  if (!r.i64(hash) || hash != fingerprint || !r.i64(out.utime) || !r.str(out.machine) || !r.i32(n) || n < 1 ||
      n > kMaxReadings)
    return false;
  out.num_values = n;
  return r.names_then_values(n, out.names.data(), out.values.data());
}

ThermalState::ThermalState(const ThermalModel& model, const std::vector<double>& base)
    : model_(model), base_(base), last_u_(model.sensors.size(), 0.0),
      order_(model.sensors.size(), StreamOrder(kMaxTimeJump)), read_(model.sensors.size(), 0),
      settle_(model.sensors.size(), 1) {}

void ThermalState::reset() noexcept {
  for (std::size_t s = 0; s < order_.size(); ++s) {
    order_[s].reset();
    settle_[s] = 1;
  }
}

bool ThermalState::take(const Readings& r, std::string_view machine, ParamsUpdate& update) noexcept {
  ++received_;
  if (!r.machine.empty() && r.machine != machine) return refuse(ReadingRefuse::kWrongMachine);
  const int ns = static_cast<int>(model_.sensors.size());
  // check all first: a message is taken whole or not at all
  for (int i = 0; i < r.num_values; ++i) {
    slot_[i] = -1;
    for (int s = 0; s < ns; ++s) {
      if (r.names[i] == model_.sensors[s]) slot_[i] = s;
    }
    if (slot_[i] < 0) continue;   // another model's sensor
    if (!(r.values[i] >= kLowest && r.values[i] <= kHighest)) return refuse(ReadingRefuse::kBadValue);
    for (int k = 0; k < i; ++k) {
      if (slot_[k] == slot_[i]) return refuse(ReadingRefuse::kTimeNotIncreasing);   // twice at one time
    }
  }
  // each sensor's stream rule sees the message (a refused one counts in its restart run)
  bool in_order = true;
  for (int i = 0; i < r.num_values; ++i) {
    if (slot_[i] < 0) continue;
    verdict_[i] = order_[slot_[i]].judge(r.utime);
    in_order = in_order && StreamOrder::taken(verdict_[i]);
  }
  if (!in_order) return refuse(ReadingRefuse::kTimeNotIncreasing);
  for (int i = 0; i < r.num_values; ++i) {
    const int s = slot_[i];
    if (s < 0) continue;
    const double u = r.values[i];
    const bool settle = settle_[s] || verdict_[i] == StreamOrder::Verdict::kRestart;
    // (both int64: the difference exact, without overflow, and positive here unless settling)
    const double dt = settle ? 0.0 : static_cast<double>(ahead_by(order_[s].last(), r.utime)) * 1e-6;
    for (int e = 0; e < model_.num_errors; ++e) {
      const ThermalError& err = model_.errors[e];
      for (int k = 0; k < err.num_terms; ++k) {
        const ThermalTerm& term = err.terms[k];
        if (term.sensor != s) continue;
        double& y = lag_[e][k];
        if (settle || term.time_constant == 0) {
          y = u;   // settled at the first reading of a stream; no lag
          continue;
        }
        const double one_minus_e = -std::expm1(-dt / term.time_constant);
        const double slope = (u - last_u_[s]) / dt;
        y = u - slope * term.time_constant * one_minus_e + (1.0 - one_minus_e) * (y - last_u_[s]);
      }
    }
    last_u_[s] = u;
    order_[s].accept(r.utime);
    read_[s] = 1;
    settle_[s] = 0;
  }
  for (int s = 0; s < ns; ++s) {
    if (!read_[s]) return false;   // not every sensor read yet: nothing to apply
  }
  update.num_values = model_.num_errors;
  for (int e = 0; e < model_.num_errors; ++e) {
    const ThermalError& err = model_.errors[e];
    double v = base_[err.param] + err.offset;
    for (int k = 0; k < err.num_terms; ++k) v += err.terms[k].gain * (lag_[e][k] - model_.reference);
    update.names[e] = err.name;
    update.values[e] = v;
  }
  return true;
}

}  // namespace chaincomp
