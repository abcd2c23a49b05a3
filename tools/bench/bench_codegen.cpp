// bench_codegen: ns per call of the generated models (chaincomp_models, called through the
// type-erased registry exactly as chaincompd calls them) against a run-time baseline that
// multiplies one Eigen::Matrix4d per elementary transform of the chain.
//
// The baseline knows no machine: tools/bench_codegen exports, for the chosen params, each
// elementary transform's angle or translation as an affine function of the axes
// (constant + one coefficient per axis) for the actual chain (every error) and the nominal
// chain (errors at zero), plus the tool point, direction and (a tool frame) the reference x
// axis, written "reference yes x y z" after the direction (optional). This program reads that file,
// checks the baseline pose against the generated pose_exact (and the Python/numpy exact
// model's poses) to 1e-9 before timing anything, and prints one JSON object on stdout.
// The baseline is an interpreter: the number of axes is a run-time value (Eigen matrices
// of fixed maximum size, so no heap); only the pose size is a template parameter.
//
// Tables case (--tables-machine NAME --tables P.yaml [--tables-linear P2.yaml]): compensate,
// pose_exact and pose_jacobian with every error of P.yaml that varies along an axis attached
// (the bundled laser calibration: 18 tables of 101 points) against the same model with each
// of those errors a constant (its value at the middle of its table), after checking that
// every correction with tables puts the actual tool point (tables evaluated at the corrected
// axes) on the nominal one.
//
// Usage: bench_codegen CHAINS.txt [--samples N] [--batches N] [--batch-ms MS] [--seed N]
//                     [--tables-machine NAME --tables P.yaml [--tables-linear P2.yaml]]
#include <Eigen/Cholesky>
#include <Eigen/Core>

#include <algorithm>
#include <array>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <fstream>
#include <random>
#include <sstream>
#include <string>
#include <vector>

#include "chaincomp/compensate.hpp"
#include "chaincomp/model_info.hpp"
#include "chaincomp/params_io.hpp"
#include "chaincomp/varying.hpp"

// five_axis_ac's compensate on the solver before issue #40 (compensate_before_40.cpp)
int before40_compensate_five_axis_ac(const void* model, const double* command, double* corrected, double* residual,
                                     bool warm) noexcept;

namespace {

constexpr int kMaxAxes = 8;
constexpr int kBaselineSteps = 2;  // full Newton steps: what compensate needs at µm and arcsec
constexpr double kCheckTolerance = 1e-9;
#if defined(__clang__)
const std::string kCompiler = std::string("clang ") + __clang_version__;
#elif defined(__GNUC__)
const std::string kCompiler = std::string("gcc ") + __VERSION__;
#else
const std::string kCompiler = "unknown";
#endif

// `samples` axis vectors, uniform within the axes' limits (internal units), one after another.
std::vector<double> random_axes(const chaincomp::MachineInfo& info, int samples, unsigned seed) {
  std::mt19937_64 rng(seed);
  std::vector<double> axes(static_cast<std::size_t>(samples) * info.num_axes);
  for (int s = 0; s < samples; ++s) {
    for (int i = 0; i < info.num_axes; ++i) {
      const auto& a = info.axes[i];
      std::uniform_real_distribution<double> u(a.lower * a.to_internal, a.upper * a.to_internal);
      axes[static_cast<std::size_t>(s) * info.num_axes + i] = u(rng);
    }
  }
  return axes;
}

[[noreturn]] void die(const std::string& msg) {
  std::fprintf(stderr, "bench_codegen: %s\n", msg.c_str());
  std::exit(2);
}

// ----------------------------------------------------------------------------- the exported chain

struct Affine {  // c + k . q
  double c = 0;
  double k[kMaxAxes] = {};
  double eval(const double* q, int n) const noexcept {
    double v = c;
    for (int i = 0; i < n; ++i) v += k[i] * q[i];
    return v;
  }
};

struct Elem {
  enum Kind { kRx, kRy, kRz, kT } kind;
  Affine a[3];  // rotation: a[0] is the angle (rad, right-handed); translation: x, y, z (mm)
};

struct Chain {
  int n = 0;                // number of axes
  std::vector<Elem> elems;  // leftmost first
  Affine point[3];
  bool has_direction = false;
  double direction[3] = {0, 0, 0};
  bool has_reference = false;  // a tool frame: its x axis, pose rows 6..8
  double reference[3] = {0, 0, 0};
};

struct MachineSpec {
  std::string name;
  std::vector<std::string> axis_names;
  std::vector<std::pair<std::string, double>> params;  // internal units, by name
  Chain actual, nominal;
  std::vector<std::vector<double>> check_axes, check_pose;  // poses of the numpy exact model
};

class Reader {
 public:
  explicit Reader(const std::string& path) : in_(path), path_(path) {
    if (!in_) die("cannot open " + path);
  }
  std::string word() {
    std::string w;
    if (!(in_ >> w)) die(path_ + ": unexpected end of file");
    return w;
  }
  // Reads the next word if it is `want`; otherwise leaves it for the next read.
  bool accept(const std::string& want) {
    const auto at = in_.tellg();
    std::string w;
    if (in_ >> w && w == want) return true;
    in_.clear();
    in_.seekg(at);
    return false;
  }
  void expect(const std::string& want) {
    const std::string w = word();
    if (w != want) die(path_ + ": expected '" + want + "', got '" + w + "'");
  }
  double number() {
    const std::string w = word();
    char* end = nullptr;
    const double v = std::strtod(w.c_str(), &end);
    if (end == w.c_str() || *end != '\0' || !std::isfinite(v)) die(path_ + ": expected a number, got '" + w + "'");
    return v;
  }
  int integer() { return static_cast<int>(number()); }
  bool at_end() {
    in_ >> std::ws;
    return in_.peek() == std::char_traits<char>::eof();
  }

