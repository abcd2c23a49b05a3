// trig.hpp and the axes' sines and cosines in compensate.hpp, against the x87 long double
// sinl / cosl (64-bit significands: exact enough to measure a double's error) and the
// library's sin / cos.
#include <catch2/catch.hpp>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <limits>
#include <random>

#include "chaincomp/compensate.hpp"
#include "chaincomp/trig.hpp"

namespace {

// |a - truth| in long double.
double error(double a, long double truth) { return static_cast<double>(std::fabs(static_cast<long double>(a) - truth)); }

// Worst absolute error of sin_cos_reduced over n uniform angles in [-range, range].
double worst_error(double range, int n, std::uint64_t seed) {
  std::mt19937_64 rng(seed);
  std::uniform_real_distribution<double> uniform(-range, range);
  double worst = 0;
  for (int i = 0; i < n; ++i) {
    const double x = uniform(rng);
    double s, c;
    chaincomp::sin_cos_reduced(x, s, c);
    worst = std::max({worst, error(s, sinl(x)), error(c, cosl(x))});
  }
  return worst;
}

}  // namespace

TEST_CASE("sin_cos_reduced is within 2.5e-16 of sin and cos up to its limit", "[trig]") {
  // The library's own error here is up to 5.6e-17 (half an ulp); the polynomials and the
  // reduction add about 1.5 ulp.
  CHECK(worst_error(7.0, 200000, 1) <= 2.5e-16);                        // a few turns: joints
  CHECK(worst_error(1e3, 200000, 2) <= 2.5e-16);                        // many turns: a spindle
  CHECK(worst_error(chaincomp::kSinCosLimit, 200000, 3) <= 2.5e-16);    // the limit
}

TEST_CASE("sin_cos_reduced near multiples of pi/2 keeps its absolute error tiny", "[trig]") {
  // There the reduced angle cancels to a few ulps of x: the three-part pi/2 keeps it exact.
  double worst = 0;
  for (long k = -63600; k <= 63600; k += 7) {
    double x = static_cast<double>(k * 1.5707963267948966192313216916397514L);
    for (int step = 0; step < 4; ++step, x = std::nextafter(x, 1e9)) {
      double s, c;
      chaincomp::sin_cos_reduced(x, s, c);
      worst = std::max({worst, error(s, sinl(x)), error(c, cosl(x))});
    }
  }
  CHECK(worst <= 1e-20);
}

TEST_CASE("sin_cos_reduced at exact points and by quadrant", "[trig]") {
  double s, c;
  chaincomp::sin_cos_reduced(0.0, s, c);
  CHECK(s == 0.0);
  CHECK(c == 1.0);
  // One angle per quadrant, both signs: the signs and the swap of sin and cos.
  for (double x : {0.3, 1.9, 3.5, 5.2, -0.3, -1.9, -3.5, -5.2, 100.0, -100.0}) {
    chaincomp::sin_cos_reduced(x, s, c);
    CHECK(s == Approx(std::sin(x)).margin(3e-16));
    CHECK(c == Approx(std::cos(x)).margin(3e-16));
  }
}

TEST_CASE("the small-angle series equal sin and cos below 2^-6", "[trig]") {
  std::mt19937_64 rng(4);
  std::uniform_real_distribution<double> uniform(-chaincomp::kSmallAngle, chaincomp::kSmallAngle);
  double worst_sin = 0, worst_cos = 0;
  for (int i = 0; i < 100000; ++i) {
    const double x = uniform(rng);
    worst_sin = std::max(worst_sin, error(chaincomp::sin_small(x), sinl(x)) / std::max(std::fabs(x), 1e-300));
    worst_cos = std::max(worst_cos, error(chaincomp::cos_small(x), cosl(x)));
  }
  CHECK(worst_sin <= 2.3e-16);  // relative: about an ulp
  CHECK(worst_cos <= 1.2e-16);
  // Above it, the library itself.
  CHECK(chaincomp::sin_small(0.5) == std::sin(0.5));
  CHECK(chaincomp::cos_small(-0.5) == std::cos(-0.5));
}

TEST_CASE("axis_trig: the angles' sines and cosines, the library beyond the limit and for NaN", "[trig]") {
  constexpr unsigned kMask = 0b10110;  // axes 1, 2 and 4 angles; 0 and 3 linear
  using Axes = Eigen::Matrix<double, 5, 1>;
  chaincomp::AxisTrig<5> t;
  Axes q(1234.5, -2.5, 0.75, -900.0, 31.0);
  chaincomp::axis_trig<5, kMask>(q, t);
  for (int i : {1, 2, 4}) {
    CHECK(t.s[i] == Approx(std::sin(q[i])).margin(3e-16));
    CHECK(t.c[i] == Approx(std::cos(q[i])).margin(3e-16));
  }
  // One angle beyond kSinCosLimit: every angle from the library (its values exactly).
  q[2] = 3e5;
  chaincomp::axis_trig<5, kMask>(q, t);
  for (int i : {1, 2, 4}) {
    CHECK(t.s[i] == std::sin(q[i]));
    CHECK(t.c[i] == std::cos(q[i]));
  }
  q[2] = std::numeric_limits<double>::quiet_NaN();
  chaincomp::axis_trig<5, kMask>(q, t);
  CHECK(std::isnan(t.s[2]));
  CHECK(std::isnan(t.c[2]));
  CHECK(t.s[4] == std::sin(31.0));
  // A linear axis far beyond the limit does not matter.
  Axes far(1e12, -2.5, 0.75, -1e12, 31.0);
  chaincomp::axis_trig<5, kMask>(far, t);
  CHECK(t.s[1] == Approx(std::sin(-2.5)).margin(3e-16));
}

TEST_CASE("axis_trig_near: sines and cosines a correction away from the command", "[trig]") {
  constexpr unsigned kMask = 0b111;
  using Axes = Eigen::Matrix<double, 3, 1>;
  const Axes base(0.4, -2.0, 6.0);
  chaincomp::AxisTrig<3> base_trig, t;
  chaincomp::axis_trig<3, kMask>(base, base_trig);
  // Steps within 2^-6 (the series), and one of 0.0175 rad (the correction bound: the library).
  for (const Axes& step : {Axes(1e-3, -4e-4, 2e-6), Axes(0.0155, -0.0155, 0.0), Axes(0.0175, 1e-3, -1e-3)}) {
    const Axes q = base + step;
    chaincomp::axis_trig_near<3, kMask>(base, base_trig, q, t);
    for (int i = 0; i < 3; ++i) {
      CHECK(t.s[i] == Approx(std::sin(q[i])).margin(5e-16));
      CHECK(t.c[i] == Approx(std::cos(q[i])).margin(5e-16));
    }
  }
}
