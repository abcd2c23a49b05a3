// The rotation angle between two frames given by their z and x axes (y = z x x), exactly:
// |Ra - Rt|_F^2 = 4 (1 - cos angle) = 8 sin^2(angle / 2) (better conditioned than acos of the
// trace near 0). Not compensate()'s first-order residual. For the tests.
#pragma once

#include <cmath>

inline double frame_angle(const double* za, const double* xa, const double* zt, const double* xt) {
  auto cross = [](const double* a, const double* b, double* c) {
    c[0] = a[1] * b[2] - a[2] * b[1];
    c[1] = a[2] * b[0] - a[0] * b[2];
    c[2] = a[0] * b[1] - a[1] * b[0];
  };
  double ya[3], yt[3];
  cross(za, xa, ya);
  cross(zt, xt, yt);
  double d2 = 0;
  for (int k = 0; k < 3; ++k) {
    d2 += (xa[k] - xt[k]) * (xa[k] - xt[k]) + (ya[k] - yt[k]) * (ya[k] - yt[k]) + (za[k] - zt[k]) * (za[k] - zt[k]);
  }
  return 2 * std::asin(std::sqrt(d2 / 8));
}