 private:
  std::ifstream in_;
  std::string path_;
};

Affine read_affine(Reader& r, int n) {
  Affine a;
  a.c = r.number();
  for (int i = 0; i < n; ++i) a.k[i] = r.number();
  return a;
}

Chain read_chain(Reader& r, const char* which, int n) {
  r.expect("chain");
  r.expect(which);
  Chain ch;
  ch.n = n;
  const int count = r.integer();
  for (int i = 0; i < count; ++i) {
    const std::string kind = r.word();
    Elem e{};
    if (kind == "R") {
      const std::string axis = r.word();
      e.kind = axis == "x" ? Elem::kRx : axis == "y" ? Elem::kRy : axis == "z" ? Elem::kRz : Elem::kT;
      if (e.kind == Elem::kT) die("rotation axis must be x, y or z, got " + axis);
      e.a[0] = read_affine(r, n);
    } else if (kind == "T") {
      e.kind = Elem::kT;
      for (auto& a : e.a) a = read_affine(r, n);
    } else {
      die("chain element must be R or T, got " + kind);
    }
    ch.elems.push_back(e);
  }
  r.expect("point");
  for (auto& a : ch.point) a = read_affine(r, n);
  r.expect("direction");
  const std::string d = r.word();
  if (d == "yes") {
    ch.has_direction = true;
    for (double& v : ch.direction) v = r.number();
  } else if (d != "no") {
    die("direction must be 'yes x y z' or 'no', got " + d);
  }
  if (r.accept("reference")) {
    const std::string x = r.word();
    if (x == "yes") {
      if (!ch.has_direction) die("a tool reference needs a tool direction");
      ch.has_reference = true;
      for (double& v : ch.reference) v = r.number();
    } else if (x != "no") {
      die("reference must be 'yes x y z' or 'no', got " + x);
    }
  }
  return ch;
}

std::vector<MachineSpec> read_specs(const std::string& path) {
  Reader r(path);
  r.expect("chaincomp-bench-chains");
  r.expect("v1");
  std::vector<MachineSpec> out;
  while (!r.at_end()) {
    MachineSpec m;
    r.expect("machine");
    m.name = r.word();
    r.expect("axes");
    const int n = r.integer();
    if (n < 1 || n > kMaxAxes) die(m.name + ": unsupported number of axes (at most " + std::to_string(kMaxAxes) + ")");
    for (int i = 0; i < n; ++i) m.axis_names.push_back(r.word());
    r.expect("params");
    const int np = r.integer();
    for (int i = 0; i < np; ++i) {
      std::string name = r.word();
      m.params.emplace_back(name, r.number());
    }
    m.actual = read_chain(r, "actual", n);
    m.nominal = read_chain(r, "nominal", n);
    r.expect("checks");
    const int nc = r.integer();
    const int ps = r.integer();
    for (int c = 0; c < nc; ++c) {
      std::vector<double> q(n), p(ps);
      for (double& v : q) v = r.number();
      for (double& v : p) v = r.number();
      m.check_axes.push_back(q);
      m.check_pose.push_back(p);
    }
    r.expect("end");
    out.push_back(std::move(m));
  }
  return out;
}

// ----------------------------------------------------------------------------- the baseline

inline Eigen::Matrix4d elem_matrix(const Elem& e, const double* q, int n) noexcept {
  Eigen::Matrix4d m = Eigen::Matrix4d::Identity();
  if (e.kind == Elem::kT) {
    m(0, 3) = e.a[0].eval(q, n);
    m(1, 3) = e.a[1].eval(q, n);
    m(2, 3) = e.a[2].eval(q, n);
    return m;
  }
  const double angle = e.a[0].eval(q, n);
  const double c = std::cos(angle), s = std::sin(angle);
  switch (e.kind) {
    case Elem::kRx: m(1, 1) = c; m(1, 2) = -s; m(2, 1) = s; m(2, 2) = c; break;
    case Elem::kRy: m(0, 0) = c; m(0, 2) = s; m(2, 0) = -s; m(2, 2) = c; break;
    default: m(0, 0) = c; m(0, 1) = -s; m(1, 0) = s; m(1, 1) = c; break;
  }
  return m;
}

// Tool point (and direction, and a frame's x axis) relative to the workpiece: E1 * E2 * ... * En
// applied to the tool.
template <int PS>
inline void baseline_pose(const Chain& ch, const double* q, double* pose) noexcept {
  const int n = ch.n;
  Eigen::Matrix4d m = Eigen::Matrix4d::Identity();
  for (const Elem& e : ch.elems) m = m * elem_matrix(e, q, n);
  const Eigen::Vector4d p(ch.point[0].eval(q, n), ch.point[1].eval(q, n), ch.point[2].eval(q, n), 1.0);
  const Eigen::Vector4d r = m * p;
  pose[0] = r[0];
  pose[1] = r[1];
  pose[2] = r[2];
  if constexpr (PS >= 6) {
    const Eigen::Vector3d d = m.topLeftCorner<3, 3>() * Eigen::Map<const Eigen::Vector3d>(ch.direction);
    pose[3] = d[0];
    pose[4] = d[1];
    pose[5] = d[2];
  }
  if constexpr (PS == 9) {
    const Eigen::Vector3d x = m.topLeftCorner<3, 3>() * Eigen::Map<const Eigen::Vector3d>(ch.reference);
    pose[6] = x[0];
    pose[7] = x[1];
    pose[8] = x[2];
  }
}

// The exact tool error: actual chain minus nominal chain.
template <int PS>
inline void baseline_error(const Chain& actual, const Chain& nominal, const double* q, double* err) noexcept {
  double a[PS], b[PS];
  baseline_pose<PS>(actual, q, a);
  baseline_pose<PS>(nominal, q, b);
  for (int i = 0; i < PS; ++i) err[i] = a[i] - b[i];
}

// Pose and forward-difference Jacobian (PS x N, column-major) of the numeric product:
// N + 1 products; step 1e-7 * max(1, |q_j|), divided by the step actually taken.
template <int PS>
inline void baseline_jacobian(const Chain& ch, const double* q, double* pose, double* jac) noexcept {
  const int N = ch.n;
  baseline_pose<PS>(ch, q, pose);
  double qh[kMaxAxes], shifted[PS];
  for (int j = 0; j < N; ++j) qh[j] = q[j];
  for (int j = 0; j < N; ++j) {
    qh[j] = q[j] + 1e-7 * std::max(1.0, std::abs(q[j]));
    const double h = qh[j] - q[j];
    baseline_pose<PS>(ch, qh, shifted);
    for (int i = 0; i < PS; ++i) jac[i + PS * j] = (shifted[i] - pose[i]) / h;
    qh[j] = q[j];
  }
}

// compensate.hpp's Gauss-Newton (same steps, weights, Levenberg term, LDLT, status codes) on
// the numeric product, with the forward-difference Jacobian. Unlike compensate.hpp it skips
// the Jacobian on the last pass, where only the residual is needed (in the baseline's favour).
// ORI (a tool frame, three or more rotary axes): rows 3..5 are compensate.hpp's orientation
// residual against the target frame instead of the change of the direction.
template <int PS, bool DIR, bool ORI = false>
int baseline_compensate(const Chain& actual, const Chain& nominal, const double* command, double* corrected,
                        double* residual) noexcept {
  using chaincomp::Status;
  constexpr int rows = DIR ? 6 : 3;
  const int N = actual.n;
  // run-time number of axes, fixed maximum size: no heap
  using Vec = Eigen::Matrix<double, Eigen::Dynamic, 1, 0, kMaxAxes, 1>;
  using Square = Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic, 0, kMaxAxes, kMaxAxes>;
  const Eigen::Map<const Vec> cmd(command, N);
  Eigen::Map<Vec> out(corrected, N);
  out = cmd;
  residual[0] = residual[1] = 0;
  if (!cmd.allFinite()) return static_cast<int>(Status::kNonFiniteInput);
  double target[PS], pose[PS], jac[PS * kMaxAxes];
  baseline_pose<PS>(nominal, command, target);
  Eigen::Vector3d target_z = Eigen::Vector3d::Zero(), target_y = Eigen::Vector3d::Zero();
  if constexpr (ORI) {
    target_z = Eigen::Map<const Eigen::Vector3d>(target + 3);
    target_y = chaincomp::cross3(target_z, Eigen::Map<const Eigen::Vector3d>(target + 6));
  }
  Vec q = cmd;
  Eigen::Matrix<double, rows, 1> r;
  Eigen::Matrix<double, rows, Eigen::Dynamic, 0, rows, kMaxAxes> J(rows, N);
  const Eigen::Map<const Eigen::Matrix<double, PS, Eigen::Dynamic, 0, PS, kMaxAxes>> jm(jac, PS, N);
  for (int step = 0; step <= kBaselineSteps; ++step) {
    if (step == kBaselineSteps) {
      baseline_pose<PS>(actual, q.data(), pose);
    } else {
      baseline_jacobian<PS>(actual, q.data(), pose, jac);
      J.template topRows<3>() = jm.template topRows<3>();
      if constexpr (ORI) {
        for (int j = 0; j < N; ++j)
          J.col(j).template tail<3>() = chaincomp::kDefaultDirectionWeight *
              chaincomp::orientation_residual(target_z, target_y, jm.col(j).template segment<3>(3),
                                              jm.col(j).template segment<3>(6));
      } else if constexpr (DIR) {
        J.template bottomRows<3>() = chaincomp::kDefaultDirectionWeight * jm.template middleRows<3>(3);
      }
    }
    for (int i = 0; i < 3; ++i) r[i] = pose[i] - target[i];
    if constexpr (ORI) {
      r.template tail<3>() = chaincomp::kDefaultDirectionWeight *
          chaincomp::orientation_residual(target_z, target_y, Eigen::Map<const Eigen::Vector3d>(pose + 3),
                                          Eigen::Map<const Eigen::Vector3d>(pose + 6));
    } else if constexpr (DIR) {
      for (int i = 3; i < 6; ++i) r[i] = chaincomp::kDefaultDirectionWeight * (pose[i] - target[i]);
    }
    if (step == kBaselineSteps) break;
    Square A = J.transpose() * J;
    A.diagonal().array() += 1e-14 * (1.0 + A.diagonal().maxCoeff());
    Eigen::LDLT<Square> ldlt(A);
    if (ldlt.info() != Eigen::Success || !ldlt.isPositive()) return static_cast<int>(Status::kSingular);
    q -= ldlt.solve(J.transpose() * r);
  }
  if (!q.allFinite() || !r.allFinite()) return static_cast<int>(Status::kNonFiniteOutput);
  out = q;
  residual[0] = r.template head<3>().norm();
  if constexpr (DIR) residual[1] = r.template tail<3>().norm() / chaincomp::kDefaultDirectionWeight;
  const bool ok = residual[0] <= chaincomp::kPointTolerance && residual[1] <= chaincomp::kDirectionTolerance;
  return static_cast<int>(ok ? Status::kOk : Status::kResidual);
}

// ----------------------------------------------------------------------------- timing

double g_sink_store = 0;
volatile double g_sink = 0;

// Tells the compiler the pointed-to memory is read and written: the work producing it stays.
inline void escape(const void* p) noexcept { asm volatile("" : : "g"(p) : "memory"); }

struct Stats {
  double median_ns = 0, worst_ns = 0, best_ns = 0;
  long calls_per_batch = 0;
  int batches = 0;
};

using Clock = std::chrono::steady_clock;

// f(i) runs one call on sample i and returns a value for the sink. Calls in batches over
// the samples (round robin); per batch the mean ns per call; median, worst and best batch.
// Several functions are timed together, their batches interleaved (the order rotating from
// batch to batch): a drift of the machine's speed during the run (other load, CPU
// frequency) then moves every figure alike, and their ratios stay fair.
template <class... F>
std::array<Stats, sizeof...(F)> time_interleaved(int num_samples, int batches, double batch_ms, F&&... fs) {
  constexpr std::size_t N = sizeof...(F);
  std::array<Stats, N> out;
  std::array<std::vector<double>, N> ns;
  std::array<int, N> idx{};
  double sink = 0;
  auto run = [&](auto& f, int& i, long calls) {
    for (long k = 0; k < calls; ++k) {
      sink += f(i);
      if (++i == num_samples) i = 0;
    }
  };
  // warm-up and calibration: at least one pass over the samples and 20 ms each
  auto calibrate = [&](auto& f, std::size_t j) {
    long calls = 0;
    const auto w0 = Clock::now();
    double elapsed = 0;
    while (calls < num_samples || elapsed < 20e6) {
      run(f, idx[j], 64);
      calls += 64;
      elapsed = std::chrono::duration<double, std::nano>(Clock::now() - w0).count();
    }
    out[j].calls_per_batch = std::max<long>(16, static_cast<long>(batch_ms * 1e6 * calls / elapsed));
    out[j].batches = batches;
  };
  {
    std::size_t j = 0;
    ((calibrate(fs, j), ++j), ...);
  }
  for (int b = 0; b < batches; ++b) {
    for (std::size_t r = 0; r < N; ++r) {
      const std::size_t which = (static_cast<std::size_t>(b) + r) % N;
      std::size_t j = 0;
      auto batch = [&](auto& f) {
        if (j++ != which) return;
        const auto t0 = Clock::now();
        run(f, idx[which], out[which].calls_per_batch);
        ns[which].push_back(std::chrono::duration<double, std::nano>(Clock::now() - t0).count() /
                            static_cast<double>(out[which].calls_per_batch));
      };
      (batch(fs), ...);
    }
  }
  for (std::size_t j = 0; j < N; ++j) {
    std::sort(ns[j].begin(), ns[j].end());
    out[j].median_ns = ns[j][ns[j].size() / 2];
    out[j].worst_ns = ns[j].back();
    out[j].best_ns = ns[j].front();
  }
  g_sink_store += sink;
  return out;
}

// ----------------------------------------------------------------------------- JSON

std::string num(double v) {
  if (!std::isfinite(v)) return "null";
  char buf[64];
  std::snprintf(buf, sizeof buf, "%.6g", v);
  return buf;
}

std::string stats_json(const Stats& s) {
  return "{\"median_ns\":" + num(s.median_ns) + ",\"worst_ns\":" + num(s.worst_ns) + ",\"best_ns\":" +
         num(s.best_ns) + ",\"calls_per_batch\":" + std::to_string(s.calls_per_batch) +
         ",\"batches\":" + std::to_string(s.batches) + "}";
}

struct ModelBuffer {
  alignas(64) unsigned char bytes[1 << 14];
};

struct Options {
  int samples = 4096, batches = 101;
  double batch_ms = 1.0;
  unsigned seed = 20240611;
  std::string tables_machine, tables, tables_linear;
};

// ----------------------------------------------------------------------------- tables

struct TablesCase {
  std::vector<double> params;
  chaincomp::VaryingErrors varying;
  ModelBuffer model;
};

void load_case(const chaincomp::ModelEntry& e, const std::string& path, TablesCase& c) {
  std::string error;
  if (!chaincomp::load_params(*e.info, path, c.params, c.varying, error)) die(error);
  e.prepare(c.params.data(), c.model.bytes);
  e.attach_varying(c.model.bytes, &c.varying);
}

std::string bench_tables(const Options& opt) {
  const chaincomp::ModelEntry* e = chaincomp::find_model(opt.tables_machine.c_str());
  if (e == nullptr) die("machine " + opt.tables_machine + " is not compiled into chaincomp_models");
  const auto& info = *e->info;
  const int N = info.num_axes, PS = info.pose_size;
  auto tables = std::make_unique<TablesCase>();
  load_case(*e, opt.tables, *tables);
  if (tables->varying.count == 0) die(opt.tables + ": no error varies along an axis");
  std::unique_ptr<TablesCase> linear;
  if (!opt.tables_linear.empty()) {
    linear = std::make_unique<TablesCase>();
    load_case(*e, opt.tables_linear, *linear);
  }
  // constants: each varying error at the middle of its range
  auto constants = std::make_unique<TablesCase>();
  constants->params = tables->params;
  int knots_min = 1 << 30, knots_max = 0;
  for (int i = 0; i < tables->varying.count; ++i) {
    const auto& v = tables->varying.items[i];
    double value, slope;
    chaincomp::evaluate(tables->varying, v, 0.5 * (v.lower + v.upper), nullptr, value, slope);
    constants->params[v.param] = value;
    knots_min = std::min(knots_min, v.count);
    knots_max = std::max(knots_max, v.count);
  }
  e->prepare(constants->params.data(), constants->model.bytes);
  std::fprintf(stderr, "bench_codegen: %s tables: %s\n", info.name, chaincomp::describe_varying(tables->varying).c_str());

  const std::vector<double> axes = random_axes(info, opt.samples, opt.seed);
  auto q_at = [&](int s) { return axes.data() + static_cast<std::size_t>(s) * N; };

  // checks: with tables, the actual point at the corrected axes is the nominal one
  int ok[3] = {0, 0, 0};
  double worst[3] = {0, 0, 0};
  const void* models[3] = {constants->model.bytes, tables->model.bytes, linear ? linear->model.bytes : nullptr};
  for (int m = 0; m < 3; ++m) {
    if (models[m] == nullptr) continue;
    for (int s = 0; s < opt.samples; ++s) {
      double corr[kMaxAxes], res[2], target[6], actual[6];
      const int st = e->compensate(models[m], nullptr, q_at(s), chaincomp::kDefaultDirectionWeight, corr, res, nullptr);
      e->pose_nominal(models[m], q_at(s), target);
      e->pose_exact(models[m], corr, actual);
      double d = 0;
      for (int i = 0; i < 3; ++i) d += (actual[i] - target[i]) * (actual[i] - target[i]);
      if (st == 0) {
        ++ok[m];
        worst[m] = std::max(worst[m], std::sqrt(d));
      }
    }
  }
  if (!(worst[1] <= 1e-6) || !(worst[2] <= 1e-6))
    die(std::string(info.name) + ": with tables a corrected point is off the nominal one by " +
        num(std::max(worst[1], worst[2])) + " mm (> 1 nm): not timing");

  double out[6], jac[6 * kMaxAxes], corr[kMaxAxes], res[2];
  const int S = opt.samples, B = opt.batches;
  const double ms = opt.batch_ms;
  auto comp = [&](const void* model) {
    return [&, model](int s) { const int st = e->compensate(model, nullptr, q_at(s), chaincomp::kDefaultDirectionWeight, corr, res, nullptr); escape(corr); return corr[0] + st; };
  };
  auto pose = [&](const void* model) {
    return [&, model](int s) { e->pose_exact(model, q_at(s), out); escape(out); return out[0]; };
  };
  auto jacobian = [&](const void* model) {
    return [&, model](int s) { e->pose_jacobian(model, q_at(s), out, jac); escape(jac); return out[0] + jac[0]; };
  };
  const void* lin_model = linear ? linear->model.bytes : constants->model.bytes;  // timed either way
  const auto c = time_interleaved(S, B, ms, comp(constants->model.bytes), comp(tables->model.bytes), comp(lin_model));
  const Stats c_const = c[0], c_tab = c[1], c_lin = linear ? c[2] : Stats{};
  const auto p = time_interleaved(S, B, ms, pose(constants->model.bytes), pose(tables->model.bytes));
  const auto jt = time_interleaved(S, B, ms, jacobian(constants->model.bytes), jacobian(tables->model.bytes));
  const Stats p_const = p[0], p_tab = p[1], j_const = jt[0], j_tab = jt[1];
  (void)PS;
  std::string j = "{\"machine\":\"" + std::string(info.name) + "\",\"varying\":" +
                  std::to_string(tables->varying.count) + ",\"knots_min\":" + std::to_string(knots_min) +
                  ",\"knots_max\":" + std::to_string(knots_max) + ",\"description\":\"" +
                  chaincomp::describe_varying(tables->varying) + "\",\"samples\":" + std::to_string(S) +
                  ",\"checks\":{\"ok_constants\":" + std::to_string(ok[0]) + ",\"ok_tables\":" +
                  std::to_string(ok[1]) + ",\"ok_tables_linear\":" + (linear ? std::to_string(ok[2]) : "null") +
                  ",\"max_point_residual_ok_tables\":" + num(worst[1]) +
                  ",\"max_point_residual_ok_tables_linear\":" + (linear ? num(worst[2]) : "null") +
                  ",\"max_point_residual_ok_constants\":" + num(worst[0]) + "},\"timings\":{" +
                  "\"compensate\":{\"constants\":" + stats_json(c_const) + ",\"tables\":" + stats_json(c_tab) +
                  (linear ? ",\"tables_linear\":" + stats_json(c_lin) : std::string()) + "}," +
                  "\"pose_exact\":{\"constants\":" + stats_json(p_const) + ",\"tables\":" + stats_json(p_tab) + "}," +
                  "\"pose_jacobian\":{\"constants\":" + stats_json(j_const) + ",\"tables\":" + stats_json(j_tab) +
                  "}}}";
  return j;
}

// ----------------------------------------------------------------------------- one machine

template <int PS, bool DIR, bool ORI = false>
std::string bench_machine(const MachineSpec& spec, const chaincomp::ModelEntry& e, const void* model,
                          const Options& opt) {
  const auto& info = *e.info;
  const int N = info.num_axes;
  std::fprintf(stderr, "bench_codegen: %s (%d axes, pose %d, chain of %zu transforms)\n", info.name, N, PS,
               spec.actual.elems.size());
  const std::vector<double> axes = random_axes(info, opt.samples, opt.seed);
  auto q_at = [&](int s) { return axes.data() + static_cast<std::size_t>(s) * N; };
  // A stream, as chaincompd and replay see one: a closed 5-axis-like path sampled at the
  // same count (a circle of 50 mm in the first two linear axes, the others swinging by a
  // tenth of their range around 15% of it off the middle, which keeps a tilted tool away
  // from the singular pose; one period over the samples: about 0.08 mm and 0.09 deg per step).
  std::vector<double> path(static_cast<std::size_t>(opt.samples) * N);
  for (int s = 0; s < opt.samples; ++s) {
    const double t = 2 * M_PI * s / opt.samples;
    int linear = 0;
    for (int i = 0; i < N; ++i) {
      const auto& a = info.axes[i];
      const double mid = 0.5 * (a.lower + a.upper), range = a.upper - a.lower;
      const bool angle = a.kind == chaincomp::UnitKind::kAngle;
      double v = mid + range * (0.15 + 0.05 * std::sin(t + i));
      if (!angle && linear < 2) v = mid + 50.0 * (linear++ == 0 ? std::cos(t) : std::sin(t));
      path[static_cast<std::size_t>(s) * N + i] = v * a.to_internal;
    }
  }
  auto p_at = [&](int s) { return path.data() + static_cast<std::size_t>(s) * N; };
  std::vector<unsigned char> ws_storage;
  void* ws = chaincomp::aligned_slot(ws_storage, e.workspace_size, e.workspace_align);
  e.init_workspace(ws);

  // ---- checks before timing
  double pose_diff = 0, numpy_diff = 0, numpy_base_diff = 0, err1_diff = 0, err2_diff = 0, err_size = 0;
  double gen_pose[PS], base_pose[PS], gen_err[PS], exact_err[PS];
  for (int s = 0; s < opt.samples; ++s) {
    e.pose_exact(model, q_at(s), gen_pose);
    baseline_pose<PS>(spec.actual, q_at(s), base_pose);
    baseline_error<PS>(spec.actual, spec.nominal, q_at(s), exact_err);
    for (int i = 0; i < PS; ++i) pose_diff = std::max(pose_diff, std::abs(gen_pose[i] - base_pose[i]));
    for (int order = 1; order <= 2; ++order) {
      if (!e.error(model, q_at(s), order, gen_err)) die(std::string(info.name) + ": no order-" + std::to_string(order) + " error");
      for (int i = 0; i < PS; ++i) {
        double& d = order == 1 ? err1_diff : err2_diff;
        d = std::max(d, std::abs(gen_err[i] - exact_err[i]));
      }
    }
    for (int i = 0; i < 3; ++i) err_size = std::max(err_size, std::abs(exact_err[i]));
  }
  for (std::size_t c = 0; c < spec.check_axes.size(); ++c) {
    e.pose_exact(model, spec.check_axes[c].data(), gen_pose);
    baseline_pose<PS>(spec.actual, spec.check_axes[c].data(), base_pose);
    for (int i = 0; i < PS; ++i) {
      numpy_diff = std::max(numpy_diff, std::abs(gen_pose[i] - spec.check_pose[c][i]));
      numpy_base_diff = std::max(numpy_base_diff, std::abs(base_pose[i] - spec.check_pose[c][i]));
    }
  }
  if (!(pose_diff <= kCheckTolerance))
    die(std::string(info.name) + ": baseline pose differs from the generated pose_exact by " + num(pose_diff) +
        " (> 1e-9) over " + std::to_string(opt.samples) + " random axes: not timing an unequal pair");
  if (!(numpy_diff <= kCheckTolerance) || !(numpy_base_diff <= kCheckTolerance))
    die(std::string(info.name) + ": the numpy exact model's poses differ from the generated (" + num(numpy_diff) +
        ") or baseline (" + num(numpy_base_diff) + ") pose by more than 1e-9");

  // Jacobian: forward differences against the generated exact one (relative to its size)
  double jac_diff = 0;
  {
    double gj[PS * kMaxAxes], bj[PS * kMaxAxes], gp[PS], bp[PS];
    for (int s = 0; s < opt.samples; ++s) {
      e.pose_jacobian(model, q_at(s), gp, gj);
      baseline_jacobian<PS>(spec.actual, q_at(s), bp, bj);
      for (int i = 0; i < PS * N; ++i) jac_diff = std::max(jac_diff, std::abs(gj[i] - bj[i]) / (1.0 + std::abs(gj[i])));
    }
  }
  // compensation: the two implementations must agree (same statuses, same corrections)
  double comp_axis_diff = 0, comp_axis_diff_ok = 0, comp_res_gen = 0, comp_res_base = 0;
  int status_mismatch = 0, gen_ok = 0, base_ok = 0;
  {
    double cg[kMaxAxes], cb[kMaxAxes], rg[2], rb[2];
    for (int s = 0; s < opt.samples; ++s) {
      const int sg = e.compensate(model, nullptr, q_at(s), chaincomp::kDefaultDirectionWeight, cg, rg, nullptr);
      const int sb = baseline_compensate<PS, DIR, ORI>(spec.actual, spec.nominal, q_at(s), cb, rb);
      status_mismatch += sg != sb;
      gen_ok += sg == 0;
      base_ok += sb == 0;
      for (int i = 0; i < N; ++i) {
        comp_axis_diff = std::max(comp_axis_diff, std::abs(cg[i] - cb[i]));
        if (sg == 0 && sb == 0) comp_axis_diff_ok = std::max(comp_axis_diff_ok, std::abs(cg[i] - cb[i]));
      }
      comp_res_gen = std::max(comp_res_gen, rg[0]);
      comp_res_base = std::max(comp_res_base, rb[0]);
    }
  }

  // ---- timing
  double out[PS], jac[PS * kMaxAxes];
  double corr[kMaxAxes], res[2];
  auto sum = [](const double* v, int n) {
    double t = 0;
    for (int i = 0; i < n; ++i) t += v[i];
    return t;
  };
  struct Row {
    const char* fn;
    Stats gen, base;
  };
  std::vector<Row> rows;
  const int S = opt.samples, B = opt.batches;
  const double ms = opt.batch_ms;
  auto timed_row = [&](const char* fn, auto&& generated, auto&& baseline) {
    const auto t = time_interleaved(S, B, ms, generated, baseline);
    return Row{fn, t[0], t[1]};
  };
  rows.push_back(timed_row("pose_exact",
                           [&](int s) { e.pose_exact(model, q_at(s), out); escape(out); return out[0]; },
                           [&](int s) { baseline_pose<PS>(spec.actual, q_at(s), out); escape(out); return sum(out, PS); }));
  rows.push_back(timed_row("error_order1",
                           [&](int s) { e.error(model, q_at(s), 1, out); escape(out); return out[0]; },
                           [&](int s) { baseline_error<PS>(spec.actual, spec.nominal, q_at(s), out); escape(out); return sum(out, PS); }));
  // the same exact-error baseline, timed again for its own figures
  rows.push_back(timed_row("error_order2",
                           [&](int s) { e.error(model, q_at(s), 2, out); escape(out); return out[0]; },
                           [&](int s) { baseline_error<PS>(spec.actual, spec.nominal, q_at(s), out); escape(out); return sum(out, PS); }));
  rows.push_back(timed_row("pose_jacobian",
                           [&](int s) { e.pose_jacobian(model, q_at(s), out, jac); escape(jac); return out[0] + jac[0]; },
                           [&](int s) { baseline_jacobian<PS>(spec.actual, q_at(s), out, jac); escape(jac); return out[0] + jac[0]; }));
  rows.push_back(timed_row("compensate",
                           [&](int s) { const int st = e.compensate(model, nullptr, q_at(s), chaincomp::kDefaultDirectionWeight, corr, res, nullptr); escape(corr); return corr[0] + st; },
                           [&](int s) { const int st = baseline_compensate<PS, DIR, ORI>(spec.actual, spec.nominal, q_at(s), corr, res); escape(corr); return corr[0] + st; }));

  // Issue #40's timing check: today's compensate (as the row above: cold, through the registry)
  // beside the solver before its never-worse rule ("baseline"), alternated in the same run, after
  // checking that both land on the same corrections.
  double before40_diff = -1;
  if (std::strcmp(info.name, "five_axis_ac") == 0) {
    before40_diff = 0;
    for (int s = 0; s < opt.samples; ++s) {
      double cn[kMaxAxes], co[kMaxAxes], rn[2], ro[2];
      const int sn = e.compensate(model, nullptr, q_at(s), chaincomp::kDefaultDirectionWeight, cn, rn, nullptr);
      const int so = before40_compensate_five_axis_ac(model, q_at(s), co, ro, false);
      for (int i = 0; i < N; ++i) before40_diff = std::max(before40_diff, sn == so ? std::abs(cn[i] - co[i]) : HUGE_VAL);
    }
    rows.push_back(timed_row("compensate_before_40",
                             [&](int s) { const int st = e.compensate(model, nullptr, q_at(s), chaincomp::kDefaultDirectionWeight, corr, res, nullptr); escape(corr); return corr[0] + st; },
                             [&](int s) { const int st = before40_compensate_five_axis_ac(model, q_at(s), corr, res, false); escape(corr); return corr[0] + st; }));
  }
  // and along the stream with a kept workspace each (warm starts), as chaincompd calls it
  std::vector<unsigned char> ws40_storage;
  void* ws40 = chaincomp::aligned_slot(ws40_storage, e.workspace_size, e.workspace_align);
  e.init_workspace(ws40);
  if (before40_diff >= 0) {
    rows.push_back(timed_row("compensate_stream_before_40",
                             [&](int s) { const int st = e.compensate(model, ws40, p_at(s), chaincomp::kDefaultDirectionWeight, corr, res, nullptr); escape(corr); return corr[0] + st; },
                             [&](int s) { const int st = before40_compensate_five_axis_ac(model, p_at(s), corr, res, true); escape(corr); return corr[0] + st; }));
  }

  // the stream with a kept workspace (warm starts) lands where a cold start lands
  double stream_diff = 0;
  int stream_mismatch = 0;
  for (int pass = 0; pass < 2; ++pass) {
    for (int s = 0; s < opt.samples; ++s) {
      double cw[kMaxAxes], cc[kMaxAxes], rw[2], rc[2];
      const int sw = e.compensate(model, ws, p_at(s), chaincomp::kDefaultDirectionWeight, cw, rw, nullptr);
      const int sc = e.compensate(model, nullptr, p_at(s), chaincomp::kDefaultDirectionWeight, cc, rc, nullptr);
      stream_mismatch += sw != sc;
      for (int i = 0; i < N; ++i) stream_diff = std::max(stream_diff, std::abs(cw[i] - cc[i]));
    }
  }
  rows.push_back(timed_row("compensate_stream",
                           [&](int s) { const int st = e.compensate(model, ws, p_at(s), chaincomp::kDefaultDirectionWeight, corr, res, nullptr); escape(corr); return corr[0] + st; },
                           [&](int s) { const int st = baseline_compensate<PS, DIR, ORI>(spec.actual, spec.nominal, p_at(s), corr, res); escape(corr); return corr[0] + st; }));

  std::string j = "{\"machine\":\"" + std::string(info.name) + "\",\"num_axes\":" + std::to_string(N) +
                  ",\"pose_size\":" + std::to_string(PS) + ",\"corrects_direction\":" + (DIR ? "true" : "false") +
                  ",\"corrects_orientation\":" + (ORI ? "true" : "false") +
                  ",\"chain_transforms\":" + std::to_string(spec.actual.elems.size()) +
                  ",\"samples\":" + std::to_string(opt.samples) + ",\"checks\":{" +
                  "\"pose_max_abs_diff_baseline_vs_generated\":" + num(pose_diff) +
                  ",\"pose_max_abs_diff_numpy_vs_generated\":" + num(numpy_diff) +
                  ",\"pose_max_abs_diff_numpy_vs_baseline\":" + num(numpy_base_diff) +
                  ",\"numpy_check_points\":" + std::to_string(spec.check_axes.size()) +
                  ",\"tolerance\":" + num(kCheckTolerance) +
                  ",\"exact_point_error_max_abs\":" + num(err_size) +
                  ",\"error_order1_max_abs_diff_vs_exact\":" + num(err1_diff) +
                  ",\"error_order2_max_abs_diff_vs_exact\":" + num(err2_diff) +
                  ",\"jacobian_max_rel_diff_fd_vs_generated\":" + num(jac_diff) +
                  ",\"compensate_max_axis_diff\":" + num(comp_axis_diff) +
                  ",\"compensate_max_axis_diff_where_both_ok\":" + (gen_ok ? num(comp_axis_diff_ok) : std::string("null")) +
                  ",\"compensate_status_mismatches\":" + std::to_string(status_mismatch) +
                  ",\"compensate_ok_generated\":" + std::to_string(gen_ok) +
                  ",\"compensate_ok_baseline\":" + std::to_string(base_ok) +
                  ",\"compensate_max_residual_point_generated\":" + num(comp_res_gen) +
                  ",\"compensate_max_residual_point_baseline\":" + num(comp_res_base) +
                  ",\"stream_max_axis_diff_warm_vs_cold\":" + num(stream_diff) +
                  ",\"stream_status_mismatches\":" + std::to_string(stream_mismatch) +
                  ",\"before_40_max_axis_diff\":" + (before40_diff >= 0 ? num(before40_diff) : std::string("null")) +
                  "},\"timings\":{";
  for (std::size_t i = 0; i < rows.size(); ++i) {
    if (i) j += ",";
    j += "\"" + std::string(rows[i].fn) + "\":{\"generated\":" + stats_json(rows[i].gen) +
         ",\"baseline\":" + stats_json(rows[i].base) + "}";
  }
  j += "}}";
  return j;
}

using BenchFn = std::string (*)(const MachineSpec&, const chaincomp::ModelEntry&, const void*, const Options&);

// ori: a tool frame with three or more rotary axes, corrected in full (compensate.hpp's
// kCorrectsOrientation)
BenchFn pick(int ps, bool dir, bool ori) {
  if (ps == 3 && !dir) return bench_machine<3, false>;
  if (ps == 6 && !dir) return bench_machine<6, false>;
  if (ps == 6 && dir) return bench_machine<6, true>;
  if (ps == 9 && !dir) return bench_machine<9, false>;
  if (ps == 9 && dir && !ori) return bench_machine<9, true>;
  if (ps == 9 && dir && ori) return bench_machine<9, true, true>;
  return nullptr;
}

}  // namespace

