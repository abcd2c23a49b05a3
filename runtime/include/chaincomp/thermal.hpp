// Thermal models (chaincomp thermal fit's files, docs/guide/thermal.md): error values that
// follow named temperatures through first-order lags,
//     value = params value + offset + sum gain * (lag(T, tau) - T_ref),
// the lag exact for readings linear in between and settled at each sensor's first reading
// (the same as chaincomp/measure/thermal.py's lag). The loader reads the file as the Python
// one does (the same messages: tests/conformance/thermal); the state advances the lags on
// each reading and hands the values to a ParamsUpdater. Loading allocates; readings do not.
#pragma once

#include <array>
#include <cstdint>
#include <string>
#include <string_view>
#include <vector>

#include "chaincomp/model_info.hpp"
#include "chaincomp/params_update.hpp"
#include "chaincomp/stream_order.hpp"

namespace chaincomp {

constexpr int kMaxThermalErrors = 64;    // measure/thermal.py MAX_ERRORS
constexpr int kMaxThermalTerms = 8;      // MAX_TERMS
constexpr int kMaxSensors = 64;          // MAX_SENSORS
constexpr int kMaxReadings = 64;         // lcmt_temperatures.MAX_VALUES

struct ThermalTerm {
  int sensor = 0;         // into ThermalModel::sensors
  double gain = 0;        // internal units (mm, rad) per K
  double time_constant = 0;  // s; 0: no lag
};

struct ThermalError {
  int param = 0;          // kParams order
  const char* name = "";  // the parameter's (the model's static table)
  double offset = 0;      // internal units
  int num_terms = 0;
  std::array<ThermalTerm, kMaxThermalTerms> terms{};
};

struct ThermalModel {
  std::string machine;
  double reference = 20.0;  // degC
  int num_errors = 0;
  std::array<ThermalError, kMaxThermalErrors> errors{};
  std::vector<std::string> sensors;   // at most kMaxSensors
};

bool load_thermal_model(const MachineInfo& info, const std::string& path, ThermalModel& out, std::string& error);

struct Readings {
  std::int64_t utime = 0;
  std::string_view machine;
  int num_values = 0;
  std::array<std::string_view, kMaxReadings> names{};
  std::array<double, kMaxReadings> values{};
};

// An lcmt_temperatures payload into `out` (names point into `data`); false for anything not
// one of this version or past its bounds.
bool decode_readings(const void* data, std::size_t size, std::int64_t fingerprint, Readings& out) noexcept;

enum class ReadingRefuse : int {
  kUndecodable = 0,
  kWrongMachine = 1,
  kBadValue = 2,        // not finite, or outside -100 .. 300 degC
  kTimeNotIncreasing = 3,  // for a sensor the model reads: at or before its last reading, or more than
                           // kMaxTimeJump after it (the stream rule, stream_order.hpp, per sensor)
};
constexpr int kNumReadingRefusals = 4;

class ThermalState {
 public:
  // `base`: the params file's values (internal units, kParams order).
  ThermalState(const ThermalModel& model, const std::vector<double>& base);

  // Takes the readings of the model's sensors (all of the message's or none); true when every
  // sensor has a reading and the new error values are in `update`, for the updater.
  bool take(const Readings& r, std::string_view machine, ParamsUpdate& update) noexcept;
  void count_undecodable() noexcept { ++received_; ++refused_[0]; }
  // A new stream (a control message's reset): each sensor's next reading is taken whatever its
  // time, and its lags settle there (as at a sensor's first reading).
  void reset() noexcept;

  std::int64_t received() const noexcept { return received_; }
  const std::array<std::int64_t, kNumReadingRefusals>& refused() const noexcept { return refused_; }
  const ThermalModel& model() const noexcept { return model_; }

 private:
  bool refuse(ReadingRefuse r) noexcept { ++refused_[static_cast<int>(r)]; return false; }

  ThermalModel model_;
  std::vector<double> base_;
  std::vector<double> last_u_;            // per sensor: last reading (degC)
  std::vector<StreamOrder> order_;        // per sensor: its readings' utime (the last one's time)
  std::vector<unsigned char> read_;       // per sensor: has a reading
  std::vector<unsigned char> settle_;     // per sensor: its next reading settles the lags (first, restart, reset)
  std::array<StreamOrder::Verdict, kMaxReadings> verdict_{};  // per value of a message
  std::array<std::array<double, kMaxThermalTerms>, kMaxThermalErrors> lag_{};  // per term
  std::array<int, kMaxReadings> slot_{};  // per value of a message: its sensor, or -1
  std::int64_t received_ = 0;
  std::array<std::int64_t, kNumReadingRefusals> refused_{};
};

}  // namespace chaincomp
