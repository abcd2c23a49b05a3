// Every compiled model against the Python exact model's reference values, its Jacobian
// against central differences, and compensation against the exact pose.
#include <catch2/catch.hpp>

#include <cmath>
#include <fstream>
#include <random>
#include <sstream>
#include <string>
#include <vector>

#include "chaincomp/compensate.hpp"
#include "chaincomp/model_info.hpp"

namespace {

struct Vector {
  std::vector<double> axes, params, exact, nominal, order1, order2;
};

std::vector<Vector> read_vectors(const std::string& name, int num_axes, int num_params, int pose_size) {
  std::ifstream in(std::string(CHAINCOMP_VECTOR_DIR) + "/" + name + ".txt");
  REQUIRE(in.good());
  std::string line;
  std::vector<Vector> out;
  int count = 0, na = 0, np = 0, ps = 0;
  while (std::getline(in, line)) {
    if (line.empty() || line[0] == '#') continue;
    std::istringstream ss(line);
    if (count == 0 && out.empty() && na == 0) {
      ss >> count >> na >> np >> ps;
      REQUIRE(na == num_axes);
      REQUIRE(np == num_params);
      REQUIRE(ps == pose_size);
      continue;
    }
    Vector v;
    auto take = [&ss](std::vector<double>& dst, int n) {
      dst.resize(n);
      for (double& x : dst) ss >> x;
    };
    take(v.axes, na);
    take(v.params, np);
    take(v.exact, ps);
    take(v.nominal, ps);
    take(v.order1, ps);
    take(v.order2, ps);
    REQUIRE(!ss.fail());
    out.push_back(v);
  }
  REQUIRE(static_cast<int>(out.size()) == count);
  return out;
}

// Storage for a type-erased model, aligned for any generated Model.
struct ModelBuffer {
  alignas(64) unsigned char bytes[1 << 14];
};

double norm(const std::vector<double>& v, int from, int n) {
  double s = 0;
  for (int i = from; i < from + n; ++i) s += v[i] * v[i];
  return std::sqrt(s);
}

}  // namespace

TEST_CASE("every bundled machine is compiled into the registry", "[registry]") {
  REQUIRE(chaincomp::model_count() >= 4);
  for (const char* name : {"angle_head", "me220_xz", "mori_seiki_nv1500", "five_axis_ac"}) {
    INFO(name);
    REQUIRE(chaincomp::find_model(name) != nullptr);
  }
  REQUIRE(chaincomp::find_model("no_such_machine") == nullptr);
}

TEST_CASE("generated models match the Python exact and truncated models", "[models]") {
  for (std::size_t m = 0; m < chaincomp::model_count(); ++m) {
    const chaincomp::ModelEntry& e = *chaincomp::model_at(m);
    const auto& info = *e.info;
    const int ps = info.pose_size, na = info.num_axes;
    INFO("machine " << info.name);
    REQUIRE(e.model_size <= sizeof(ModelBuffer));
    ModelBuffer buf;
    for (const Vector& v : read_vectors(info.name, na, info.num_params, ps)) {
      e.prepare(v.params.data(), buf.bytes);
      std::vector<double> pose(ps), nominal(ps), err(ps), jac(ps * na);
      e.pose_exact(buf.bytes, v.axes.data(), pose.data());
      e.pose_nominal(buf.bytes, v.axes.data(), nominal.data());
      for (int i = 0; i < ps; ++i) {
        CHECK(std::abs(pose[i] - v.exact[i]) < 1e-9);
        CHECK(std::abs(nominal[i] - v.nominal[i]) < 1e-9);
      }
      for (int order = 1; order <= 2; ++order) {
        const auto& want = order == 1 ? v.order1 : v.order2;
        REQUIRE(e.error(buf.bytes, v.axes.data(), order, err.data()));
        // relative to the size of the error vector (point and direction separately)
        for (int part = 0; part < ps; part += 3) {
          const double scale = norm(want, part, 3);
          for (int i = part; i < part + 3; ++i) CHECK(std::abs(err[i] - want[i]) <= 1e-12 * scale + 1e-300);
        }
      }
      REQUIRE_FALSE(e.error(buf.bytes, v.axes.data(), e.max_order + 1, err.data()));

      // Jacobian against central differences of pose_exact: error ~ h^2 + eps/h.
      e.pose_jacobian(buf.bytes, v.axes.data(), pose.data(), jac.data());
      const double h = 1e-5;
      for (int j = 0; j < na; ++j) {
        std::vector<double> qp = v.axes, qm = v.axes, pp(ps), pm(ps);
        qp[j] += h;
        qm[j] -= h;
        e.pose_exact(buf.bytes, qp.data(), pp.data());
        e.pose_exact(buf.bytes, qm.data(), pm.data());
        for (int i = 0; i < ps; ++i) {
          const double fd = (pp[i] - pm[i]) / (2 * h);
          CHECK(std::abs(jac[i + ps * j] - fd) < 1e-6 * (1 + std::abs(fd)));
        }
      }
    }
  }
}

