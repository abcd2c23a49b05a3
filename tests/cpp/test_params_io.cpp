// The C++ params loader and the machine-file hash check.
#include <catch2/catch.hpp>

#include <cmath>
#include <cstdio>
#include <fstream>
#include <string>
#include <vector>

#include "chaincomp/params_io.hpp"
#include "chaincomp/yaml_strict.hpp"

namespace {

std::string write_temp(const std::string& name, const std::string& text) {
  const std::string path = std::string("/tmp/chaincomp_test_") + name;
  std::ofstream(path) << text;
  return path;
}

const std::string kMachine = std::string(CHAINCOMP_SOURCE_DIR) + "/configs/machines/angle_head.yaml";

int index_of(const chaincomp::MachineInfo& info, const char* name) {
  for (int i = 0; i < info.num_params; ++i) {
    if (std::string(info.params[i].name) == name) return i;
  }
  return -1;
}

}  // namespace

TEST_CASE("a bundled machine file opens its compiled model", "[params]") {
  std::string error;
  const chaincomp::ModelEntry* e = chaincomp::open_machine(kMachine, error);
  REQUIRE(e != nullptr);
  CHECK(std::string(e->info->name) == "angle_head");
}

TEST_CASE("a changed machine file is refused with a rebuild hint", "[params]") {
  std::ifstream in(kMachine);
  std::string text((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  const std::string path = write_temp("changed.yaml", text + "\n# edited\n");
  std::string error;
  CHECK(chaincomp::open_machine(path, error) == nullptr);
  CHECK(error.find("changed since its model was compiled") != std::string::npos);
  CHECK(error.find("rebuild") != std::string::npos);
}

TEST_CASE("params load with units into internal values", "[params]") {
  std::string error;
  const auto* e = chaincomp::open_machine(kMachine, error);
  REQUIRE(e != nullptr);
  const std::string path = write_temp("ok.yaml",
      "machine: angle_head\nvalues:\n  Ocx: 0.005\n  Ocy: -15 um\n  ThetaAs: 100\n  ThetaCh: 0.5 mrad\n");
  std::vector<double> v;
  REQUIRE(chaincomp::load_params(*e->info, path, v, error));
  CHECK(v[index_of(*e->info, "Ocx")] == Approx(0.005));
  CHECK(v[index_of(*e->info, "Ocy")] == Approx(-0.015));
  CHECK(v[index_of(*e->info, "ThetaAs")] == Approx(100.0 * M_PI / 180.0 / 3600.0));
  CHECK(v[index_of(*e->info, "ThetaCh")] == Approx(0.5e-3));
  CHECK(v[index_of(*e->info, "G")] == Approx(20.0));  // nominal kept
  CHECK(v[index_of(*e->info, "DY")] == 0.0);           // unlisted error
}

TEST_CASE("bad params files name file, line and key", "[params]") {
  std::string error;
  const auto* e = chaincomp::open_machine(kMachine, error);
  REQUIRE(e != nullptr);
  struct Case {
    const char* body;
    const char* line_key;
    const char* words;
  };
  const Case cases[] = {
      {"values:\n  Nope: 1\n", ":2: values.Nope", "unknown symbol"},
      {"values:\n  Ocx: 1\n  Ocy: 2 arcsec\n", ":3: values.Ocy", "is an angle unit"},
      {"values:\n  Ocx: .nan\n", ":2: values.Ocx", "expected a"},
      {"values:\n  Ocx:\n", ":2: values.Ocx", "missing value"},
      {"values:\n  Ocx: 1 furlong\n", ":2: values.Ocx", "unknown unit"},
      {"values:\n  Ap: 3\n", ":2: values.Ap", "is an axis"},
      {"machine: other\nvalues: {}\n", ":1: machine", "not 'angle_head'"},
      {"values:\n  Ocx: [1, 2\n", ":", "YAML syntax error"},
  };
  int i = 0;
  for (const Case& c : cases) {
    const std::string path = write_temp("bad" + std::to_string(i++) + ".yaml", c.body);
    std::vector<double> v;
    INFO(c.body);
    CHECK_FALSE(chaincomp::load_params(*e->info, path, v, error));
    CHECK(error.find(path + c.line_key) != std::string::npos);
    CHECK(error.find(c.words) != std::string::npos);
  }
}

namespace {

const std::string kFiveMachine = std::string(CHAINCOMP_SOURCE_DIR) + "/configs/machines/five_axis_ac.yaml";

// A params file with one table (EXX over X, line 3 on) and one polynomial (EBX, line 12 on).
const std::string kTables =
    "machine: five_axis_ac\n"                  // 1
    "values:\n"                                // 2
    "  EXX:\n"                                 // 3
    "    axis: X\n"                            // 4
    "    units: [mm, um]\n"                    // 5
    "    interpolation: monotone_cubic\n"      // 6
    "    outside: hold\n"                      // 7
    "    table:\n"                             // 8
    "      - [-400, 0.0]\n"                    // 9
    "      - [0, 2.5]\n"                       // 10
    "      - [400, 1.0]\n"                     // 11
    "  EBX:\n"                                 // 12
    "    axis: X\n"                            // 13
    "    units: [mm, arcsec]\n"                // 14
    "    polynomial: [1.0, 0.01, -2.0e-5]\n"   // 15
    "    range: [-400, 400]\n"                 // 16
    "    outside: reject\n"                    // 17
    "  ECX: 2 arcsec\n";                       // 18

std::string replace(std::string text, const std::string& from, const std::string& to) {
  const auto at = text.find(from);
  REQUIRE(at != std::string::npos);
  return text.replace(at, from.size(), to);
}

}  // namespace

TEST_CASE("tables and polynomials load into fixed storage, in internal units", "[params][varying]") {
  std::string error;
  const auto* e = chaincomp::open_machine(kFiveMachine, error);
  REQUIRE(e != nullptr);
  std::vector<double> v;
  chaincomp::VaryingErrors varying;
  REQUIRE(chaincomp::load_params(*e->info, write_temp("tables.yaml", kTables), v, varying, error));
  REQUIRE(varying.count == 2);
  const auto& exx = varying.items[0];
  CHECK(exx.param == index_of(*e->info, "EXX"));
  CHECK(exx.column == 0);
  CHECK(exx.axis == 0);
  CHECK(exx.kind == chaincomp::VaryingKind::kTable);
  CHECK(exx.interpolation == chaincomp::Interpolation::kMonotoneCubic);
  CHECK(exx.count == 3);
  double value, slope;
  CHECK(chaincomp::evaluate(varying, exx, 0.0, nullptr, value, slope));
  CHECK(value == Approx(2.5e-3));
  CHECK(chaincomp::evaluate(varying, exx, 500.0, nullptr, value, slope));  // hold
  CHECK(value == Approx(1.0e-3));
  const auto& ebx = varying.items[1];
  CHECK(ebx.kind == chaincomp::VaryingKind::kPolynomial);
  CHECK(chaincomp::evaluate(varying, ebx, 100.0, nullptr, value, slope));
  CHECK(value == Approx((1.0 + 1.0 - 0.2) * M_PI / 648000.0));
  CHECK(slope == Approx((0.01 - 4e-3) * M_PI / 648000.0));
  CHECK_FALSE(chaincomp::evaluate(varying, ebx, 401.0, nullptr, value, slope));  // reject
  CHECK(v[index_of(*e->info, "EXX")] == 0.0);
  CHECK(v[index_of(*e->info, "ECX")] == Approx(2 * M_PI / 648000.0));
  CHECK(chaincomp::describe_varying(varying) == "2 errors vary along an axis: 1 table (3 points), 1 polynomial");
  // the constants-only loader refuses it rather than drop the tables
  CHECK_FALSE(chaincomp::load_params(*e->info, write_temp("tables.yaml", kTables), v, error));
  CHECK(error.find("values.EXX") != std::string::npos);
}

TEST_CASE("the bundled laser calibration loads: 18 tables of 101 points", "[params][varying]") {
  std::string error;
  const auto* e = chaincomp::open_machine(kFiveMachine, error);
  REQUIRE(e != nullptr);
  std::vector<double> v;
  chaincomp::VaryingErrors varying;
  REQUIRE(chaincomp::load_params(*e->info, std::string(CHAINCOMP_SOURCE_DIR) + "/configs/params/five_axis_ac-laser.yaml",
                                 v, varying, error));
  CHECK(varying.count == 18);
  for (int i = 0; i < varying.count; ++i) {
    CHECK(varying.items[i].count == 101);
    CHECK(varying.items[i].inv_step > 0);
  }
  CHECK(varying.storage.size() == 18u * 101u * chaincomp::kTableRecord);
}

TEST_CASE("bad tables and polynomials name file, line and key", "[params][varying]") {
  std::string error;
  const auto* e = chaincomp::open_machine(kFiveMachine, error);
  REQUIRE(e != nullptr);
  struct Case {
    std::string body;
    const char* line_key;
    const char* words;
  };
  const Case cases[] = {
      {replace(kTables, "[0, 2.5]", "[-500, 2.5]"), ":10: values.EXX.table[1]", "positions must increase: -500 follows -400"},
      {replace(kTables, "[0, 2.5]", "[-400, 2.5]"), ":10: values.EXX.table[1]", "duplicate position -400"},
      {replace(kTables, "[0, 2.5]", "[0, .nan]"), ":10: values.EXX.table[1]", "expected finite numbers"},
      {replace(kTables, "[400, 1.0]", "[.inf, 1.0]"), ":11: values.EXX.table[2]", "expected finite numbers"},
      {replace(kTables, "[0, 2.5]", "[0, abc]"), ":10: values.EXX.table[1]", "expected a number"},
      {replace(kTables, "[0, 2.5]", "[0, 2.5, 3]"), ":10: values.EXX.table[1]", "expected [position, value]"},
      {replace(kTables, "      - [0, 2.5]\n      - [400, 1.0]\n", ""), ":8: values.EXX.table", "at least 2 points, got 1"},
      {replace(kTables, "axis: X\n    units: [mm, um]", "axis: W\n    units: [mm, um]"), ":4: values.EXX.axis",
       "'W' is not an axis of five_axis_ac"},
      {replace(kTables, "axis: X\n    units: [mm, um]", "axis: G\n    units: [mm, um]"), ":4: values.EXX.axis",
       "'G' is not an axis"},
      {replace(kTables, "[mm, um]", "[deg, um]"), ":5: values.EXX.units", "position unit 'deg' is an angle unit, but axis X"},
      {replace(kTables, "[mm, um]", "[mm, arcsec]"), ":5: values.EXX.units", "value unit 'arcsec' is an angle unit, but EXX"},
      {replace(kTables, "[mm, um]", "[mm, furlong]"), ":5: values.EXX.units", "unknown unit 'furlong'"},
      {replace(kTables, "[mm, um]", "mm"), ":5: values.EXX.units", "expected [position unit, value unit]"},
      {replace(kTables, "    units: [mm, um]\n", ""), ":3: values.EXX", "missing required field 'units'"},
      {replace(kTables, "monotone_cubic", "spline"), ":6: values.EXX.interpolation", "linear or monotone_cubic"},
      {replace(kTables, "outside: hold", "outside: clamp"), ":7: values.EXX.outside", "hold or reject"},
      {replace(kTables, "    outside: hold\n", ""), ":3: values.EXX", "missing required field 'outside'"},
      {replace(kTables, "    outside: hold\n", "    outside: hold\n    polynomial: [1]\n"), ":3: values.EXX",
       "not both"},
      {replace(kTables, "    outside: hold\n", "    outside: hold\n    step: 8\n"), ":8: values.EXX.step",
       "unknown field 'step'"},
      {replace(kTables, "[1.0, 0.01, -2.0e-5]", "[1.0, .nan]"), ":15: values.EBX.polynomial[1]", "expected finite"},
      {replace(kTables, "[1.0, 0.01, -2.0e-5]", "[]"), ":15: values.EBX.polynomial", "1 to 16 coefficients"},
      {replace(kTables, "[-400, 400]", "[400, -400]"), ":16: values.EBX.range", "must be below"},
      {replace(kTables, "    range: [-400, 400]\n", ""), ":16: values.EBX.outside", "applies to a polynomial's 'range'"},
      {replace(kTables, "  ECX: 2 arcsec\n", "  G:\n    axis: X\n    units: [mm, mm]\n    polynomial: [1]\n"), ":18: values.G",
       "only error symbols may vary"},
      {replace(kTables, "  ECX: 2 arcsec\n", "  ECX: [1, 2]\n"), ":18: values.ECX", "or a mapping with 'table' or 'polynomial'"},
  };
  int i = 0;
  for (const Case& c : cases) {
    const std::string path = write_temp("badtable" + std::to_string(i++) + ".yaml", c.body);
    std::vector<double> v;
    chaincomp::VaryingErrors varying;
    INFO(c.body);
    CHECK_FALSE(chaincomp::load_params(*e->info, path, v, varying, error));
    INFO(error);
    CHECK(error.find(path + c.line_key + ": ") != std::string::npos);
    CHECK(error.find(c.words) != std::string::npos);
  }
}

TEST_CASE("numbers in messages are written as Python's repr writes them", "[params]") {
  // Python's repr(float), from its documented rule: the shortest digits that read back,
  // fixed notation for decimal exponents -4 <= e < 16, else d.ddde+XX
  const std::pair<double, const char*> cases[] = {
      {1e16, "1e+16"},        {1e15, "1000000000000000.0"}, {0.0001, "0.0001"}, {1e-05, "1e-05"},
      {0.1, "0.1"},           {-0.0, "-0.0"},               {123.456, "123.456"}, {2e18, "2e+18"},
      {1.5e-300, "1.5e-300"}, {5e-324, "5e-324"},           {1.7976931348623157e308, "1.7976931348623157e+308"},
      {170.0, "170.0"},       {-2.5, "-2.5"},               {INFINITY, "inf"},    {-INFINITY, "-inf"},
      {NAN, "nan"},           {123456789012345680000.0, "1.2345678901234568e+20"}};
  for (const auto& [v, text] : cases) CHECK(chaincomp::py_float_repr(v) == text);
}
