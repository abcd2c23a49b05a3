// The daemon's thermal model: the lag of each term against the closed form of a ramp read at
// uneven times, the readings taken whole or not at all, and lcm-gen's encoding decoded.
#include <catch2/catch.hpp>

#include <cmath>
#include <cstdio>
#include <fstream>
#include <numeric>
#include <unistd.h>
#include <string>
#include <vector>

#include "chaincomp/params_update.hpp"
#include "chaincomp/thermal.hpp"
#include "chaincomp_lcm/lcmt_temperatures.hpp"

namespace {

std::string write_model(const std::string& text) {
  char name[] = "/tmp/chaincomp-thermal-XXXXXX";
  const int fd = mkstemp(name);
  REQUIRE(fd >= 0);
  close(fd);
  std::ofstream(name) << text;
  return name;
}

struct Fixture {
  const chaincomp::ModelEntry& entry = *chaincomp::find_model("five_axis_ac");
  chaincomp::ThermalModel model;
  std::vector<double> base;
  int exx = -1, oas = -1;

  explicit Fixture(const std::string& text) {
    std::string error;
    const std::string path = write_model(text);
    REQUIRE(chaincomp::load_thermal_model(*entry.info, path, model, error));
    std::remove(path.c_str());
    base.assign(entry.info->num_params, 0.0);
    for (int i = 0; i < entry.info->num_params; ++i) {
      base[i] = entry.info->params[i].nominal;
      if (std::string(entry.info->params[i].name) == "EXX") exx = i;
      if (std::string(entry.info->params[i].name) == "Oas") oas = i;
    }
    base[exx] = 2e-3;   // the params file's cold value: the thermal part adds to it
  }
};

chaincomp::Readings reading(double t, std::vector<std::pair<const char*, double>> values, const char* machine = "") {
  chaincomp::Readings r;
  r.utime = static_cast<std::int64_t>(std::llround(t * 1e6));
  r.machine = machine;
  r.num_values = static_cast<int>(values.size());
  for (std::size_t i = 0; i < values.size(); ++i) {
    r.names[i] = values[i].first;
    r.values[i] = values[i].second;
  }
  return r;
}

const char* kModel =
    "machine: five_axis_ac\n"
    "errors:\n"
    "  EXX:\n"
    "    unit: um\n"
    "    offset: 0.5\n"
    "    terms:\n"
    "      - {sensor: T_spindle, gain: 1.5, time_constant: 600}\n"
    "      - {sensor: T_column, gain: -0.4}\n"
    "  Oas:\n"
    "    unit: mm\n"
    "    terms:\n"
    "      - {sensor: T_column, gain: 1.0e-3, time_constant: 3000}\n";

}  // namespace

TEST_CASE("each term's lag is the closed form of a ramp read at uneven times", "[thermal]") {
  Fixture f(kModel);
  chaincomp::ThermalState state(f.model, f.base);
  chaincomp::ParamsUpdate u;
  const double r1 = 0.002, r2 = -0.0005;   // K/s: linear between readings, so the lag is exact
  double t = 0;
  unsigned seed = 7;
  for (int k = 0; k < 3000; ++k) {
    const double t1 = 20 + r1 * t, t2 = 21 + r2 * t;
    REQUIRE(state.take(reading(t, {{"T_spindle", t1}, {"T_ambient", 99.0}, {"T_column", t2}}), "five_axis_ac", u));
    REQUIRE(u.num_values == 2);
    const double lag1 = 20 + r1 * (t - 600 * (1 - std::exp(-t / 600)));
    const double lag2 = 21 + r2 * (t - 3000 * (1 - std::exp(-t / 3000)));
    CHECK(u.names[0] == "EXX");
    CHECK(u.values[0] == Approx(2e-3 + 0.5e-3 + 1.5e-3 * (lag1 - 20) - 0.4e-3 * (t2 - 20)).margin(1e-12));
    CHECK(u.names[1] == "Oas");
    CHECK(u.values[1] == Approx(0 + 1e-3 * (lag2 - 20)).margin(1e-12));
    seed = seed * 1103515245u + 12345u;
    t += 0.1 + 2.0 * ((seed >> 16) % 1000) / 1000.0;
  }
  CHECK(state.received() == 3000);
}