// The machine's axes can hold its whole pose: the point alone (pose size 3), or point and
// direction with at least five axes of which two rotary (corrects_direction: a rotary axis).
static bool corrects_whole_pose(const chaincomp::MachineInfo& info) {
  if (info.pose_size == 3) return info.num_axes >= 3;
  int rotary = 0;
  for (int i = 0; i < info.num_axes; ++i) rotary += info.axes[i].kind == chaincomp::UnitKind::kAngle;
  return info.corrects_direction && info.num_axes >= 5 && rotary >= 2;
}

TEST_CASE("compensation puts the actual tool point on the nominal one", "[compensate]") {
  for (std::size_t m = 0; m < chaincomp::model_count(); ++m) {
    const chaincomp::ModelEntry& e = *chaincomp::model_at(m);
    const auto& info = *e.info;
    const int ps = info.pose_size, na = info.num_axes;
    INFO("machine " << info.name);
    int near_singular = 0;
    ModelBuffer buf;
    for (const Vector& v : read_vectors(info.name, na, info.num_params, ps)) {
      e.prepare(v.params.data(), buf.bytes);
      std::vector<double> corrected(na), target(ps), actual(ps), before(ps);
      double residual[2];
      const auto status = static_cast<chaincomp::Status>(
          e.compensate(buf.bytes, nullptr, v.axes.data(), chaincomp::kDefaultDirectionWeight, corrected.data(), residual, nullptr));
      e.pose_nominal(buf.bytes, v.axes.data(), target.data());
      e.pose_exact(buf.bytes, corrected.data(), actual.data());
      e.pose_exact(buf.bytes, v.axes.data(), before.data());
      double point_after = 0, dir_after = 0, dir_before = 0, point_before = 0;
      for (int i = 0; i < 3; ++i) {
        point_after += (actual[i] - target[i]) * (actual[i] - target[i]);
        point_before += (before[i] - target[i]) * (before[i] - target[i]);
      }
      for (int i = 3; i < ps; ++i) {
        dir_after += (actual[i] - target[i]) * (actual[i] - target[i]);
        dir_before += (before[i] - target[i]) * (before[i] - target[i]);
      }
      // the documented objective (docs/guide/daemon.md): the direction wherever the pose has one
      const double w2 = ps >= 6 ? chaincomp::kDefaultDirectionWeight * chaincomp::kDefaultDirectionWeight : 0.0;
      const double objective_after = point_after + w2 * dir_after;
      const double objective_before = point_before + w2 * dir_before;
      point_after = std::sqrt(point_after);
      dir_after = std::sqrt(dir_after);
      // the reported residual is the true one
      CHECK(std::abs(residual[0] - point_after) < 1e-9);
      if (status == chaincomp::Status::kOk) {
        CHECK(point_after < 1e-6);  // 1 nm
        if (info.corrects_direction) CHECK(dir_after < 1e-9);
      } else {
        REQUIRE(status == chaincomp::Status::kResidual);
        CHECK(objective_after <= objective_before);  // never worse than no correction
      }
      // Machines whose axes can hold the whole pose (a point alone, or two rotary axes for the
      // direction): the point is always corrected; the direction too, except near a singular
      // pose (tool along the C axis), where the rotary correction stops at its bound and the
      // rest is reported. (Three slides cannot correct a tilt: status 1 reports it.)
      if (corrects_whole_pose(info)) {
        CHECK(point_after < 1e-6);
        if (status != chaincomp::Status::kOk) ++near_singular;
      }
    }
    // A few of a machine's 40 random commands fall near a singular pose (the tool along C, or
    // a nutating table at its largest tilt, B = 180 deg); nearly all are corrected fully.
    CHECK(near_singular <= 2);
  }
}

TEST_CASE("compensation rejects a non-finite command without computing", "[compensate]") {
  const chaincomp::ModelEntry& e = *chaincomp::find_model("five_axis_ac");
  ModelBuffer buf;
  std::vector<double> params(e.info->num_params);
  for (int i = 0; i < e.info->num_params; ++i) params[i] = e.info->params[i].nominal;
  e.prepare(params.data(), buf.bytes);
  std::vector<double> cmd(e.info->num_axes, 0.1), out(e.info->num_axes);
  cmd[2] = std::nan("");
  double residual[2];
  CHECK(e.compensate(buf.bytes, nullptr, cmd.data(), chaincomp::kDefaultDirectionWeight, out.data(), residual, nullptr) ==
        static_cast<int>(chaincomp::Status::kNonFiniteInput));
}

