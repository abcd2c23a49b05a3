// Zero heap allocations in 10^5 calls of every generated function and of compensate, with
// constant errors and with the bundled laser calibration's tables attached.
#include <catch2/catch.hpp>

#include <cstddef>
#include <cstdint>
#include <cstring>
#include <cstdlib>
#include <new>
#include <string>
#include <vector>

#include "chaincomp/compensate.hpp"
#include "chaincomp/model_info.hpp"
#include "chaincomp/params_io.hpp"
#include "chaincomp/params_update.hpp"
#include "chaincomp/varying.hpp"

extern "C" {
void* __real_malloc(std::size_t);
void* __real_calloc(std::size_t, std::size_t);
void* __real_realloc(void*, std::size_t);
void* __real_aligned_alloc(std::size_t, std::size_t);
int __real_posix_memalign(void**, std::size_t, std::size_t);
}

namespace {
std::size_t g_allocations = 0;
}

// operator new lives in the shared libstdc++, out of reach of --wrap: replace it here.
void* operator new(std::size_t n) {
  ++g_allocations;
  if (void* p = __real_malloc(n ? n : 1)) return p;
  throw std::bad_alloc();
}
void* operator new[](std::size_t n) { return operator new(n); }
void operator delete(void* p) noexcept { std::free(p); }
void operator delete[](void* p) noexcept { std::free(p); }
void operator delete(void* p, std::size_t) noexcept { std::free(p); }
void operator delete[](void* p, std::size_t) noexcept { std::free(p); }

extern "C" {
void* __wrap_malloc(std::size_t n) { ++g_allocations; return __real_malloc(n); }
void* __wrap_calloc(std::size_t a, std::size_t b) { ++g_allocations; return __real_calloc(a, b); }
void* __wrap_realloc(void* p, std::size_t n) { ++g_allocations; return __real_realloc(p, n); }
void* __wrap_aligned_alloc(std::size_t a, std::size_t n) { ++g_allocations; return __real_aligned_alloc(a, n); }
int __wrap_posix_memalign(void** p, std::size_t a, std::size_t n) { ++g_allocations; return __real_posix_memalign(p, a, n); }
}

TEST_CASE("the allocation counter sees operator new", "[alloc]") {
  const std::size_t before = g_allocations;
  auto* p = new std::vector<double>(100);
  delete p;
  CHECK(g_allocations - before >= 1);
}

TEST_CASE("generated functions and compensate (cold and with a kept workspace) never allocate", "[alloc]") {
  constexpr int kCalls = 100000;
  alignas(64) static unsigned char model[1 << 14];
  for (std::size_t m = 0; m < chaincomp::model_count(); ++m) {
    const chaincomp::ModelEntry& e = *chaincomp::model_at(m);
    INFO("machine " << e.info->name);
    double params[256], axes[16], out[16], jac[6 * 16], residual[2];
    REQUIRE(e.info->num_params <= 256);
    for (int i = 0; i < e.info->num_params; ++i) params[i] = e.info->params[i].nominal + 1e-5;
    for (int i = 0; i < e.info->num_axes; ++i) axes[i] = 0.5 * (e.info->axes[i].lower + e.info->axes[i].upper) *
                                                       e.info->axes[i].to_internal + 0.1;
    e.prepare(params, model);
    // a kept workspace (warm starts), set up before counting
    alignas(64) static unsigned char workspace[1 << 15];
    REQUIRE(e.workspace_size <= sizeof workspace);
    REQUIRE(64 % e.workspace_align == 0);
    e.init_workspace(workspace);
    const std::size_t before = g_allocations;
    double sink = 0;
    for (int k = 0; k < kCalls; ++k) {
      axes[0] += 1e-9;
      e.pose_exact(model, axes, out);
      sink += out[0];
      e.pose_nominal(model, axes, out);
      e.pose_jacobian(model, axes, out, jac);
      for (int order = 1; order <= e.max_order; ++order) e.error(model, axes, order, out);
      e.compensate(model, nullptr, axes, chaincomp::kDefaultDirectionWeight, out, residual, nullptr);
      e.compensate(model, workspace, axes, chaincomp::kDefaultDirectionWeight, out, residual, nullptr);
      sink += out[0] + jac[0];
    }
    CHECK(g_allocations - before == 0);
    CHECK(sink == sink);
  }
}

