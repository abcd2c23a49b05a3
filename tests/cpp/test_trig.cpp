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

// ---- review of ed81529 (bad input, boundaries, masks) ----------------------------------------

// The library's sin(-0) is -0 (C99 F.9.4.1); in r + r r2 P the sum -0 + (+0) rounds to +0,
// which sin_cos_reduced mends. Harmless for the poses (products and sums), visible where a
// sign of zero matters (atan2, 1/x, a printed "-0").
TEST_CASE("sin_cos_reduced(-0) is -0, as the library's sin", "[trig]") {
  double s, c;
  chaincomp::sin_cos_reduced(-0.0, s, c);
  CHECK(std::signbit(s));
  CHECK(std::signbit(std::sin(-0.0)));
}

TEST_CASE("sin_cos_reduced: signed zero, subnormals, the smallest normal", "[trig]") {
  double s, c;
  chaincomp::sin_cos_reduced(-0.0, s, c);
  CHECK(s == 0.0);
  CHECK(c == 1.0);
  for (double x : {5e-324, -5e-324, 1e-310, -1e-310, 2.2250738585072014e-308, 1e-200}) {
    chaincomp::sin_cos_reduced(x, s, c);
    CHECK(s == x);  // sin x = x to rounding below 1e-8
    CHECK(c == 1.0);
  }
}

TEST_CASE("sin_cos_reduced where the quadrant changes (x near (k + 1/2) pi/2) and at the limit", "[trig]") {
  // There n = round(x 2/pi) switches and the reduced angle is +-pi/4: the polynomials' widest
  // argument, and a tie of the rounding where x 2/pi lands on a half-integer.
  double worst = 0;
  const long last = static_cast<long>(chaincomp::kSinCosLimit / 1.5707963267948966) + 1;
  for (long k = -last; k <= last; ++k) {
    const double mid = static_cast<double>((k + 0.5L) * 1.5707963267948966192313216916397514L);
    double x = mid;
    for (int i = 0; i < 3; ++i) x = std::nextafter(x, -1e9);
    for (int step = 0; step < 7; ++step, x = std::nextafter(x, 1e9)) {
      if (std::abs(x) > chaincomp::kSinCosLimit) continue;
      double s, c;
      chaincomp::sin_cos_reduced(x, s, c);
      worst = std::max({worst, error(s, sinl(x)), error(c, cosl(x))});
    }
  }
  CHECK(worst <= 2.5e-16);
  // at the limit and the doubles next to it inside
  double x = chaincomp::kSinCosLimit;
  for (int i = 0; i < 1000; ++i, x = std::nextafter(x, 0.0)) {
    for (double y : {x, -x}) {
      double s, c;
      chaincomp::sin_cos_reduced(y, s, c);
      CHECK(error(s, sinl(y)) <= 2.5e-16);
      CHECK(error(c, cosl(y)) <= 2.5e-16);
    }
  }
}

TEST_CASE("sin_cos_reduced at the double nearest every multiple of pi/2 up to the limit", "[trig]") {
  double worst = 0;
  const long last = static_cast<long>(chaincomp::kSinCosLimit / 1.5707963267948966);
  for (long k = -last; k <= last; ++k) {
    const double x = static_cast<double>(k * 1.5707963267948966192313216916397514L);
    for (double y : {std::nextafter(x, -1e9), x, std::nextafter(x, 1e9)}) {
      double s, c;
      chaincomp::sin_cos_reduced(y, s, c);
      worst = std::max({worst, error(s, sinl(y)), error(c, cosl(y))});
    }
  }
  CHECK(worst <= 1e-20);  // sin there is as small as 1e-12: its error must be too
}

namespace {

// axis_trig<N, Mask> against sinl / cosl on the angle lanes (the linear lanes are not
// checked: nothing reads them), uniform angles in +-range.
template <int N, unsigned Mask>
double axis_trig_error(double range, std::uint64_t seed, int count) {
  using Axes = Eigen::Matrix<double, N, 1>;
  std::mt19937_64 rng(seed);
  std::uniform_real_distribution<double> u(-range, range);
  double worst = 0;
  for (int k = 0; k < count; ++k) {
    Axes q;
    for (int i = 0; i < N; ++i) q[i] = u(rng);
    chaincomp::AxisTrig<N> t;
    chaincomp::axis_trig<N, Mask>(q, t);
    for (int i = 0; i < N; ++i) {
      if (chaincomp::is_angle_axis(Mask, i)) worst = std::max({worst, error(t.s[i], sinl(q[i])), error(t.c[i], cosl(q[i]))});
    }
  }
  return worst;
}

}  // namespace

