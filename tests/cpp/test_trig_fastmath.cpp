// trig.hpp compiled with -ffast-math (its own program: an inline function compiled two ways in
// one program would break the one-definition rule). The reduction's rounding by adding and
// subtracting 1.5 2^52 is folded away under fast-math, which gave sines of the wrong quadrant
// (error 2); trig.hpp detects the flag and takes the library's sin and cos.
#include <catch2/catch.hpp>

#include <cmath>
#include <random>

#include "chaincomp/trig.hpp"

#ifndef __FAST_MATH__
#error "compile this test with -ffast-math"
#endif

TEST_CASE("under -ffast-math sin_cos_reduced is the library's (right quadrant)", "[trig_fastmath]") {
  static_assert(!chaincomp::kReducedTrig, "fast-math detected");
  std::mt19937_64 rng(9);
  std::uniform_real_distribution<double> uniform(-chaincomp::kSinCosLimit, chaincomp::kSinCosLimit);
  double worst = 0;
  for (int i = 0; i < 20000; ++i) {
    const double x = uniform(rng);
    double s, c;
    chaincomp::sin_cos_reduced(x, s, c);
    worst = std::fmax(worst, std::fmax(std::fabs(static_cast<double>(s - sinl(x))), std::fabs(static_cast<double>(c - cosl(x)))));
  }
  CHECK(worst <= 2.5e-16);
}
