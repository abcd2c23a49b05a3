// Driver of tools/bench_chains: ns per call of chaincomp's generated pose_jacobian_gain and of
// SymForce's generated function with the same outputs, for one chain, in one process.
//
// tools/bench_chains writes bench_config.hpp next to the generated code: NQ, NC, NE (axes,
// constants, errors), and, for each side whose code generation finished in time, a
// CC_NS (the chaincomp model's namespace) or a SF_<n> declaration of a plain function
//     void sf_<model>(const Vq& q, const Vc& c, const Ve& e, Pose* pose, Jq* J, Je* G);
// compiled in its own translation unit (the generated SymForce template, instantiated at
// double), so both sides are out-of-line calls compiled with the same flags.
//
// Input (argv[1], text): the params in chaincomp's kParams order; the constants and the
// errors in the machine's order; CHECKS lines "q... | expected pose (numpy exact model)";
// SAMPLES lines of axes. Before timing: chaincomp's pose against numpy's, every SymForce
// output (pose, J at the errors; G at zero errors) against chaincomp's, and chaincomp's G
// against central differences of its own pose_exact in each error; any miss: exit 1,
// nothing timed. Output: one JSON object on stdout.
#include <Eigen/Core>

#include <algorithm>
#include <array>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <fstream>
#include <functional>
#include <string>
#include <vector>

#include "bench_config.hpp"

namespace {

using Vq = Eigen::Matrix<double, NQ, 1>;
using Vc = Eigen::Matrix<double, NC, 1>;
using Ve = Eigen::Matrix<double, NE, 1>;
using Pose6 = Eigen::Matrix<double, 6, 1>;
using Jq = Eigen::Matrix<double, 6, NQ>;
using Je = Eigen::Matrix<double, 6, NE>;

constexpr double kTolerance = 1e-9;
#ifndef SF_TOLERANCE
#define SF_TOLERANCE 1e-9
#endif
// SymForce's outputs: beyond kTolerance, what its quarter turns rounded as chaincomp's
// derivation rounds them can move the pose (bench_chains' export_chain)
constexpr double kSfTolerance = SF_TOLERANCE;

[[noreturn]] void die(const std::string& msg) {
  std::fprintf(stderr, "bench_chains driver: %s\n", msg.c_str());
  std::exit(1);
}

inline void escape(const void* p) noexcept { asm volatile("" : : "g"(p) : "memory"); }

using Clock = std::chrono::steady_clock;
struct Stats {
  double median_ns = 0, best_ns = 0, worst_ns = 0;
  long calls_per_batch = 0;
};

// Batches of calls over the samples, the functions' batches interleaved (order rotating), so
// a drift of the machine's speed moves every figure alike (as tools/bench/bench_codegen.cpp).
std::vector<Stats> time_interleaved(int samples, int batches, double batch_ms,
                                    const std::vector<std::function<void(int)>>& fs) {
  const std::size_t n = fs.size();
  std::vector<Stats> out(n);
  std::vector<std::vector<double>> ns(n);
  std::vector<int> idx(n, 0);
  auto run = [&](std::size_t j, long calls) {
    for (long k = 0; k < calls; ++k) {
      fs[j](idx[j]);
      if (++idx[j] == samples) idx[j] = 0;
    }
  };
  for (std::size_t j = 0; j < n; ++j) {  // warm-up and calibration: >= one pass and 20 ms
    long calls = 0;
    double elapsed = 0;
    const auto t0 = Clock::now();
    while (calls < samples || elapsed < 20e6) {
      run(j, 64);
      calls += 64;
      elapsed = std::chrono::duration<double, std::nano>(Clock::now() - t0).count();
    }
    out[j].calls_per_batch = std::max<long>(16, static_cast<long>(batch_ms * 1e6 * calls / elapsed));
  }
  for (int b = 0; b < batches; ++b) {
    for (std::size_t r = 0; r < n; ++r) {
      const std::size_t j = (static_cast<std::size_t>(b) + r) % n;
      const auto t0 = Clock::now();
      run(j, out[j].calls_per_batch);
      ns[j].push_back(std::chrono::duration<double, std::nano>(Clock::now() - t0).count() /
                      static_cast<double>(out[j].calls_per_batch));
    }
  }
  for (std::size_t j = 0; j < n; ++j) {
    std::sort(ns[j].begin(), ns[j].end());
    out[j].median_ns = ns[j][ns[j].size() / 2];
    out[j].best_ns = ns[j].front();
    out[j].worst_ns = ns[j].back();
  }
  return out;
}

std::string num(double v) {
  if (!std::isfinite(v)) return "null";
  char buf[64];
  std::snprintf(buf, sizeof buf, "%.6g", v);
  return buf;
}

template <class M>
double max_abs_diff(const M& a, const M& b) {
  return (a - b).cwiseAbs().maxCoeff();
}

// Each side a plain function at the input's params (globals: no captured state, one
// indirect call per call for every side alike).
struct Side {
  std::string name;
  void (*call)(const Vq&, Pose6&, Jq&, Je&);
};
Vc g_c;
Ve g_e;

}  // namespace

