#include "chaincomp/varying.hpp"

#include <algorithm>
#include <cmath>
#include <cstdio>

namespace chaincomp {

namespace {

int sign(double v) noexcept { return (v > 0) - (v < 0); }

bool room(const VaryingErrors& v, std::string& why) {
  if (v.count >= kMaxVaryingErrors) {
    why = "more than " + std::to_string(kMaxVaryingErrors) + " varying errors";
    return false;
  }
  return true;
}

// The fields a table and a polynomial share; its data goes at the end of the storage.
VaryingError item(const VaryingErrors& v, int param, int column, int axis, VaryingKind kind, Outside outside,
                  int count, double lower, double upper) {
  VaryingError e;
  e.param = param;
  e.column = column;
  e.axis = axis;
  e.kind = kind;
  e.outside = outside;
  e.count = count;
  e.offset = static_cast<int>(v.storage.size());
  e.lower = lower;
  e.upper = upper;
  return e;
}

std::string number(double v) {
  char buf[32];
  std::snprintf(buf, sizeof buf, "%.10g", v);
  return buf;
}

}  // namespace

void monotone_cubic_slopes(const double* x, const double* y, int n, double* d) noexcept {
  if (n < 2) return;
  if (n == 2) {
    d[0] = d[1] = (y[1] - y[0]) / (x[1] - x[0]);
    return;
  }
  auto h = [&](int k) { return x[k + 1] - x[k]; };
  auto delta = [&](int k) { return (y[k + 1] - y[k]) / (x[k + 1] - x[k]); };
  for (int k = 1; k < n - 1; ++k) {
    const double m0 = delta(k - 1), m1 = delta(k);
    if (sign(m0) != sign(m1) || m0 == 0 || m1 == 0) {
      d[k] = 0;  // a local extremum or a flat piece: no overshoot
    } else {
      const double w1 = 2 * h(k) + h(k - 1), w2 = h(k) + 2 * h(k - 1);
      d[k] = (w1 + w2) / (w1 / m0 + w2 / m1);
    }
  }
  // one-sided three-point estimate, kept from overshooting
  auto edge = [](double h0, double h1, double m0, double m1) {
    double e = ((2 * h0 + h1) * m0 - h0 * m1) / (h0 + h1);
    if (sign(e) != sign(m0)) {
      e = 0;
    } else if (sign(m0) != sign(m1) && std::abs(e) > 3 * std::abs(m0)) {
      e = 3 * m0;
    }
    return e;
  };
  d[0] = edge(h(0), h(1), delta(0), delta(1));
  d[n - 1] = edge(h(n - 2), h(n - 3), delta(n - 2), delta(n - 3));
}

bool add_table(VaryingErrors& v, int param, int column, int axis, const double* x, const double* y, int n,
               Interpolation interpolation, Outside outside, std::string& why, int& at) {
  at = -1;
  if (!room(v, why)) return false;
  if (n < 2) {
    why = "a table needs at least 2 points, got " + std::to_string(n);
    return false;
  }
  if (n > kMaxTableKnots) {
    why = "a table holds at most " + std::to_string(kMaxTableKnots) + " points, got " + std::to_string(n);
    return false;
  }
  for (int i = 0; i < n; ++i) {
    if (!std::isfinite(x[i]) || !std::isfinite(y[i])) {
      at = i;
      why = "expected finite numbers";
      return false;
    }
    if (i > 0 && !(x[i] > x[i - 1])) {
      at = i;
      why = x[i] == x[i - 1] ? "duplicate position " + number(x[i])
                             : "positions must increase: " + number(x[i]) + " follows " + number(x[i - 1]);
      return false;
    }
  }
  VaryingError e = item(v, param, column, axis, VaryingKind::kTable, outside, n, x[0], x[n - 1]);
  e.interpolation = interpolation;
  // Equally spaced knots (to rounding) are located by one division instead of a search.
  const double step = (x[n - 1] - x[0]) / (n - 1);
  bool equal = true;
  for (int i = 1; i < n && equal; ++i) equal = std::abs(x[i] - (x[0] + i * step)) <= 1e-9 * step;
  e.inv_step = equal ? 1.0 / step : 0.0;
  std::vector<double> d(n, 0.0);
  if (interpolation == Interpolation::kMonotoneCubic) {
    monotone_cubic_slopes(x, y, n, d.data());
  } else {
    for (int k = 0; k < n - 1; ++k) d[k] = (y[k + 1] - y[k]) / (x[k + 1] - x[k]);  // the interval's slope
    d[n - 1] = d[n - 2];
  }
  v.storage.resize(v.storage.size() + kTableRecord * n, 0.0);
  double* r = v.storage.data() + e.offset;
  for (int k = 0; k < n; ++k, r += kTableRecord) {
    r[0] = x[k];
    r[1] = y[k];
    r[2] = d[k];
    if (k < n - 1 && interpolation == Interpolation::kMonotoneCubic) {
      // the Hermite cubic of the interval in powers of s = t - x[k]
      const double h = x[k + 1] - x[k], delta = (y[k + 1] - y[k]) / h;
      r[3] = (3 * delta - 2 * d[k] - d[k + 1]) / h;
      r[4] = (d[k] + d[k + 1] - 2 * delta) / (h * h);
    }
  }
  v.items[v.count++] = e;
  return true;
}

bool add_polynomial(VaryingErrors& v, int param, int column, int axis, const double* c, int n, double scale_in,
                    double scale_out, double lower, double upper, Outside outside, std::string& why, int& at) {
  at = -1;
  if (!room(v, why)) return false;
  if (n < 1 || n > kMaxPolynomialCoefficients) {
    why = "a polynomial has 1 to " + std::to_string(kMaxPolynomialCoefficients) + " coefficients, got " +
          std::to_string(n);
    return false;
  }
  for (int i = 0; i < n; ++i) {
    if (!std::isfinite(c[i])) {
      at = i;
      why = "expected finite numbers";
      return false;
    }
  }
  if (std::isnan(lower) || std::isnan(upper) || !(lower < upper)) {
    why = "the range needs low < high";
    return false;
  }
  VaryingError e = item(v, param, column, axis, VaryingKind::kPolynomial, outside, n, lower, upper);
  e.scale_in = scale_in;
  e.scale_out = scale_out;
  v.storage.insert(v.storage.end(), c, c + n);
  v.items[v.count++] = e;
  return true;
}

}  // namespace chaincomp