TEST_CASE("near the tool-along-C singularity the correction stays bounded", "[compensate]") {
  const chaincomp::ModelEntry& e = *chaincomp::find_model("five_axis_ac");
  alignas(64) static unsigned char model[1 << 14];
  std::vector<double> params(e.info->num_params);
  for (int i = 0; i < e.info->num_params; ++i) {
    const auto& p = e.info->params[i];
    params[i] = p.role == chaincomp::ParamRole::kError
                    ? (p.kind == chaincomp::UnitKind::kLength ? 5e-3 : 20.0 * M_PI / 648000.0)
                    : p.nominal;
  }
  e.prepare(params.data(), model);
  const double deg = M_PI / 180.0;
  // 2000 commands with the tool within 2 degrees of the C axis (seeded), and A exactly 0
  std::mt19937 rng(7);
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  int residual_status = 0;
  for (int k = 0; k < 2000; ++k) {
    const double a = k == 0 ? 0.0 : 2.0 * deg * u(rng);
    const double cmd[5] = {300 * u(rng), 250 * u(rng), -200 + 150 * u(rng), a, 180 * deg * u(rng)};
    double out[5], residual[2], target[6], actual[6];
    const auto status = static_cast<chaincomp::Status>(e.compensate(model, nullptr, cmd, chaincomp::kDefaultDirectionWeight, out, residual, nullptr));
    INFO("A = " << a / deg << " deg, status " << chaincomp::status_name(status));
    REQUIRE((status == chaincomp::Status::kOk || status == chaincomp::Status::kResidual));
    residual_status += status == chaincomp::Status::kResidual;
    for (int i = 0; i < 3; ++i) CHECK(std::abs(out[i] - cmd[i]) <= chaincomp::kMaxLinearCorrection);
    for (int i = 3; i < 5; ++i) CHECK(std::abs(out[i] - cmd[i]) <= chaincomp::kMaxAngularCorrection + 1e-15);
    e.pose_nominal(model, cmd, target);
    e.pose_exact(model, out, actual);
    double point = 0;
    for (int i = 0; i < 3; ++i) point += (actual[i] - target[i]) * (actual[i] - target[i]);
    CHECK(std::sqrt(point) < 1e-6);  // the tool point is corrected (1 nm) even here
    CHECK(std::abs(std::sqrt(point) - residual[0]) < 1e-9);  // the residual reported is the true one
  }
  CHECK(residual_status > 0);  // some directions are left uncorrected (and reported) here
}

TEST_CASE("a stream with a kept workspace corrects every command as a cold start does", "[compensate]") {
  // A smooth path (steps well within the warm-start range) with a few jumps, through every
  // bundled machine: the warm start must land where a cold start lands, within tolerance.
  for (std::size_t m = 0; m < chaincomp::model_count(); ++m) {
    const chaincomp::ModelEntry& e = *chaincomp::model_at(m);
    const auto& info = *e.info;
    const int na = info.num_axes, ps = info.pose_size;
    INFO("machine " << info.name);
    ModelBuffer buf;
    e.prepare(read_vectors(info.name, na, info.num_params, ps).front().params.data(), buf.bytes);
    std::vector<unsigned char> storage;
    void* ws = chaincomp::aligned_slot(storage, e.workspace_size, e.workspace_align);
    e.init_workspace(ws);
    int ok = 0;
    for (int k = 0; k < 3000; ++k) {
      std::vector<double> cmd(na), warm(na), cold(na), target(ps), actual(ps);
      for (int i = 0; i < na; ++i) {
        const chaincomp::AxisInfo& a = info.axes[i];
        const double mid = 0.5 * (a.lower + a.upper), half = 0.45 * (a.upper - a.lower);
        const double phase = k % 1000 == 999 ? 2.0 : 0.0;  // a jump now and then
        cmd[i] = (mid + half * std::sin(0.002 * k * (i + 1) + phase + i)) * a.to_internal;
      }
      double rw[2], rc[2];
      const int sw = e.compensate(buf.bytes, ws, cmd.data(), chaincomp::kDefaultDirectionWeight, warm.data(), rw, nullptr);
      const int sc = e.compensate(buf.bytes, nullptr, cmd.data(), chaincomp::kDefaultDirectionWeight, cold.data(), rc, nullptr);
      INFO("command " << k);
      REQUIRE(sw == sc);
      ok += sw == static_cast<int>(chaincomp::Status::kOk);
      if (sw == static_cast<int>(chaincomp::Status::kOk)) {
        // both within tolerance (checked below) of the same solution: a warm start may stop
        // anywhere inside the tolerance (0.1 nm, 1e-9 rad), so the axes agree to about that.
        // One solution only where the axes are no more than the pose's conditions (3, or 5 with
        // the direction): an arm's extra joints leave a set of equally good corrections, and a
        // warm start may stop elsewhere on it; there the poses agree (checked below), not the axes.
        if (na <= (info.corrects_direction ? 5 : 3))
          for (int i = 0; i < na; ++i) CHECK(std::abs(warm[i] - cold[i]) < 1e-6);
      } else {  // fewer DOF than the pose: the least-squares optimum may be flat along the axes
        CHECK(std::abs(rw[0] - rc[0]) < 1e-9);
        CHECK(std::abs(rw[1] - rc[1]) < 1e-11);
      }
      e.pose_nominal(buf.bytes, cmd.data(), target.data());
      e.pose_exact(buf.bytes, warm.data(), actual.data());
      double point = 0;
      for (int i = 0; i < 3; ++i) point += (actual[i] - target[i]) * (actual[i] - target[i]);
      CHECK(std::abs(std::sqrt(point) - rw[0]) < 1e-9);  // the residual reported is the true one
      if (sw == static_cast<int>(chaincomp::Status::kOk)) {
        CHECK(std::sqrt(point) <= chaincomp::kPointTolerance * (1 + 1e-9));
        double dir = 0;
        for (int i = 3; i < ps; ++i) dir += (actual[i] - target[i]) * (actual[i] - target[i]);
        // with a tool frame (pose size 9) the tolerance is on the rotation vector w; the frame's
        // z and x axes then move by w x z and w x x, together up to sqrt(2) |w|
        const double axes = ps == 9 ? std::sqrt(2.0) : 1.0;
        if (info.corrects_direction) CHECK(std::sqrt(dir) <= axes * chaincomp::kDirectionTolerance * (1 + 1e-6));
      }
    }
    // where the axes can correct the whole pose, nearly every command is corrected fully
    if (corrects_whole_pose(info)) CHECK(ok > 2900);
  }
}

