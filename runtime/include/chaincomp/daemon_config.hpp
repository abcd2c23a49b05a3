// chaincompd's runtime configuration (configs/runtime/*.yaml). Start-up only.
#pragma once

#include <string>

#include "chaincomp/compensator.hpp"
#include "chaincomp/model_info.hpp"
#include "chaincomp/params_update.hpp"

namespace chaincomp {

// The longest channel name LCM publishes on (LCM_MAX_CHANNEL_NAME_LENGTH).
constexpr std::size_t kMaxChannelName = 63;

struct DaemonConfig {
  // a udpm URL gets `recv_buf_size=` from recv_buf_size (load_daemon_config adds it)
  std::string lcm_url = "udpm://239.255.76.67:7667?ttl=0";
  int recv_buf_size = 2097152;  // bytes of socket receive buffer asked for (capped by net.core.rmem_max)
  std::string source_file;      // the file read ("": defaults)
  std::string command_channel = "CHAINCOMP_COMMAND";
  std::string corrected_channel = "CHAINCOMP_CORRECTED";
  std::string status_channel = "CHAINCOMP_STATUS";
  std::string control_channel = "CHAINCOMP_CONTROL";
  std::string params_channel = "CHAINCOMP_PARAMS";   // lcmt_params_update
  std::string temperatures_channel = "CHAINCOMP_TEMPERATURES";   // lcmt_temperatures (with a thermal model)
  ParamsUpdateLimits params_updates;
  double status_period_s = 1.0;
  int latency_window = 1000;
  bool mlockall = false;
  int sched_fifo_priority = 0;  // 0: leave the scheduler alone
  int cpu = -1;                 // -1: no pinning
  CompensatorConfig compensator;
};

// Defaults for `info`'s axes (limits from the machine file), then the file at `path` (may
// be empty: defaults only). Errors name file, line and key.
bool load_daemon_config(const MachineInfo& info, const std::string& path, DaemonConfig& out,
                        std::string& error);

}  // namespace chaincomp
