#include "chaincomp/daemon_config.hpp"

#include <yaml-cpp/yaml.h>

#include "chaincomp/compensate.hpp"
#include "chaincomp/yaml_strict.hpp"

#include <algorithm>
#include <cerrno>
#include <climits>
#include <cmath>
#include <cstdlib>
#include <cstring>
#include <fstream>
#include <regex>
#include <sstream>
#include <set>

namespace chaincomp {

namespace {

// Defaults per axis kind, in the axis's unit: mm for linear axes, deg for rotary ones.
constexpr AxisLimits kLinearDefaults{0, 0, 10.0, 0.5, 0.001};
constexpr AxisLimits kRotaryDefaults{0, 0, 5.0, 0.5, 0.001};

struct Reader {
  const std::string& path;
  std::string& error;

  bool fail(const YAML::Node& node, const std::string& key, const std::string& what) {
    // an empty document has no mark: its first line
    error = path + ":" + std::to_string(std::max(node.Mark().line, 0) + 1) + ": " + (key.empty() ? "" : key + ": ") + what;
    return false;
  }
  // Numbers and booleans as the shared YAML reading types them (yaml_strict.hpp); a plain
  // decimal such as 1e-3, text in YAML 1.1, is a number here too.
  bool number(const YAML::Node& node, const std::string& key, double& out, double min = -INFINITY) {
    static const std::regex decimal("[-+]?(?:[0-9]+\\.?[0-9]*|\\.[0-9]+)(?:[eE][-+]?[0-9]+)?");
    if (!yaml_number(node, out)) {
      if (!node.IsScalar() || node.Tag() != "?" || !std::regex_match(node.Scalar(), decimal))
        return fail(node, key, "expected a number");
      out = std::strtod(node.Scalar().c_str(), nullptr);
    }
    if (!std::isfinite(out)) return fail(node, key, "expected a finite number");
    if (out < min) return fail(node, key, "must be at least " + std::to_string(min));
    return true;
  }
  bool integer(const YAML::Node& node, const std::string& key, int& out) {
    if (resolve(node) != Yaml11::kInt) return fail(node, key, "expected an integer");
    errno = 0;
    const long long v = std::strtoll(node.Scalar().c_str(), nullptr, 10);
    if (errno != 0 || v < INT_MIN || v > INT_MAX) return fail(node, key, "expected an integer");
    out = static_cast<int>(v);
    return true;
  }
  bool boolean(const YAML::Node& node, const std::string& key, bool& out) {
    if (resolve(node) != Yaml11::kBool) return fail(node, key, "expected true or false");
    out = py_repr(node) == "True";
    return true;
  }
  bool text(const YAML::Node& node, const std::string& key, std::string& out) {
    if (!node.IsScalar() || node.Scalar().empty()) return fail(node, key, "expected text");
    out = node.Scalar();
    return true;
  }
  // A channel name: LCM refuses to publish on one longer than kMaxChannelName.
  bool channel(const YAML::Node& node, const std::string& key, std::string& out) {
    if (!text(node, key, out)) return false;
    if (out.size() > kMaxChannelName)
      return fail(node, key, std::to_string(out.size()) + " bytes: LCM's channel names are at most " +
                                 std::to_string(kMaxChannelName) + " (LCM_MAX_CHANNEL_NAME_LENGTH)");
    return true;
  }
  bool keys(const YAML::Node& node, const std::string& where, const std::set<std::string>& allowed) {
    if (!node.IsMap()) return fail(node, where, "expected a mapping");
    for (const auto& kv : node) {
      const std::string k = kv.first.IsScalar() ? kv.first.Scalar() : "None";
      if (!allowed.count(k)) {
        std::string list;
        for (const auto& a : allowed) list += (list.empty() ? "" : ", ") + a;
        return fail(kv.first, where.empty() ? k : where + "." + k, "unknown key (expected one of: " + list + ")");
      }
    }
    return true;
  }
  bool axis_limits(const YAML::Node& node, const std::string& where, AxisLimits& lim) {
    if (!keys(node, where, {"max_step", "max_correction", "max_correction_step", "limits"})) return false;
    if (node["max_step"] && !number(node["max_step"], where + ".max_step", lim.max_step, 0)) return false;
    if (node["max_correction"] && !number(node["max_correction"], where + ".max_correction", lim.max_correction, 0))
      return false;
    if (node["max_correction_step"] &&
        !number(node["max_correction_step"], where + ".max_correction_step", lim.max_correction_step, 0))
      return false;
    return true;
  }
};

// The receive buffer asked of udpm's socket: one key, recv_buf_size, appended to the URL.
std::string udpm_url(const std::string& url, int recv_buf_size) {
  if (url.rfind("udpm://", 0) != 0) return url;
  return url + (url.find('?') == std::string::npos ? "?" : "&") + "recv_buf_size=" + std::to_string(recv_buf_size);
}

}  // namespace

bool load_daemon_config(const MachineInfo& info, const std::string& path, DaemonConfig& out,
                        std::string& error) {
  if (info.num_axes > kMaxAxes) {
    error = std::string("machine ") + info.name + " has more than " + std::to_string(kMaxAxes) + " axes";
    return false;
  }
  for (int i = 0; i < info.num_axes; ++i) {
    AxisLimits lim = info.axes[i].kind == UnitKind::kAngle ? kRotaryDefaults : kLinearDefaults;
    lim.lower = info.axes[i].lower;
    lim.upper = info.axes[i].upper;
    out.compensator.axes[i] = lim;
  }
  out.source_file = path;
  if (path.empty()) {
    out.lcm_url = udpm_url(out.lcm_url, out.recv_buf_size);
    return true;
  }
  YAML::Node doc;
  std::string text;
  if (!read_input_file(path, text, error) || !load_strict_yaml(path, text, doc, error)) return false;
  Reader r{path, error};
  if (!r.keys(doc, "", {"lcm_url", "channels", "status_period", "latency_window", "start_enabled", "ramp_time",
                        "out_of_limits", "linear_axes", "rotary_axes", "axes", "realtime", "recv_buf_size",
                        "params_updates", "direction_weight"}))
    return false;
  if (doc["lcm_url"] && !r.text(doc["lcm_url"], "lcm_url", out.lcm_url)) return false;
  if (out.lcm_url.find("recv_buf_size=") != std::string::npos)
    return r.fail(doc["lcm_url"], "lcm_url", "recv_buf_size is set by its own key, recv_buf_size");
  if (doc["recv_buf_size"]) {
    if (!r.integer(doc["recv_buf_size"], "recv_buf_size", out.recv_buf_size)) return false;
    if (out.recv_buf_size < 2048 || out.recv_buf_size > (1 << 30))
      return r.fail(doc["recv_buf_size"], "recv_buf_size", "must be between 2048 and 1073741824 bytes");
  }
  out.lcm_url = udpm_url(out.lcm_url, out.recv_buf_size);
  if (const YAML::Node ch = doc["channels"]) {
    if (!r.keys(ch, "channels", {"command", "corrected", "status", "control", "params", "temperatures"})) return false;
    if (ch["command"] && !r.channel(ch["command"], "channels.command", out.command_channel)) return false;
    if (ch["corrected"] && !r.channel(ch["corrected"], "channels.corrected", out.corrected_channel)) return false;
    if (ch["status"] && !r.channel(ch["status"], "channels.status", out.status_channel)) return false;
    if (ch["control"] && !r.channel(ch["control"], "channels.control", out.control_channel)) return false;
    if (ch["params"] && !r.channel(ch["params"], "channels.params", out.params_channel)) return false;
    if (ch["temperatures"] && !r.channel(ch["temperatures"], "channels.temperatures", out.temperatures_channel))
      return false;
  }
  if (const YAML::Node pu = doc["params_updates"]) {
    ParamsUpdateLimits& l = out.params_updates;
    if (!r.keys(pu, "params_updates", {"max_length", "max_angle", "max_ratio", "min_interval"})) return false;
    if (pu["max_length"] && !r.number(pu["max_length"], "params_updates.max_length", l.max_length, 0)) return false;
    if (pu["max_angle"] && !r.number(pu["max_angle"], "params_updates.max_angle", l.max_angle, 0)) return false;
    if (pu["max_ratio"] && !r.number(pu["max_ratio"], "params_updates.max_ratio", l.max_ratio, 0)) return false;
    if (pu["min_interval"] && !r.number(pu["min_interval"], "params_updates.min_interval", l.min_interval_s, 0))
      return false;
  }
  if (doc["status_period"] && !r.number(doc["status_period"], "status_period", out.status_period_s, 0.001))
    return false;
  if (doc["latency_window"]) {
    if (!r.integer(doc["latency_window"], "latency_window", out.latency_window)) return false;
    if (out.latency_window < 1 || out.latency_window > 1000000)
      return r.fail(doc["latency_window"], "latency_window", "must be between 1 and 1000000");
  }
  if (doc["start_enabled"] && !r.boolean(doc["start_enabled"], "start_enabled", out.compensator.start_enabled))
    return false;
  if (const YAML::Node w = doc["direction_weight"]) {
    double& weight = out.compensator.direction_weight;
    if (!r.number(w, "direction_weight", weight)) return false;
    if (!(weight >= kMinDirectionWeight && weight <= kMaxDirectionWeight))
      return r.fail(w, "direction_weight", "must be between 0.1 and 10000 mm");
  }
  if (doc["ramp_time"] && !r.number(doc["ramp_time"], "ramp_time", out.compensator.ramp_time_s, 0)) return false;
  if (const YAML::Node pol = doc["out_of_limits"]) {
    std::string v;
    if (!r.text(pol, "out_of_limits", v)) return false;
    if (v != "reject" && v != "clamp") return r.fail(pol, "out_of_limits", "expected 'reject' or 'clamp'");
    out.compensator.clamp_out_of_limits = v == "clamp";
  }
  for (const char* kind : {"linear_axes", "rotary_axes"}) {
    if (const YAML::Node k = doc[kind]) {
      const bool rotary = std::string(kind) == "rotary_axes";
      for (int i = 0; i < info.num_axes; ++i) {
        if ((info.axes[i].kind == UnitKind::kAngle) != rotary) continue;
        if (!r.axis_limits(k, kind, out.compensator.axes[i])) return false;
      }
      if (!r.keys(k, kind, {"max_step", "max_correction", "max_correction_step"})) return false;
    }
  }
  if (const YAML::Node axes = doc["axes"]) {
    if (!axes.IsMap()) return r.fail(axes, "axes", "expected a mapping of axis names");
    for (const auto& kv : axes) {
      const std::string name = kv.first.IsScalar() ? kv.first.Scalar() : "None";
      int index = -1;
      for (int i = 0; i < info.num_axes; ++i) {
        if (name == info.axes[i].name) index = i;
      }
      if (index < 0) return r.fail(kv.first, "axes." + name, std::string("no such axis on machine ") + info.name);
      AxisLimits& lim = out.compensator.axes[index];
      if (!r.axis_limits(kv.second, "axes." + name, lim)) return false;
      if (const YAML::Node l = kv.second["limits"]) {
        double lo, hi;
        if (!l.IsSequence() || l.size() != 2) return r.fail(l, "axes." + name + ".limits", "expected [low, high]");
        if (!r.number(l[0], "axes." + name + ".limits", lo) || !r.number(l[1], "axes." + name + ".limits", hi))
          return false;
        if (!(lo < hi) || lo < info.axes[index].lower || hi > info.axes[index].upper)
          return r.fail(l, "axes." + name + ".limits",
                        "must satisfy low < high within the machine's limits [" +
                            std::to_string(info.axes[index].lower) + ", " + std::to_string(info.axes[index].upper) + "]");
        lim.lower = lo;
        lim.upper = hi;
      }
    }
  }
  if (const YAML::Node rt = doc["realtime"]) {
    if (!r.keys(rt, "realtime", {"mlockall", "sched_fifo_priority", "cpu"})) return false;
    if (rt["mlockall"] && !r.boolean(rt["mlockall"], "realtime.mlockall", out.mlockall)) return false;
    if (rt["sched_fifo_priority"]) {
      if (!r.integer(rt["sched_fifo_priority"], "realtime.sched_fifo_priority", out.sched_fifo_priority)) return false;
      if (out.sched_fifo_priority < 0 || out.sched_fifo_priority > 99)
        return r.fail(rt["sched_fifo_priority"], "realtime.sched_fifo_priority", "must be 0 (off) .. 99");
    }
    if (rt["cpu"] && !r.integer(rt["cpu"], "realtime.cpu", out.cpu)) return false;
  }
  return true;
}

}  // namespace chaincomp