TEST_CASE("readings are taken whole or not at all, and only once every sensor has been read", "[thermal]") {
  Fixture f(kModel);
  chaincomp::ThermalState state(f.model, f.base);
  chaincomp::ParamsUpdate u;
  using R = chaincomp::ReadingRefuse;
  auto refused = [&](R r) { return state.refused()[static_cast<int>(r)]; };
  CHECK_FALSE(state.take(reading(0, {{"T_spindle", 20.0}}), "five_axis_ac", u));   // T_column not yet read
  CHECK(std::accumulate(state.refused().begin(), state.refused().end(), 0LL) == 0);
  CHECK_FALSE(state.take(reading(1, {{"T_column", 20.0}}, "vmc_xyz"), "five_axis_ac", u));
  CHECK(refused(R::kWrongMachine) == 1);
  // a NaN or a broken sensor's 400 degC refuses the message: T_column is still unread after it
  CHECK_FALSE(state.take(reading(1, {{"T_column", 20.0}, {"T_spindle", NAN}}), "five_axis_ac", u));
  CHECK_FALSE(state.take(reading(1, {{"T_column", 400.0}}), "five_axis_ac", u));
  CHECK(refused(R::kBadValue) == 2);
  CHECK(state.take(reading(1, {{"T_column", 20.0}}, "five_axis_ac"), "five_axis_ac", u));
  CHECK_FALSE(state.take(reading(1, {{"T_column", 20.5}}), "five_axis_ac", u));   // not after its last reading
  CHECK_FALSE(state.take(reading(0.5, {{"T_column", 20.5}}), "five_axis_ac", u));
  CHECK_FALSE(state.take(reading(2, {{"T_spindle", 20.5}, {"T_spindle", 20.6}}), "five_axis_ac", u));
  CHECK(refused(R::kTimeNotIncreasing) == 3);
  CHECK(state.take(reading(2, {{"T_spindle", 21.0}, {"Unknown", -500.0}}), "five_axis_ac", u));   // others' sensors ignored
  state.count_undecodable();
  CHECK(refused(R::kUndecodable) == 1);
  CHECK(state.received() == 10);
}

TEST_CASE("temperature readings decode as lcm-gen encodes them, and nothing past their bounds", "[thermal]") {
  chaincomp_lcm::lcmt_temperatures m;
  m.utime = 123456789;
  m.machine = "";
  m.num_values = 2;
  m.names = {"T_spindle", "T_bed"};
  m.values = {24.5, 19.75};
  std::vector<unsigned char> buf(m.getEncodedSize());
  REQUIRE(m.encode(buf.data(), 0, static_cast<int>(buf.size())) == static_cast<int>(buf.size()));
  const std::int64_t hash = chaincomp_lcm::lcmt_temperatures::getHash();
  chaincomp::Readings r;
  REQUIRE(chaincomp::decode_readings(buf.data(), buf.size(), hash, r));
  CHECK(r.utime == 123456789);
  CHECK(r.machine.empty());
  REQUIRE(r.num_values == 2);
  CHECK((r.names[0] == "T_spindle" && r.names[1] == "T_bed"));
  CHECK((r.values[0] == 24.5 && r.values[1] == 19.75));
  for (std::size_t cut = 0; cut < buf.size(); ++cut) CHECK_FALSE(chaincomp::decode_readings(buf.data(), cut, hash, r));
  CHECK_FALSE(chaincomp::decode_readings(buf.data(), buf.size(), hash ^ 1, r));
  m.num_values = 0;
  m.names.clear();
  m.values.clear();
  std::vector<unsigned char> empty(m.getEncodedSize());
  REQUIRE(m.encode(empty.data(), 0, static_cast<int>(empty.size())) > 0);
  CHECK_FALSE(chaincomp::decode_readings(empty.data(), empty.size(), hash, r));
}