TEST_CASE("with 18 tables of 101 points attached, compensate and the poses never allocate", "[alloc]") {
  constexpr int kCalls = 100000;
  // start-up (allowed to allocate): the machine, the params file with its tables
  std::string error;
  const chaincomp::ModelEntry* e =
      chaincomp::open_machine(std::string(CHAINCOMP_SOURCE_DIR) + "/configs/machines/five_axis_ac.yaml", error);
  REQUIRE(e != nullptr);
  std::vector<double> params;
  chaincomp::VaryingErrors varying;
  REQUIRE(chaincomp::load_params(*e->info, std::string(CHAINCOMP_SOURCE_DIR) + "/configs/params/five_axis_ac-laser.yaml",
                                 params, varying, error));
  REQUIRE(varying.count == 18);
  alignas(64) static unsigned char model[1 << 14];
  e->prepare(params.data(), model);
  e->attach_varying(model, &varying);
  alignas(64) static unsigned char workspace[1 << 15];
  REQUIRE(e->workspace_size <= sizeof workspace);
  e->init_workspace(workspace);
  double axes[5] = {-350.0, -250.0, -390.0, 0.5, 0.3}, out[16], jac[6 * 16], gain[6 * 64], residual[2];
  const std::size_t before = g_allocations;
  double sink = 0;
  int ok = 0;
  for (int k = 0; k < kCalls; ++k) {
    // sweep X, Y and Z through their tables (interval changes, direct lookups)
    axes[0] = -350.0 + 700.0 * (k % 1000) / 1000.0;
    axes[1] = -250.0 + 500.0 * (k % 777) / 777.0;
    axes[2] = -390.0 + 380.0 * (k % 555) / 555.0;
    ok += e->compensate(model, nullptr, axes, chaincomp::kDefaultDirectionWeight, out, residual, nullptr) == 0;
    sink += out[0];
    ok += e->compensate(model, workspace, axes, chaincomp::kDefaultDirectionWeight, out, residual, nullptr) == 0;
    e->pose_exact(model, axes, out);
    e->pose_jacobian(model, axes, out, jac);
    e->pose_jacobian_gain(model, axes, out, jac, gain);
    for (int order = 1; order <= e->max_order; ++order) e->error(model, axes, order, out);
    sink += out[0] + jac[0] + gain[0];
  }
  CHECK(g_allocations - before == 0);
  CHECK(ok == 2 * kCalls);
  CHECK(sink == sink);
}

namespace {

// An lcmt_params_update payload as LCM encodes it (big-endian; strings with their NUL).
struct Payload {
  std::vector<unsigned char> b;
  void u64(std::uint64_t v) { for (int i = 7; i >= 0; --i) b.push_back(static_cast<unsigned char>(v >> (8 * i))); }
  void u32(std::uint32_t v) { for (int i = 3; i >= 0; --i) b.push_back(static_cast<unsigned char>(v >> (8 * i))); }
  void str(const std::string& s) { u32(static_cast<std::uint32_t>(s.size() + 1)); b.insert(b.end(), s.begin(), s.end()); b.push_back(0); }
  void f64(double d) { std::uint64_t v; std::memcpy(&v, &d, 8); u64(v); }
};

}  // namespace

TEST_CASE("decoding and applying params updates never allocates, nor does compensating between them", "[alloc]") {
  constexpr int kUpdates = 20000;
  const chaincomp::ModelEntry& e = *chaincomp::find_model("five_axis_ac");
  std::string error;
  std::vector<double> params;
  chaincomp::VaryingErrors varying;
  REQUIRE(chaincomp::load_params(*e.info, std::string(CHAINCOMP_SOURCE_DIR) + "/configs/params/five_axis_ac-laser.yaml",
                                 params, varying, error));
  alignas(64) static unsigned char model[1 << 14];
  e.prepare(params.data(), model);
  e.attach_varying(model, &varying);
  chaincomp::ParamsUpdater up(e, model, &varying, params, chaincomp::ParamsUpdateLimits{});
  // two payloads set up before counting: seq and values are patched in place
  const std::uint64_t hash = 0x1234567890abcdefULL;
  Payload p;
  p.u64(hash);
  p.u64(0);          // utime
  p.u64(0);          // seq (at byte 16)
  p.str("five_axis_ac");
  p.u64(0);          // every instance
  p.u32(3);
  for (const char* name : {"Oas", "ThetaAs", "Ocx"}) p.str(name);
  const std::size_t values_at = p.b.size();
  for (int i = 0; i < 3; ++i) p.f64(0.0);
  chaincomp::ParamsUpdate u;
  double axes[5] = {10.0, -20.0, -100.0, 0.5, -0.8}, out[16], residual[2];
  const std::size_t before = g_allocations;
  int applied = 0;
  for (int k = 1; k <= kUpdates; ++k) {
    for (int i = 0; i < 8; ++i) p.b[16 + i] = static_cast<unsigned char>(std::uint64_t(k) >> (8 * (7 - i)));
    const double v[3] = {1e-3 * (k % 5), 1e-5 * (k % 3), -2e-3 * (k % 7)};
    for (int j = 0; j < 3; ++j) {
      std::uint64_t bits;
      std::memcpy(&bits, &v[j], 8);
      for (int i = 0; i < 8; ++i) p.b[values_at + 8 * j + i] = static_cast<unsigned char>(bits >> (8 * (7 - i)));
    }
    REQUIRE(chaincomp::decode_params_update(p.b.data(), p.b.size(), static_cast<std::int64_t>(hash), u));
    applied += up.apply(u, 1, 10000LL * k);   // 10 ms of command time apart: each is applied
    e.compensate(model, nullptr, axes, chaincomp::kDefaultDirectionWeight, out, residual, nullptr);
  }
  CHECK(g_allocations - before == 0);
  CHECK(applied == kUpdates);
  CHECK(up.params()[0] == up.params()[0]);
}
