// chaincomp_replay: runs every command of an lcm-logger log through the daemon's compensator
// (the same compiled code, the same runtime settings) and writes a corrected log and/or a CSV.
#include <sys/stat.h>
#include <unistd.h>

#include <charconv>
#include <chrono>
#include <cerrno>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <exception>
#include <string>
#include <vector>

#include "chaincomp/compensator.hpp"
#include "chaincomp/daemon_config.hpp"
#include "chaincomp/event_log.hpp"
#include "chaincomp/loaded_model.hpp"
#include "chaincomp/lcm_node.hpp"
#include "chaincomp/output_file.hpp"
#include "chaincomp/params_io.hpp"
#include "chaincomp/params_update.hpp"
#include "chaincomp_lcm/lcmt_chaincomp_status.hpp"
#include "chaincomp_lcm/lcmt_params_update.hpp"
#include "chaincomp_lcm/lcmt_temperatures.hpp"
#include "chaincomp/thermal.hpp"

namespace {

const char* kUsage =
    "usage: chaincomp_replay --machine M.yaml --params P.yaml --in IN.lcmlog [--out OUT.lcmlog]\n"
    "                        [--csv OUT.csv] [--config R.yaml] [--channel NAME] [--model LIB.so] [--quiet]\n"
    "                        [--format text|json] [--thermal T.yaml]\n"
    "       chaincomp_replay --version\n";

int fail(const std::string& msg) {
  std::fprintf(stderr, "chaincomp replay: error: %s\n", msg.c_str());
  return 2;
}

// Appends numbers to a line with std::to_chars: shortest text that reads back exactly.
struct Line {
  char buf[4096];
  std::size_t n = 0;
  void num(double v) {
    n += std::to_chars(buf + n, buf + sizeof buf - 64, v).ptr - (buf + n);
    buf[n++] = ',';
  }
  void num(long long v) {
    n += std::to_chars(buf + n, buf + sizeof buf - 64, v).ptr - (buf + n);
    buf[n++] = ',';
  }
  void text(const char* s) {
    const std::size_t k = std::strlen(s);
    std::memcpy(buf + n, s, k);
    n += k;
    buf[n++] = ',';
  }
  void skip(int count) {
    for (int i = 0; i < count; ++i) buf[n++] = ',';
  }
  void end(std::FILE* f) {
    buf[n - 1] = '\n';
    std::fwrite(buf, 1, n, f);
    n = 0;
  }
};

// A JSON string: the machine's name and the channel come from the user.
std::string json_string(const std::string& s) {
  std::string out = "\"";
  for (const unsigned char c : s) {
    if (c == '"' || c == '\\') {
      out += '\\';
      out += static_cast<char>(c);
    } else if (c < 0x20) {
      char esc[8];
      std::snprintf(esc, sizeof esc, "\\u%04x", c);
      out += esc;
    } else {
      out += static_cast<char>(c);
    }
  }
  return out + "\"";
}

// Whether both paths name one existing file (links and other spellings included).
bool same_file(const std::string& a, const std::string& b) {
  struct stat sa {}, sb {};
  return stat(a.c_str(), &sa) == 0 && stat(b.c_str(), &sb) == 0 && sa.st_dev == sb.st_dev && sa.st_ino == sb.st_ino;
}

}  // namespace