TEST_CASE("axis_trig on every kind of mask: all angles (the vectorised loop), one, none in between", "[trig]") {
  for (double range : {7.0, chaincomp::kSinCosLimit, 3e5}) {  // 3e5: mostly the library's
    INFO("range " << range);
    CHECK(axis_trig_error<7, 0b1111111u>(range, 1, 20000) <= 2.5e-16);  // the Panda
    CHECK(axis_trig_error<6, 0b111111u>(range, 2, 20000) <= 2.5e-16);   // the UR5
    CHECK(axis_trig_error<5, 0b11000u>(range, 3, 20000) <= 2.5e-16);    // five_axis_ac
    CHECK(axis_trig_error<5, 0b01010u>(range, 4, 20000) <= 2.5e-16);    // X A Y C Z
    CHECK(axis_trig_error<6, 0b100000u>(range, 5, 20000) <= 2.5e-16);   // the last lane only
    CHECK(axis_trig_error<4, 0b0001u>(range, 6, 20000) <= 2.5e-16);     // the first lane only
    CHECK(axis_trig_error<2, 0b11u>(range, 7, 20000) <= 2.5e-16);       // the angle head
    CHECK(axis_trig_error<1, 0b1u>(range, 8, 20000) <= 2.5e-16);
  }
  // An all-angle arm with one lane beyond the limit, NaN or Inf: the library for all lanes;
  // the bad lane NaN, the others their sin and cos.
  using Axes = Eigen::Matrix<double, 6, 1>;
  for (double bad : {2e5, -1e12, std::numeric_limits<double>::quiet_NaN(), std::numeric_limits<double>::infinity()}) {
    Axes q(0.1, -2.0, 3.0, 99999.0, -6.0, 1e-3);
    q[2] = bad;
    chaincomp::AxisTrig<6> t;
    chaincomp::axis_trig<6, 0b111111u>(q, t);
    for (int i = 0; i < 6; ++i) {
      INFO("bad " << bad << " lane " << i);
      if (std::isfinite(q[i])) {
        CHECK(error(t.s[i], sinl(q[i])) <= 2.5e-16);
        CHECK(error(t.c[i], cosl(q[i])) <= 2.5e-16);
      } else {
        CHECK(std::isnan(t.s[i]));
        CHECK(std::isnan(t.c[i]));
      }
    }
  }
}

TEST_CASE("axis_trig_near: bit for bit the base's at the base, the series' switch at 2^-6, bases far out",
          "[trig]") {
  using Axes = Eigen::Matrix<double, 5, 1>;
  constexpr unsigned kMask = 0b01010u;  // X A Y C Z
  for (const Axes& base : {Axes(1.0, 0.4, -2.0, 6.0, 3.0), Axes(1e9, chaincomp::kSinCosLimit, -1e9, -chaincomp::kSinCosLimit, 0.0),
                           Axes(0.0, 1e6, 0.0, -3e5, 0.0), Axes(0.0, -0.0, 5e-324, 1e-310, 0.0)}) {
    INFO("base " << base.transpose());
    chaincomp::AxisTrig<5> bt, t;
    chaincomp::axis_trig<5, kMask>(base, bt);
    // at the base itself: exactly the base's values (compensate's q = command relies on it)
    chaincomp::axis_trig_near<5, kMask>(base, bt, base, t);
    for (int i : {1, 3}) {
      CHECK(t.s[i] == bt.s[i]);
      CHECK(t.c[i] == bt.c[i]);
    }
    // steps at and either side of kSmallAngle on one lane (the branch-free loop or the
    // per-lane one), and up to the correction bound, with the other lane moved or not
    const double k = chaincomp::kSmallAngle;
    for (double d : {std::nextafter(k, 0.0), k, std::nextafter(k, 1.0), -k, 0.0175, -0.0175, 1e-9, 0.0}) {
      for (double other : {0.0, 1e-4, -0.0175}) {
        Axes q = base;
        q[1] += d;
        q[3] += other;
        q[0] += 0.5;  // linear axes move too: they must not matter
        chaincomp::axis_trig_near<5, kMask>(base, bt, q, t);
        for (int i : {1, 3}) {
          // the step as the solver takes it (q - base, exact by Sterbenz near the base)
          const long double truth_angle = static_cast<long double>(base[i]) + static_cast<long double>(q[i] - base[i]);
          INFO("step " << d << " other " << other << " lane " << i);
          CHECK(error(t.s[i], sinl(truth_angle)) <= 4e-16);
          CHECK(error(t.c[i], cosl(truth_angle)) <= 4e-16);
        }
      }
    }
    // NaN in one lane's step: NaN there, the other lane untouched
    Axes q = base;
    q[3] = std::numeric_limits<double>::quiet_NaN();
    q[1] += 1e-3;
    chaincomp::axis_trig_near<5, kMask>(base, bt, q, t);
    CHECK(std::isnan(t.s[3]));
    CHECK(std::isnan(t.c[3]));
    CHECK(error(t.s[1], sinl(static_cast<long double>(base[1]) + static_cast<long double>(q[1] - base[1]))) <= 4e-16);
  }
}
