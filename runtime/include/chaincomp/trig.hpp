// Sines and cosines for the generated models and the compensator: of the axes (any angle up
// to kSinCosLimit, by a reduction to [-pi/4, pi/4] and Taylor polynomials) and of small
// angles (errors, corrections: a short series). Plain arithmetic without branches, where the
// library's sin and cos (a call each, with its own reduction and branches) cost twice as
// much and were a ninth of a cold compensation on a six-joint arm. Against the library:
// tests/cpp/test_trig.cpp.
#pragma once

#include <cmath>

namespace chaincomp {

// Below this |x| (rad) the series below are exact to rounding: their truncation is < 1e-20
// relative.
constexpr double kSmallAngle = 0.015625;  // 2^-6

inline double sin_small_series(double x) noexcept {
  const double x2 = x * x;
  return x + x * x2 * (-1.0 / 6 + x2 * (1.0 / 120 + x2 * (-1.0 / 5040)));
}
inline double cos_small_series(double x) noexcept {
  const double x2 = x * x;
  return 1.0 + x2 * (-0.5 + x2 * (1.0 / 24 + x2 * (-1.0 / 720 + x2 * (1.0 / 40320))));
}

// sin and cos of an angle that is usually an error (µrad to arcmin): the series below
// kSmallAngle, the library otherwise. The generated set_errors uses them: tables of angular
// errors recompute these per evaluation.
inline double sin_small(double x) noexcept { return std::abs(x) < kSmallAngle ? sin_small_series(x) : std::sin(x); }
inline double cos_small(double x) noexcept { return std::abs(x) < kSmallAngle ? cos_small_series(x) : std::cos(x); }

// Up to this |x| (rad) sin_cos_reduced reduces exactly enough: n = round(x 2/pi) < 2^17, so
// n times each of the first two parts of pi/2 below is exact. Beyond it (and for NaN, Inf)
// callers use the library.
constexpr double kSinCosLimit = 1e5;

// The reduction needs IEEE double arithmetic as written: -ffast-math (and gcc's
// -fassociative-math) fold (a + kRound) - kRound to a, and x87 excess precision
// (__FLT_EVAL_METHOD__ 2: i386 without -mfpmath=sse) keeps a + kRound from rounding to an
// integer; either gives sines and cosines of the wrong quadrant. There the library's.
#if defined(__FAST_MATH__) || defined(__ASSOCIATIVE_MATH__) || (defined(__FLT_EVAL_METHOD__) && __FLT_EVAL_METHOD__ != 0)
constexpr bool kReducedTrig = false;
#else
constexpr bool kReducedTrig = true;
#endif

// sin and cos of x, |x| <= kSinCosLimit. x - n pi/2 in three parts (Cody and Waite: pi/2 =
// kPio2a + kPio2b + kPio2c, the first two of 33 significant bits), the Taylor series of sin
// and cos on [-pi/4, pi/4] to the terms x^17 and x^18 (the next below 1e-19), and the
// quadrant n mod 4 picks and signs them. No integer conversion: beyond the limit (or NaN)
// the result is wrong, not undefined behaviour.
inline void sin_cos_reduced(double x, double& s, double& c) noexcept {
  if constexpr (!kReducedTrig) {
    s = std::sin(x);
    c = std::cos(x);
    return;
  }
  constexpr double kTwoOverPi = 0.6366197723675814;
  constexpr double kPio2a = 0x1.921fb544p+0;        // 1.5707963267341256
  constexpr double kPio2b = 0x1.0b4611a6p-34;       // 6.077100506303966e-11
  constexpr double kPio2c = 0x1.3198a2e037073p-69;  // 2.0222662487959506e-21
  constexpr double kRound = 0x1.8p52;               // adding it rounds to an integer (to nearest)
  const double n = (x * kTwoOverPi + kRound) - kRound;
  const double r = ((x - n * kPio2a) - n * kPio2b) - n * kPio2c;
  const double r2 = r * r;
  const double sr =
      r + r * r2 *
              (-1.0 / 6 +
               r2 * (1.0 / 120 +
                     r2 * (-1.0 / 5040 +
                           r2 * (1.0 / 362880 +
                                 r2 * (-1.0 / 39916800 +
                                       r2 * (1.0 / 6227020800 +
                                             r2 * (-1.0 / 1307674368000 + r2 * (1.0 / 355687428096000))))))));
  const double cr =
      1.0 + r2 * (-0.5 +
                  r2 * (1.0 / 24 +
                        r2 * (-1.0 / 720 +
                              r2 * (1.0 / 40320 +
                                    r2 * (-1.0 / 3628800 +
                                          r2 * (1.0 / 479001600 +
                                                r2 * (-1.0 / 87178291200 +
                                                      r2 * (1.0 / 20922789888000 +
                                                            r2 * (-1.0 / 6402373705728000)))))))));
  // m = n - 4 round(n / 4), in {-1, 0, 1, +-2}: the quadrant 3, 0, 1, 2.
  const double m = n - 4.0 * ((n * 0.25 + kRound) - kRound);
  const bool odd = m * m == 1.0;  // quadrants 1 and 3 swap sin and cos
  const double sq = odd ? cr : sr, cq = odd ? sr : cr;
  s = (m < 0.0 || m > 1.5) ? -sq : sq;   // sin < 0 in quadrants 2 and 3
  s = x == 0.0 ? x : s;                  // sin(-0) = -0, as the library's
  c = (m > 0.5 || m < -1.5) ? -cq : cq;  // cos < 0 in quadrants 1 and 2
}

}  // namespace chaincomp
