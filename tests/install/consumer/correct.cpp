// A controller's use of an installed chaincomp: one generated model (CHAINCOMP_MODEL_HEADER,
// namespace chaincomp::models::CHAINCOMP_MODEL_NAMESPACE, set by CMakeLists.txt) and the
// compensator around it. Corrects one commanded pose and prints the result as one JSON object.
//
//   correct_NAME AXIS... [PARAM=VALUE ...]
//
// AXIS: one value per axis, in the machine file's order and declared units (mm, deg).
// PARAM=VALUE: a constant or error in its declared unit (um, arcsec, ...); the others keep
// their nominal value (errors: 0).
// Output: {"machine", "status", "flags", "commanded", "corrected", "correction",
// "residual_point_mm", "residual_direction_rad"}, axes in their declared units.
// Exit 0 corrected, 1 rejected by the compensator (the reason on stderr), 2 bad arguments.
#include <chaincomp/compensate.hpp>
#include <chaincomp/compensator.hpp>
#include <chaincomp/model_info.hpp>

#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <limits>
#include <string>

#include CHAINCOMP_MODEL_HEADER

namespace model = chaincomp::models::CHAINCOMP_MODEL_NAMESPACE;

namespace {

int usage(const char* why) {
  std::fprintf(stderr, "correct_%s: %s\nusage: correct_%s", model::kName, why, model::kName);
  for (int i = 0; i < model::kNumAxes; ++i) std::fprintf(stderr, " %s[%s]", model::kAxes[i].name, model::kAxes[i].unit);
  std::fputs(" [PARAM=VALUE ...]\n", stderr);
  return 2;
}

bool parse_number(const char* text, double& value) {
  char* end = nullptr;
  value = std::strtod(text, &end);
  return end != text && *end == '\0' && std::isfinite(value);
}

void print_axes(const char* key, const double* v, int n) {
  std::printf("\"%s\": [", key);
  for (int i = 0; i < n; ++i) std::printf("%s%.17g", i ? ", " : "", v[i]);
  std::printf("]");
}

}  // namespace

int main(int argc, char** argv) {
  const chaincomp::ModelEntry& entry = model::kEntry;
  const chaincomp::MachineInfo& info = *entry.info;
  const int n = info.num_axes;
  if (argc < 1 + n) return usage("expected one value per axis");

  chaincomp::Command command;
  command.utime = 0;
  command.seq = 1;
  command.machine = info.name;
  command.num_axes = n;
  for (int i = 0; i < n; ++i) {
    if (!parse_number(argv[1 + i], command.axes[i])) return usage((std::string("not a number: ") + argv[1 + i]).c_str());
  }

  // The parameters in kParams order and internal units (mm, rad): nominal, then argv's.
  double params[model::kNumParams];
  for (int j = 0; j < info.num_params; ++j) params[j] = info.params[j].nominal;
  for (int a = 1 + n; a < argc; ++a) {
    const char* eq = std::strchr(argv[a], '=');
    if (eq == nullptr) return usage((std::string("expected PARAM=VALUE: ") + argv[a]).c_str());
    const std::string name(argv[a], static_cast<std::size_t>(eq - argv[a]));
    int j = 0;
    while (j < info.num_params && name != info.params[j].name) ++j;
    if (j == info.num_params) return usage(("no parameter " + name + " in " + info.name).c_str());
    double value = 0;
    if (!parse_number(eq + 1, value)) return usage((std::string("not a number: ") + argv[a]).c_str());
    params[j] = value * info.params[j].to_internal;
  }
  model::Model m;
  entry.prepare(params, &m);

  // Limits a controller would take from its machine: the axes' travel from the machine file,
  // corrections of at most one axis unit (mm, deg); one command, so no step limit.
  chaincomp::CompensatorConfig config;
  for (int i = 0; i < n; ++i) {
    chaincomp::AxisLimits& lim = config.axes[i];
    lim.lower = info.axes[i].lower;
    lim.upper = info.axes[i].upper;
    lim.max_step = std::numeric_limits<double>::infinity();
    lim.max_correction = 1.0;
    lim.max_correction_step = 1.0;
  }
  chaincomp::Compensator compensator(entry, &m, config);

  chaincomp::Target target;
  chaincomp::Reject why = chaincomp::Reject::kUndecodable;
  if (!compensator.process(command, target, &why)) {
    std::fprintf(stderr, "correct_%s: command rejected: %s\n", info.name, chaincomp::reject_name(why));
    return 1;
  }
  std::printf("{\"machine\": \"%s\", \"status\": \"%s\", \"flags\": %d, ", info.name,
              chaincomp::status_name(static_cast<chaincomp::Status>(target.status)), target.flags);
  print_axes("commanded", command.axes.data(), n);
  std::printf(", ");
  print_axes("corrected", target.axes.data(), n);
  std::printf(", ");
  print_axes("correction", target.correction.data(), n);
  std::printf(", \"residual_point_mm\": %.17g, \"residual_direction_rad\": %.17g}\n", target.residual_point,
              target.residual_direction);
  return 0;
}