TEST_CASE("a kept workspace through the singular pose: bounded, and a residual exactly as cold", "[compensate]") {
  // five_axis_ac with the tool swinging through the C axis (A = 3 deg cos(3t), C turning):
  // corrections grow towards the bound there. A warm start must keep every axis within its
  // bound, reach the same status as a cold start, and a residual (redone cold) must be
  // the cold result bit for bit.
  const chaincomp::ModelEntry& e = *chaincomp::find_model("five_axis_ac");
  const int na = e.info->num_axes;
  std::vector<unsigned char> storage;
  void* ws = chaincomp::aligned_slot(storage, e.workspace_size, e.workspace_align);
  int residual_seen = 0;
  for (unsigned seed = 1; seed <= 3; ++seed) {
    std::mt19937 rng(seed);
    std::uniform_real_distribution<double> u(-1.0, 1.0);
    std::vector<double> params(e.info->num_params);
    for (int i = 0; i < e.info->num_params; ++i) {
      const auto& p = e.info->params[i];  // errors up to 10 um and 10 arcsec
      params[i] = p.role == chaincomp::ParamRole::kError
                      ? 10.0 * u(rng) * (p.kind == chaincomp::UnitKind::kLength ? 1e-3 : M_PI / 648000.0)
                      : p.nominal;
    }
    ModelBuffer buf;
    e.prepare(params.data(), buf.bytes);
    e.init_workspace(ws);
    for (int k = 0; k < 20000; ++k) {
      const double t = 1e-4 * k;
      const double cmd[5] = {100 * std::sin(t), 80 * std::cos(1.3 * t), -200 + 50 * std::sin(0.7 * t),
                             3 * std::cos(3 * t) * M_PI / 180, 2 * t};
      double warm[5], cold[5], rw[2], rc[2];
      const int sw = e.compensate(buf.bytes, ws, cmd, chaincomp::kDefaultDirectionWeight, warm, rw, nullptr);
      const int sc = e.compensate(buf.bytes, nullptr, cmd, chaincomp::kDefaultDirectionWeight, cold, rc, nullptr);
      INFO("seed " << seed << ", command " << k);
      REQUIRE(sw == sc);
      for (int i = 0; i < na; ++i) {
        const double bound = i < 3 ? chaincomp::kMaxLinearCorrection : chaincomp::kMaxAngularCorrection;
        CHECK(std::abs(warm[i] - cmd[i]) <= bound);
      }
      if (sw == static_cast<int>(chaincomp::Status::kResidual)) {
        ++residual_seen;
        for (int i = 0; i < na; ++i) CHECK(warm[i] == cold[i]);
        CHECK(rw[0] == rc[0]);
        CHECK(rw[1] == rc[1]);
      } else {
        REQUIRE(sw == static_cast<int>(chaincomp::Status::kOk));
        CHECK(rw[0] <= chaincomp::kPointTolerance);  // and the reported residual is the true one:
        CHECK(rw[1] <= chaincomp::kDirectionTolerance);  // checked on other paths above
      }
    }
  }
  CHECK(residual_seen > 0);  // the path does reach the singular pose
}