int main(int argc, char** argv) {
  if (argc < 2) die("usage: bench_codegen CHAINS.txt [--samples N] [--batches N] [--batch-ms MS] [--seed N]");
  Options opt;
  for (int i = 2; i < argc; ++i) {
    const std::string a = argv[i];
    if (i + 1 >= argc) die("missing value after " + a);
    const char* v = argv[++i];
    if (a == "--samples") opt.samples = std::atoi(v);
    else if (a == "--batches") opt.batches = std::atoi(v);
    else if (a == "--batch-ms") opt.batch_ms = std::atof(v);
    else if (a == "--seed") opt.seed = static_cast<unsigned>(std::strtoul(v, nullptr, 10));
    else if (a == "--tables-machine") opt.tables_machine = v;
    else if (a == "--tables") opt.tables = v;
    else if (a == "--tables-linear") opt.tables_linear = v;
    else die("unknown option " + a);
  }
  if (opt.samples < 1 || opt.batches < 1 || !(opt.batch_ms > 0)) die("bad option value");
  if (opt.tables.empty() != opt.tables_machine.empty()) die("--tables and --tables-machine go together");

  std::string json = "{\"machines\":[";
  bool first = true;
  for (const MachineSpec& spec : read_specs(argv[1])) {
    const chaincomp::ModelEntry* e = chaincomp::find_model(spec.name.c_str());
    if (e == nullptr) die("machine " + spec.name + " is not compiled into chaincomp_models");
    const auto& info = *e->info;
    if (info.num_axes != static_cast<int>(spec.axis_names.size())) die(spec.name + ": axis count differs from the export");
    for (int i = 0; i < info.num_axes; ++i)
      if (spec.axis_names[i] != info.axes[i].name) die(spec.name + ": axis " + spec.axis_names[i] + " where the model has " + info.axes[i].name);
    if (info.pose_size != 3 + 3 * spec.actual.has_direction + 3 * spec.actual.has_reference)
      die(spec.name + ": pose size differs from the export");
    if (e->model_size > sizeof(ModelBuffer) || e->model_align > 64) die(spec.name + ": model too large for the buffer");
    // parameters by name, every one required
    std::vector<double> params(info.num_params);
    for (int i = 0; i < info.num_params; ++i) {
      auto it = std::find_if(spec.params.begin(), spec.params.end(),
                             [&](const auto& p) { return p.first == info.params[i].name; });
      if (it == spec.params.end()) die(spec.name + ": the export has no value for parameter " + info.params[i].name);
      params[i] = it->second;
    }
    if (static_cast<int>(spec.params.size()) != info.num_params) die(spec.name + ": the export has unknown parameters");
    auto* buf = new ModelBuffer;
    e->prepare(params.data(), buf->bytes);
    int rotary = 0;
    for (int i = 0; i < info.num_axes; ++i) rotary += info.axes[i].kind == chaincomp::UnitKind::kAngle;
    const BenchFn fn = pick(info.pose_size, info.corrects_direction, info.pose_size == 9 && rotary >= 3);
    if (fn == nullptr) die(spec.name + ": no baseline for this pose size / direction correction");
    json += (first ? "" : ",") + fn(spec, *e, buf->bytes, opt);
    first = false;
    delete buf;
  }
  json += "],\"tables\":" + (opt.tables.empty() ? std::string("null") : bench_tables(opt));
  g_sink = g_sink_store;
  json += ",\"sink\":" + num(g_sink) + ",\"options\":{\"samples\":" + std::to_string(opt.samples) +
          ",\"batches\":" + std::to_string(opt.batches) + ",\"batch_ms\":" + num(opt.batch_ms) +
          ",\"seed\":" + std::to_string(opt.seed) + "},\"compiler\":\"" + kCompiler + "\"}";
  std::printf("%s\n", json.c_str());
  return 0;
}
