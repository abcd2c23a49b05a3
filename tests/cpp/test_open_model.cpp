// open_model: which model a machine file gets, and the cache key of runtime-built ones
// (the build itself and its loading are tested end to end in tests/python/emit/test_build.py).
#include <catch2/catch.hpp>

#include <unistd.h>

#include <cmath>
#include <cstdlib>
#include <fstream>
#include <string>
#include <vector>

#include "chaincomp/compensate.hpp"
#include "chaincomp/model_info.hpp"
#include "chaincomp/open_model.hpp"
#include "chaincomp/params_io.hpp"
#include "chaincomp/varying.hpp"

namespace {

const std::string kMachine = std::string(CHAINCOMP_SOURCE_DIR) + "/configs/machines/angle_head.yaml";

std::string read(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  return std::string((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
}

}  // namespace

TEST_CASE("a bundled machine file gets its compiled-in model, by name and hash", "[open_model]") {
  std::string error;
  const chaincomp::ModelEntry* e = chaincomp::open_model(kMachine, "", error);
  REQUIRE(e != nullptr);
  CHECK(e == chaincomp::find_model("angle_head"));
  CHECK(chaincomp::find_compiled_model("angle_head", read(kMachine)) == e);
  CHECK(chaincomp::find_compiled_model("angle_head", read(kMachine) + " ") == nullptr);
}

TEST_CASE("the cache path holds the name, the content hash and the toolchain hash", "[open_model]") {
  // FNV-1a 64 of "" is the offset basis; of "a" the FNV reference's af63dc4c8601ec8c
  CHECK(chaincomp::model_cache_path("/c", "m", "", "a") == "/c/m-cbf29ce484222325-af63dc4c8601ec8c/m.so");
  std::string error;
  const std::string tc = chaincomp::model_toolchain(error);
  REQUIRE(error.empty());
  CHECK(tc.rfind("chaincomp model abi ", 0) == 0);
  CHECK(tc.find("-fPIC") != std::string::npos);
}

TEST_CASE("the cache folder follows XDG_CACHE_HOME, else HOME", "[open_model]") {
  const char* old_xdg = std::getenv("XDG_CACHE_HOME");
  const std::string keep = old_xdg ? old_xdg : "";
  std::string error;
  setenv("XDG_CACHE_HOME", "/x/cache", 1);
  CHECK(chaincomp::model_cache_root(error) == "/x/cache/chaincomp");
  setenv("XDG_CACHE_HOME", "relative", 1);  // XDG: a relative path is ignored
  CHECK(chaincomp::model_cache_root(error) == std::string(std::getenv("HOME")) + "/.cache/chaincomp");
  if (old_xdg) setenv("XDG_CACHE_HOME", keep.c_str(), 1); else unsetenv("XDG_CACHE_HOME");
}

// --model LIB.so is checked as the cache is, before dlopen runs any of it: LIB.so.sha256 beside
// it in sha256sum's format. The advice of the refusal is run here as given (coreutils' sha256sum
// writes the record): after it the file reaches dlopen, which refuses what is not a library.
TEST_CASE("a --model file is checked against its .sha256 first; one that is not a library is refused",
          "[open_model]") {
  char dir_template[] = "/tmp/chaincomp_model_XXXXXX";
  REQUIRE(mkdtemp(dir_template) != nullptr);
  const std::string dir = dir_template, lib = dir + "/notlib.so";
  {
    std::ofstream(lib, std::ios::binary) << read(kMachine);  // not a library at all
  }
  std::string error;
  CHECK(chaincomp::open_model(kMachine, lib, error) == nullptr);
  const std::string advice = "(cd " + dir + " && sha256sum notlib.so > notlib.so.sha256)";
  CHECK(error == "--model: " + lib + ": no notlib.so.sha256 beside it, the digest chaincomp build records (build -o "
                 "DIR copies both): copy the two together, or for a library you built and trust record it with " +
                 advice);
  REQUIRE(std::system(advice.c_str()) == 0);
  CHECK(chaincomp::open_model(kMachine, lib, error) == nullptr);
  CHECK(error.rfind("--model: " + lib + ": cannot load: ", 0) == 0);
  CHECK(error.find('\n') == std::string::npos);
  {
    std::ofstream(lib, std::ios::binary | std::ios::app) << "changed";  // after its digest was recorded
  }
  CHECK(chaincomp::open_model(kMachine, lib, error) == nullptr);
  CHECK(error == "--model: " + lib + ": not the library recorded in notlib.so.sha256 (its SHA-256 differs: truncated "
                 "or overwritten since it was built): copy it again with its .sha256, or rebuild it with chaincomp "
                 "build " + kMachine + " -o " + dir);
  std::remove(lib.c_str());
  std::remove((lib + ".sha256").c_str());
  CHECK(::rmdir(dir.c_str()) == 0);
}

// The solver compiled once per shape (compensate.hpp's Core) serves a model through the
// varying errors' calls (ModelCalls): a kept workspace on a model whose table rejects beyond
// its end, the stream running onto the end and past it and back. Truth from outside the
// solver: the range (the table's knots, written here) decides outside_table, and at every
// correction the actual pose equals the nominal one at the command; a warm start lands where
// a cold one does (five axes: one solution).
TEST_CASE("a kept workspace onto a rejecting table's end: outside exactly beyond it, else as cold", "[compensate]") {
  std::string error;
  const auto* e = chaincomp::open_machine(std::string(CHAINCOMP_SOURCE_DIR) + "/configs/machines/five_axis_ac.yaml",
                                          error);
  REQUIRE(e != nullptr);
  const auto& info = *e->info;
  std::vector<double> params(info.num_params);
  int exx = -1, column = 0;
  for (int i = 0; i < info.num_params; ++i) {
    params[i] = info.params[i].nominal;
    if (std::string(info.params[i].name) == "EXX") exx = i;
    if (exx < 0 && info.params[i].role == chaincomp::ParamRole::kError) ++column;
  }
  REQUIRE(exx >= 0);
  // X positioning -5 um at the end: the correction pushes X beyond it (Newton iterates there
  // are evaluated held at the end)
  chaincomp::VaryingErrors v;
  const double x[] = {-100, 0, 60, 100}, y[] = {0, 2e-3, -1e-3, -5e-3};
  std::string why;
  int at;
  REQUIRE(chaincomp::add_table(v, exx, column, 0, x, y, 4, chaincomp::Interpolation::kMonotoneCubic,
                               chaincomp::Outside::kReject, why, at));
  alignas(64) static unsigned char model[1 << 14];
  e->prepare(params.data(), model);
  e->attach_varying(model, &v);
  // the same table held beyond its end: the truth where a correction lies past the end (the
  // solver evaluates its iterates so; the entry points give NaN there, as outside the range)
  chaincomp::VaryingErrors held;
  REQUIRE(chaincomp::add_table(held, exx, column, 0, x, y, 4, chaincomp::Interpolation::kMonotoneCubic,
                               chaincomp::Outside::kHold, why, at));
  alignas(64) static unsigned char held_model[1 << 14];
  e->prepare(params.data(), held_model);
  e->attach_varying(held_model, &held);
  std::vector<unsigned char> storage;
  void* ws = chaincomp::aligned_slot(storage, e->workspace_size, e->workspace_align);
  e->init_workspace(ws);
  int ok = 0, outside = 0, past_end = 0;
  for (int k = 0; k < 4000; ++k) {
    // X: 99 -> 100.5 -> 99 (steps of 0.75 um), A through 0 and back (the singular pose: damped,
    // a warm start redone cold), C turning
    const double s = k < 2000 ? k : 4000 - k;
    double cmd[5] = {99.0 + 7.5e-4 * s, 10.0, -50.0, 0.02 * std::cos(0.003 * k), 0.4 + 1e-3 * k};
    double warm[5], cold[5], rw[2], rc[2], actual[6], target[6];
    const int sw = e->compensate(model, ws, cmd, chaincomp::kDefaultDirectionWeight, warm, rw, nullptr);
    const int sc = e->compensate(model, nullptr, cmd, chaincomp::kDefaultDirectionWeight, cold, rc, nullptr);
    INFO("command " << k << " X " << cmd[0]);
    REQUIRE(sw == sc);
    if (cmd[0] > 100) {
      CHECK(sw == static_cast<int>(chaincomp::Status::kOutsideTable));
      for (int i = 0; i < 5; ++i) CHECK(warm[i] == cmd[i]);
      ++outside;
      continue;
    }
    CHECK(sw != static_cast<int>(chaincomp::Status::kOutsideTable));
    if (sw == static_cast<int>(chaincomp::Status::kOk)) {
      ++ok;
      // within tolerance of one solution; near A = 0 (the tool along C) the axes that hold the
      // pose within tolerance spread wider, and at A within 1e-3 rad of 0 C is all but free
      // (the poses are checked below)
      const double spread = std::abs(cmd[3]) > 0.01 ? 1e-6 : 1e-5;
      if (std::abs(cmd[3]) > 1e-3)
        for (int i = 0; i < 5; ++i) CHECK(std::abs(warm[i] - cold[i]) < spread);
      past_end += warm[0] > 100;
      e->pose_nominal(model, cmd, target);
      e->pose_exact(held_model, warm, actual);
      double point = 0, dir = 0;
      for (int i = 0; i < 3; ++i) point += (actual[i] - target[i]) * (actual[i] - target[i]);
      for (int i = 3; i < 6; ++i) dir += (actual[i] - target[i]) * (actual[i] - target[i]);
      CHECK(std::sqrt(point) <= chaincomp::kPointTolerance * (1 + 1e-9));
      CHECK(std::sqrt(dir) <= chaincomp::kDirectionTolerance * (1 + 1e-6));
    } else {
      CHECK(sw == static_cast<int>(chaincomp::Status::kResidual));
      CHECK(std::abs(rw[0] - rc[0]) < 1e-9);
      CHECK(std::abs(rw[1] - rc[1]) < 1e-11);
    }
  }
  CHECK(outside == 1333);  // X beyond 100 on 2 x 666 commands and the turn (k = 2000)
  CHECK(ok > 1000);
  CHECK(past_end > 0);  // corrections beyond the end of the table, as intended
}
