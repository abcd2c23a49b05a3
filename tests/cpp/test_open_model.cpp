// open_model: which model a machine file gets, and the cache key of runtime-built ones
// (the build itself and its loading are tested end to end in tests/python/test_build.py).
#include <catch2/catch.hpp>

#include <cstdlib>
#include <fstream>
#include <string>

#include "chaincomp/open_model.hpp"
#include "chaincomp/params_io.hpp"

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

TEST_CASE("a --model file that is not a library is refused in one line", "[open_model]") {
  std::string error;
  CHECK(chaincomp::open_model(kMachine, kMachine, error) == nullptr);
  CHECK(error.rfind("--model: " + kMachine + ": cannot load: ", 0) == 0);
  CHECK(error.find('\n') == std::string::npos);
}