int main(int argc, char** argv) {
  if (argc < 2) die("usage: driver INPUT.txt [--batches N] [--batch-ms MS]");
  int batches = 51;
  double batch_ms = 2.0;
  for (int i = 2; i + 1 < argc; i += 2) {
    const std::string a = argv[i];
    if (a == "--batches") batches = std::atoi(argv[i + 1]);
    else if (a == "--batch-ms") batch_ms = std::atof(argv[i + 1]);
    else die("unknown option " + a);
  }
  std::ifstream in(argv[1]);
  if (!in) die(std::string("cannot read ") + argv[1]);
  int np = 0, checks = 0, samples = 0;
  in >> np;
  std::vector<double> params(np);
  for (auto& v : params) in >> v;
  for (int i = 0; i < NC; ++i) in >> g_c[i];
  for (int i = 0; i < NE; ++i) in >> g_e[i];
  in >> checks;
  std::vector<Vq> check_q(checks);
  std::vector<Pose6> check_pose(checks);
  for (int s = 0; s < checks; ++s) {
    for (int i = 0; i < NQ; ++i) in >> check_q[s][i];
    for (int i = 0; i < 6; ++i) in >> check_pose[s][i];
  }
  in >> samples;
  std::vector<Vq> qs(samples);
  for (auto& q : qs)
    for (int i = 0; i < NQ; ++i) in >> q[i];
  if (!in || samples < 1) die("input truncated");

  std::vector<Side> sides;
  std::string checks_json;
  double worst_vs_numpy = 0, worst_gain_fd = 0;
#ifdef CC_NS
  namespace cc = CC_NS;
  static_assert(cc::kNumAxes == NQ && cc::kNumErrors == NE, "bench_config.hpp and the model disagree");
  if (np != cc::kNumParams) die("params count differs from kNumParams");
  static cc::Model model;
  cc::prepare(cc::params_from_array(params.data()), model);
  // the same Eigen types as the model's Axes, Pose, Jacobian and Gain: no copies
  sides.push_back({"chaincomp", [](const Vq& q, Pose6& p, Jq& J, Je& G) { cc::pose_jacobian_gain(model, q, p, J, G); }});
  // chaincomp's pose against the numpy exact model; its gains against central differences of
  // its exact pose at zero errors (step 1e-6: truncation ~1e-12 x lengths, rounding ~1e-10)
  for (int s = 0; s < checks; ++s) {
    cc::Pose p;
    cc::pose_exact(model, check_q[s], p);
    worst_vs_numpy = std::max(worst_vs_numpy, max_abs_diff(Pose6(p), check_pose[s]));
  }
  {
    std::vector<double> zero = params;
    std::vector<int> error_index;
    for (int i = 0; i < np; ++i)
      if (cc::kParams[i].role == chaincomp::ParamRole::kError) zero[i] = 0, error_index.push_back(i);
    cc::Model m0;
    cc::prepare(cc::params_from_array(zero.data()), m0);
    cc::Pose p;
    cc::Jacobian J;
    cc::Gain G;
    cc::pose_jacobian_gain(m0, check_q[0], p, J, G);
    const double h = 1e-6;
    for (int j = 0; j < NE; ++j) {
      std::vector<double> up = zero, down = zero;
      up[error_index[j]] = h, down[error_index[j]] = -h;
      cc::Model mu, md;
      cc::prepare(cc::params_from_array(up.data()), mu);
      cc::prepare(cc::params_from_array(down.data()), md);
      cc::Pose pu, pd;
      cc::pose_exact(mu, check_q[0], pu);
      cc::pose_exact(md, check_q[0], pd);
      const cc::Pose fd = (pu - pd) / (2 * h);
      const double scale = std::max(1.0, fd.cwiseAbs().maxCoeff());
      worst_gain_fd = std::max(worst_gain_fd, max_abs_diff(cc::Pose(G.col(j)), fd) / scale);
    }
  }
  if (worst_vs_numpy > kTolerance) die("chaincomp pose_exact differs from numpy by " + num(worst_vs_numpy));
  if (worst_gain_fd > 1e-6) die("chaincomp gain differs from central differences by " + num(worst_gain_fd));
  checks_json += "\"chaincomp_pose_vs_numpy\":" + num(worst_vs_numpy) + ",\"chaincomp_gain_vs_central_differences_rel\":" +
                 num(worst_gain_fd);
#endif
#ifdef SF_POSE3
  sides.push_back({"symforce_pose3", [](const Vq& q, Pose6& p, Jq& J, Je& G) { sf_pose3(q, g_c, g_e, &p, &J, &G); }});
#endif
#ifdef SF_MATRIX
  sides.push_back({"symforce_matrix", [](const Vq& q, Pose6& p, Jq& J, Je& G) { sf_matrix(q, g_c, g_e, &p, &J, &G); }});
#endif
  if (sides.empty()) die("nothing to time");

  // every side against the first (chaincomp when it is there), and against numpy's pose
  for (std::size_t k = 0; k < sides.size(); ++k) {
    double worst = 0, worst_np = 0;  // k = 0: its own pose_jacobian_gain against numpy only
    for (int s = 0; s < checks; ++s) {
      Pose6 p0, p;
      Jq J0, J;
      Je G0, G;
      sides[0].call(check_q[s], p0, J0, G0);
      sides[k].call(check_q[s], p, J, G);
      worst = std::max({worst, max_abs_diff(p, p0), max_abs_diff(J, J0), max_abs_diff(G, G0)});
      worst_np = std::max(worst_np, max_abs_diff(p, check_pose[s]));
    }
    const double tolerance = k == 0 ? kTolerance : kSfTolerance;
    if (worst > tolerance || worst_np > tolerance)
      die(sides[k].name + " differs from " + sides[0].name + " by " + num(worst) + ", from numpy by " + num(worst_np));
    if (!checks_json.empty()) checks_json += ",";
    if (k > 0) checks_json += "\"" + sides[k].name + "_vs_" + sides[0].name + "\":" + num(worst) + ",";
    checks_json += "\"" + sides[k].name + "_pose_vs_numpy\":" + num(worst_np);
  }

  static Pose6 p;
  static Jq J;
  static Je G;
  std::vector<std::function<void(int)>> fs;
  for (auto& side : sides)
    fs.push_back([&side, &qs](int i) {
      side.call(qs[i], p, J, G);
      escape(&p), escape(&J), escape(&G);
    });
  const auto stats = time_interleaved(samples, batches, batch_ms, fs);
  std::string out = "{\"checks\":{" + checks_json + "},\"tolerance\":" + num(kTolerance) + ",\"samples\":" +
                    std::to_string(samples) + ",\"batches\":" + std::to_string(batches) + ",\"ns\":{";
  for (std::size_t k = 0; k < sides.size(); ++k) {
    out += (k ? ",\"" : "\"") + sides[k].name + "\":{\"median_ns\":" + num(stats[k].median_ns) + ",\"best_ns\":" +
           num(stats[k].best_ns) + ",\"worst_ns\":" + num(stats[k].worst_ns) + ",\"calls_per_batch\":" +
           std::to_string(stats[k].calls_per_batch) + "}";
  }
  std::printf("%s}}\n", out.c_str());
  return 0;
}
