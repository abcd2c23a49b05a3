// The C++ params loader and the machine-file hash check.
#include <catch2/catch.hpp>

#include <cmath>
#include <cstdio>
#include <fstream>
#include <string>
#include <vector>

#include "chaincomp/params_io.hpp"

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
      {"values:\n  Ocx: 1\n  Ocy: 2 arcsec\n", ":3: values.Ocy", "is a angle unit"},
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