int run_replay(int argc, char** argv) {
  std::string machine_path, params_path, config_path, in_path, out_path, csv_path, model_path,
      channel = "CHAINCOMP_COMMAND", format = "text", thermal_path;
  bool quiet = false;
  for (int i = 1; i < argc; ++i) {
    const std::string a = argv[i];
    std::string* dst = a == "--machine" ? &machine_path : a == "--params" ? &params_path
                     : a == "--config"  ? &config_path  : a == "--in"     ? &in_path
                     : a == "--out"     ? &out_path     : a == "--csv"    ? &csv_path
                     : a == "--channel" ? &channel      : a == "--model"  ? &model_path
                     : a == "--format"  ? &format       : a == "--thermal" ? &thermal_path : nullptr;
    if (a == "-h" || a == "--help") {
      std::fputs(kUsage, stdout);
      return 0;
    } else if (a == "--version") {
      std::puts("chaincomp_replay " CHAINCOMP_VERSION);
      return 0;
    } else if (a == "--quiet") {
      quiet = true;
    } else if (dst && i + 1 < argc) {
      *dst = argv[++i];
    } else {
      std::fputs(kUsage, stderr);
      return fail("unexpected argument '" + a + "'");
    }
  }
  if (format != "text" && format != "json") return fail("--format " + format + ": expected text or json");
  if (machine_path.empty() || params_path.empty() || in_path.empty()) {
    std::fputs(kUsage, stderr);
    return fail("--machine, --params and --in are required");
  }
  std::string error;
  chaincomp::LoadedModel loaded;
  if (!chaincomp::load_model(machine_path, model_path, params_path, config_path, loaded, error)) return fail(error);
  const chaincomp::ModelEntry* entry = loaded.entry;
  const chaincomp::DaemonConfig& config = loaded.config;
  const chaincomp::VaryingErrors& varying = loaded.varying;
  void* model = loaded.model;
  if (varying.count > 0 && !quiet) {
    std::fprintf(stderr, "chaincomp replay: %s: %s\n", params_path.c_str(), chaincomp::describe_varying(varying).c_str());
  }
  chaincomp::Compensator comp(*entry, model, config.compensator);
  // Params updates on the log's params channel change the model as they changed the daemon's.
  // Those addressed to one daemon apply when it is the one whose status or targets the log
  // holds (the first for this machine found before them); the others are refused as the
  // daemon refused them.
  chaincomp::ParamsUpdater updater(*entry, model, &varying, loaded.params, config.params_updates);
  chaincomp::ParamsUpdate update;
  // A thermal model takes the log's temperature readings as the daemon took them.
  chaincomp::ThermalModel thermal_model;
  if (!thermal_path.empty() && !chaincomp::load_thermal_model(*entry->info, thermal_path, thermal_model, error))
    return fail(error);
  chaincomp::ThermalState thermal(thermal_model, loaded.params);
  chaincomp::Readings readings;
  chaincomp_lcm::lcmt_chaincomp_control control{};
  std::int64_t daemon_instance = 0;
  chaincomp_lcm::lcmt_chaincomp_status status_scratch;
  chaincomp_lcm::lcmt_corrected_target target_scratch;

  // One file for both outputs would hold the log and the CSV interleaved: neither readable.
  if (!out_path.empty() && (out_path == csv_path || same_file(out_path, csv_path))) {
    return fail("--csv: " + csv_path + " is also the --out log; choose another file for one of them");
  }
  chaincomp::LogReader in;
  if (!in.open(in_path, error)) return fail(error);
  // Writing over the log being read would destroy it.
  for (const std::string* out_file : {&out_path, &csv_path}) {
    if (!out_file->empty() && same_file(in_path, *out_file)) {
      return fail(*out_file + ": is the input log itself; choose another output file");
    }
  }
  chaincomp::LogWriter out;
  const bool write_log = !out_path.empty();
  if (write_log && !out.open(out_path, error)) return fail(error);
  chaincomp::OutputFile csv_file;  // the CSV by the one writer's rules; stdio on a copy of its descriptor
  std::FILE* csv = nullptr;
  if (!csv_path.empty()) {
    if (!csv_file.open(csv_path, error)) return fail(error);
    const int fd = dup(csv_file.fd());
    if (fd < 0 || !(csv = fdopen(fd, "w"))) return fail(csv_path + ": cannot write: " + std::strerror(errno));
  }
  const int n = entry->info->num_axes;
  if (csv) {
    std::string header = "event,utime,seq,result";
    for (const char* part : {"commanded", "corrected", "correction"}) {
      for (int i = 0; i < n; ++i) {
        header += std::string(",") + part + "_" + entry->info->axes[i].name + "_" + entry->info->axes[i].unit;
      }
    }
    header += ",residual_point_mm,residual_direction_rad,flags,status\n";
    std::fputs(header.c_str(), csv);
  }

  chaincomp_lcm::lcmt_axis_command scratch;
  scratch.machine.reserve(chaincomp::LcmNode::kMaxMachineName + 1);
  chaincomp_lcm::lcmt_corrected_target msg;
  msg.machine = entry->info->name;  // instance_id stays 0: replayed offline, not a daemon
  std::vector<unsigned char> buf(msg.getEncodedSize() + 64);
  const std::string out_channel = config.corrected_channel;
  chaincomp::Command cmd;
  chaincomp::Target target;
  Line line;
  long long events = 0, commands = 0, listed = 0;
  std::vector<double> max_abs(n, 0.0), sum_sq(n, 0.0);
  const auto t0 = std::chrono::steady_clock::now();
  chaincomp::LogEvent ev;
  // The updates' clock as the daemon keeps it, with the log's timestamps for its receipt times.
  bool command_accepted = false;
  std::int64_t command_at = 0;
  auto command_time = [&](std::int64_t now) {
    return chaincomp::CommandTime(comp.last_utime(), chaincomp::commands_flowing(command_accepted, command_at, now), now);
  };
  std::size_t damage_listed = 0;
  auto list_damage = [&]() {  // damaged stretches of the log, as they are found
    for (; damage_listed < in.damage().size(); ++damage_listed) {
      const auto& d = in.damage()[damage_listed];
      if (damage_listed < 20) {
        std::fprintf(stderr, "chaincomp replay: bytes %llu-%llu of the log skipped: %s\n",
                     static_cast<unsigned long long>(d.offset),
                     static_cast<unsigned long long>(d.offset + d.bytes - 1), d.what);
      }
    }
  };
  while (in.next(ev)) {
    list_damage();
    ++events;
    if (write_log) out.write(ev.timestamp, ev.channel, ev.data, ev.datalen);  // the original record, untouched
    if (daemon_instance == 0 && (ev.channel == config.status_channel || ev.channel == config.corrected_channel)) {
      const bool status = ev.channel == config.status_channel;
      const int size = static_cast<int>(ev.datalen);
      if (status ? status_scratch.decode(ev.data, 0, size) >= 0 && status_scratch.machine == entry->info->name
                 : target_scratch.decode(ev.data, 0, size) >= 0 && target_scratch.machine == entry->info->name) {
        daemon_instance = status ? status_scratch.instance_id : target_scratch.instance_id;
      }
    }
    if (!thermal_path.empty() && ev.channel == config.temperatures_channel) {
      if (!chaincomp::decode_readings(ev.data, ev.datalen, chaincomp_lcm::lcmt_temperatures::getHash(), readings)) {
        thermal.count_undecodable();
      } else if (thermal.take(readings, entry->info->name, update)) {
        updater.apply_values(update, command_time(ev.timestamp));
      }
      continue;
    }
    if (ev.channel == config.control_channel) {   // enable and reset, as the daemon applies them
      if (chaincomp::decode_control(ev.data, ev.datalen, control))
        chaincomp::apply_control(control, comp, &updater, thermal_path.empty() ? nullptr : &thermal);
      continue;
    }
    if (ev.channel == config.params_channel) {
      chaincomp::Refuse refused = chaincomp::Refuse::kUndecodable;
      if (!chaincomp::decode_params_update(ev.data, ev.datalen, chaincomp_lcm::lcmt_params_update::getHash(), update)) {
        updater.count_undecodable();
      } else if (!updater.apply(update, daemon_instance, command_time(ev.timestamp), &refused) && listed < 20) {
        ++listed;
        std::fprintf(stderr, "chaincomp replay: event %lld (timestamp %lld): params update refused: %s\n",
                     static_cast<long long>(ev.eventnum), static_cast<long long>(ev.timestamp),
                     chaincomp::refuse_name(refused));
      }
      continue;
    }
    if (ev.channel != channel) continue;
    ++commands;
    chaincomp::Reject why = chaincomp::Reject::kUndecodable;
    const bool decoded = chaincomp::decode_command(ev.data, ev.datalen, scratch, cmd);
    bool ok = false;
    if (decoded) {
      ok = comp.process(cmd, target, &why);
    } else {
      comp.count_undecodable();
    }
    if (ok) {
      comp.count_published();
      command_accepted = true;
      command_at = ev.timestamp;
      for (int i = 0; i < n; ++i) {
        max_abs[i] = std::max(max_abs[i], std::abs(target.correction[i]));
        sum_sq[i] += target.correction[i] * target.correction[i];
      }
      if (write_log) {
        chaincomp::to_message(target, msg);
        msg.compute_ns = 0;  // offline: no latency to report
        const int len = msg.encode(buf.data(), 0, static_cast<int>(buf.size()));
        out.write(ev.timestamp, out_channel, buf.data(), len);  // original time kept
      }
    } else if (listed < 20) {
      ++listed;
      std::fprintf(stderr, "chaincomp replay: event %lld (timestamp %lld): rejected: %s\n",
                   static_cast<long long>(ev.eventnum), static_cast<long long>(ev.timestamp),
                   chaincomp::reject_name(why));
    }
    if (csv) {
      line.num(static_cast<long long>(ev.eventnum));
      line.num(static_cast<long long>(decoded ? cmd.utime : ev.timestamp));
      if (decoded) line.num(static_cast<long long>(cmd.seq)); else line.skip(1);
      line.text(ok ? "ok" : chaincomp::reject_name(why));
      const bool axes_known = decoded && cmd.num_axes == n;
      for (int i = 0; i < n; ++i) {
        if (axes_known) line.num(cmd.axes[i]); else line.skip(1);
      }
      if (ok) {
        for (int i = 0; i < n; ++i) line.num(target.axes[i]);
        for (int i = 0; i < n; ++i) line.num(target.correction[i]);
        line.num(target.residual_point);
        line.num(target.residual_direction);
        line.num(static_cast<long long>(target.flags));
        line.num(static_cast<long long>(target.status));
      } else {
        line.skip(2 * n + 4);
      }
      line.end(csv);
    }
    if (!quiet && commands % 1000000 == 0) {
      std::fprintf(stderr, "chaincomp replay: %lld commands...\n", commands);
    }
  }
  const double seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  list_damage();
  if (csv) {  // both written out before either is put in place
    const bool write_failed = std::ferror(csv) != 0;  // a failed fwrite of any line
    if (std::fclose(csv) != 0 || write_failed) return fail(csv_path + ": cannot write: " + std::strerror(errno));
  }
  if (write_log && !out.close(error)) return fail(error);
  if (csv && !csv_file.commit(error)) return fail(error);

  const auto& k = comp.counters();
  long long rejected = 0;
  for (auto r : k.rejected) rejected += r;
  unsigned long long damaged_bytes = 0;
  for (const auto& d : in.damage()) damaged_bytes += d.bytes;
  if (format == "json") {  // the same summary, on stdout, every counter present
    std::printf("{\"machine\": %s, \"channel\": %s, \"events\": %lld, \"commands\": %lld, \"corrected\": %lld, "
                "\"rejected_total\": %lld, \"commands_per_s\": %.6g,\n \"rejected\": {",
                json_string(entry->info->name).c_str(), json_string(channel).c_str(), events, commands,
                static_cast<long long>(k.published), rejected, commands / std::max(seconds, 1e-9));
    for (int r = 0; r < chaincomp::kNumReasons; ++r) {
      std::printf("%s\"%s\": %lld", r ? ", " : "", chaincomp::reject_name(static_cast<chaincomp::Reject>(r)),
                  static_cast<long long>(k.rejected[r]));
    }
    std::printf("},\n \"damaged\": {\"stretches\": %zu, \"bytes\": %llu}, \"seq_gaps\": %lld, \"seq_missing\": %lld, "
                "\"stream_restarts\": %lld, \"clamped\": %lld, \"held_back\": %lld, \"clamped_input\": %lld,\n "
                "\"correction\": [", in.damage().size(), damaged_bytes, static_cast<long long>(k.seq_gaps),
                static_cast<long long>(k.seq_missing), static_cast<long long>(k.stream_restarts),
                static_cast<long long>(k.clamped), static_cast<long long>(k.held_back),
                static_cast<long long>(k.clamped_input));
    for (int i = 0; i < n; ++i) {
      std::printf("%s{\"axis\": %s, \"unit\": %s, \"max_abs\": %.17g, \"rms\": %.17g}", i ? ", " : "",
                  json_string(entry->info->axes[i].name).c_str(), json_string(entry->info->axes[i].unit).c_str(),
                  max_abs[i], k.published ? std::sqrt(sum_sq[i] / k.published) : 0.0);
    }
    std::printf("],\n \"objective\": {\"direction_weight_mm\": %.17g, \"full\": %lld, \"partial\": %lld, "
                "\"uncorrected\": %lld, \"worse\": %lld, \"before_sum_mm2\": %.17g, \"after_sum_mm2\": %.17g}",
                config.compensator.direction_weight, static_cast<long long>(k.targets_full),
                static_cast<long long>(k.targets_partial), static_cast<long long>(k.targets_uncorrected),
                static_cast<long long>(k.targets_worse), k.objective_before, k.objective_after);
    std::printf(",\n \"params_updates\": {\"received\": %lld, \"applied\": %lld, \"last_seq\": %lld, \"refused\": {",
                static_cast<long long>(updater.received()), static_cast<long long>(updater.version()),
                static_cast<long long>(updater.last_seq()));
    for (int r = 0; r < chaincomp::kNumRefusals; ++r) {
      std::printf("%s\"%s\": %lld", r ? ", " : "", chaincomp::refuse_name(static_cast<chaincomp::Refuse>(r)),
                  static_cast<long long>(updater.refused()[r]));
    }
    std::printf("}}}\n");
    return std::fflush(stdout) == 0 ? 0 : fail("cannot write the summary to standard output");
  }
  std::fprintf(stderr, "chaincomp replay: %lld events, %lld commands on %s, %lld corrected, %lld rejected "
               "(%.0f commands/s)\n", events, commands, channel.c_str(), static_cast<long long>(k.published),
               rejected, commands / std::max(seconds, 1e-9));
  // what the targets correct, and the objective (compensate.hpp) before and after, as RMS lengths
  if (k.published) {
    std::fprintf(stderr, "  targets: full %lld, partial %lld, uncorrected %lld, worse than the command %lld; "
                 "objective RMS before %.6g um, after %.6g um (direction weight %.6g mm)\n",
                 static_cast<long long>(k.targets_full), static_cast<long long>(k.targets_partial),
                 static_cast<long long>(k.targets_uncorrected), static_cast<long long>(k.targets_worse),
                 1e3 * std::sqrt(k.objective_before / k.published), 1e3 * std::sqrt(k.objective_after / k.published),
                 config.compensator.direction_weight);
  }
  if (!in.damage().empty()) {
    std::fprintf(stderr, "  damaged: %zu stretches of the log (%llu bytes) skipped, not events\n",
                 in.damage().size(), damaged_bytes);
  }
  // the stream rule (compensator.hpp, kRestartRun) is the daemon's: its events counted alike
  if (k.seq_gaps || k.stream_restarts) {
    std::fprintf(stderr, "  seq gaps %lld (%lld commands missing), stream restarts %lld\n",
                 static_cast<long long>(k.seq_gaps), static_cast<long long>(k.seq_missing),
                 static_cast<long long>(k.stream_restarts));
  }
  // the limits (max_correction, max_correction_step, out_of_limits: clamp), counted as the daemon's status counts them
  if (k.clamped || k.held_back || k.clamped_input) {
    std::fprintf(stderr, "  clamped %lld (%lld held back towards none), commands clamped into limits %lld\n",
                 static_cast<long long>(k.clamped), static_cast<long long>(k.held_back),
                 static_cast<long long>(k.clamped_input));
  }
  for (int r = 0; r < chaincomp::kNumReasons; ++r) {
    if (k.rejected[r]) {
      std::fprintf(stderr, "  rejected %-20s %lld\n", chaincomp::reject_name(static_cast<chaincomp::Reject>(r)),
                   static_cast<long long>(k.rejected[r]));
    }
  }
  if (updater.received()) {
    std::fprintf(stderr, "  params updates: %lld received, %lld applied (last seq %lld)\n",
                 static_cast<long long>(updater.received()), static_cast<long long>(updater.version()),
                 static_cast<long long>(updater.last_seq()));
    for (int r = 0; r < chaincomp::kNumRefusals; ++r) {
      if (updater.refused()[r]) {
        std::fprintf(stderr, "  params updates refused %-14s %lld\n", chaincomp::refuse_name(static_cast<chaincomp::Refuse>(r)),
                     static_cast<long long>(updater.refused()[r]));
      }
    }
  }
  for (int i = 0; i < n; ++i) {
    std::fprintf(stderr, "  correction %-4s max %.6g %s, RMS %.6g %s\n", entry->info->axes[i].name, max_abs[i],
                 entry->info->axes[i].unit, k.published ? std::sqrt(sum_sq[i] / k.published) : 0.0,
                 entry->info->axes[i].unit);
  }
  return 0;
}

// Exit codes, as chaincomp's (docs/reference/grammar.md): 0 done, 2 bad input (one line, from fail),
// 3 internal error (one line here, not an abort's core dump).
int main(int argc, char** argv) {
  try {
    return run_replay(argc, argv);
  } catch (const std::exception& e) {
    std::fprintf(stderr, "chaincomp replay: internal error: %s (please report this with the command line)\n",
                 e.what());
  } catch (...) {
    std::fprintf(stderr, "chaincomp replay: internal error (please report this with the command line)\n");
  }
  return 3;
}
