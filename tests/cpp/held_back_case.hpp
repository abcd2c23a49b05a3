// A command stream on which the daemon's limits must hold corrections back (Counters::held_back),
// shared by the compensator test (which predicts every one of them) and the LCM test (which
// finds the count on the status message).
//
// five_axis_ac held at A = 1 deg, near the pose where the tool lies along C: there the tilt
// errors ask for a large C correction (C barely moves the tool there: some 0.7 deg, held at
// max_correction 0.5) and the rate limit lets it build up over 500 commands. Then A opens by
// 5 deg a command (max_step) to 46 deg: the same C correction now swings the tool far (tenths
// of a mm), the correction wanted there is a small one, and the rate limit unwinds the old
// one by 0.001 deg a command only: hundreds of targets further off than the command itself.
#pragma once

#include <algorithm>
#include <cmath>
#include <string>
#include <vector>

#include "chaincomp/compensator.hpp"
#include "chaincomp/daemon_config.hpp"

namespace held_back_case {

constexpr const char* kMachine = "five_axis_ac";
constexpr int kCommands = 3001;

// 20 um and 20 arcsec on every error, alternating signs (also the singular-pose test's errors)
inline void prepare(const chaincomp::ModelEntry& entry, void* model) {
  std::vector<double> params(entry.info->num_params);
  for (int i = 0; i < entry.info->num_params; ++i) {
    const auto& p = entry.info->params[i];
    const double sign = i % 2 ? -1.0 : 1.0;
    params[i] = p.role == chaincomp::ParamRole::kError
                    ? sign * (p.kind == chaincomp::UnitKind::kLength ? 20e-3 : 20.0 * M_PI / 648000.0)
                    : p.nominal;
  }
  entry.prepare(params.data(), model);
}

// The default runtime settings, compensating in full from the first command.
inline bool config(const chaincomp::ModelEntry& entry, chaincomp::DaemonConfig& out, std::string& error) {
  if (!chaincomp::load_daemon_config(*entry.info, "", out, error)) return false;
  out.compensator.ramp_time_s = 0;
  return true;
}

// Command k of the stream, k = 0 .. kCommands - 1: 1 ms apart.
inline chaincomp::Command command(int k) {
  chaincomp::Command cmd;
  cmd.seq = k + 1;
  cmd.utime = 1000 * (k + 1);
  cmd.machine = kMachine;
  cmd.num_axes = 5;
  const double a = k < 1000 ? 1.0 : std::min(46.0, 1.0 + 5.0 * (k - 999));
  cmd.axes = {100, -20, -150, a, 30, 0, 0, 0};
  return cmd;
}

}  // namespace held_back_case
