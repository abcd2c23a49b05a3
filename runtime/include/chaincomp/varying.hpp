// Errors that vary along an axis: a table over one axis (linear or monotone cubic
// interpolation) or a polynomial in one axis, evaluated with its slope at the axes of each
// call. Filled once at start-up (params_io.cpp, or add_table / add_polynomial below) and
// read-only afterwards; evaluation is noexcept and allocates nothing. No Eigen, no I/O.
#pragma once

#include <cmath>
#include <string>
#include <vector>

#include "chaincomp/trig.hpp"  // sin_small, cos_small: the generated set_errors

namespace chaincomp {

// Capacities, checked when a table or polynomial is added (and by the Python loader).
constexpr int kMaxVaryingErrors = 64;          // varying errors per model
constexpr int kMaxTableKnots = 4096;           // knots per table
constexpr int kMaxPolynomialCoefficients = 16; // degree 15
constexpr int kTableRecord = 5;                // doubles per knot in storage

enum class VaryingKind : int { kTable = 0, kPolynomial = 1 };
enum class Interpolation : int { kLinear = 0, kMonotoneCubic = 1 };
enum class Outside : int { kHold = 0, kReject = 1 };

struct VaryingError {
  int param = -1;   // index in MachineInfo::params
  int column = -1;  // index among the error parameters: the column of the error gain matrix
  int axis = -1;    // index in MachineInfo::axes
  VaryingKind kind = VaryingKind::kTable;
  Interpolation interpolation = Interpolation::kLinear;
  Outside outside = Outside::kHold;
  int count = 0;   // knots, or coefficients
  // into VaryingErrors::storage. Table: one record of kTableRecord doubles per knot k,
  // {x, y, b, c, e}: on [x[k], x[k+1]) the value is y + s (b + s (c + s e)) with s = t - x[k]
  // (linear: c = e = 0); b of the last knot is the slope there. One interval, one or two
  // cache lines. Polynomial: c[count].
  int offset = 0;
  double lower = -INFINITY, upper = INFINITY;  // range, internal units (mm, rad)
  double inv_step = 0;  // equally spaced knots: 1 / spacing (direct lookup); 0: binary search
  double scale_in = 1, scale_out = 1;  // polynomial: value = scale_out * sum c_k (scale_in * x)^k
};

// Every varying error of one model. `storage` is sized while loading and never resized
// afterwards; items refer to it by offset, so a copy stays valid.
struct VaryingErrors {
  int count = 0;
  VaryingError items[kMaxVaryingErrors];
  std::vector<double> storage;
};

// --- start-up (src/varying.cpp): false with `why` (and the offending knot or coefficient in
// `at`, else -1) for a bad table; nothing is added then.
// x: positions, y: values, both internal units; at least 2 knots, strictly increasing.
bool add_table(VaryingErrors& v, int param, int column, int axis, const double* x, const double* y, int count,
               Interpolation interpolation, Outside outside, std::string& why, int& at);
// value(x) = sum c[k] * (x * scale_in)^k * scale_out; outside [lower, upper] per `outside`
// (an infinite range: valid everywhere).
bool add_polynomial(VaryingErrors& v, int param, int column, int axis, const double* c, int count, double scale_in,
                    double scale_out, double lower, double upper, Outside outside, std::string& why, int& at);
// Monotone cubic (Fritsch-Carlson, PCHIP) slopes at the knots: interior slopes by the
// weighted harmonic mean of Fritsch & Butland, zero at a local extremum; end slopes by the
// shape-preserving three-point formula. Two knots: the line's slope.
void monotone_cubic_slopes(const double* x, const double* y, int count, double* d) noexcept;

// --- evaluation

// The interval k (x[k] <= t < x[k+1]) of a table (records r) for t inside (x[0], x[count-1]).
inline int locate(const VaryingError& e, const double* r, double t) noexcept {
  constexpr int R = kTableRecord;
  const int last = e.count - 2;
  if (e.inv_step > 0) {
    int k = static_cast<int>((t - r[0]) * e.inv_step);
    k = k < 0 ? 0 : k > last ? last : k;
    // the spacing is equal only to rounding: step once if the product landed next door
    if (t < r[R * k] && k > 0) --k;
    else if (t >= r[R * (k + 1)] && k < last) ++k;
    return k;
  }
  int lo = 0, hi = last;
  while (lo < hi) {
    const int mid = (lo + hi + 1) / 2;
    if (r[R * mid] <= t) lo = mid; else hi = mid - 1;
  }
  return lo;
}

// The error's value and slope (d value / d axis, internal units) at axis position t. Outside
// its range it is held at the nearest end with slope 0, and the result is false where
// `outside` is reject. `hint` (may be null; -1: none) keeps the last interval of a table:
// the Newton iterates, microns from the command, find it there. Without kSlope the slope is
// left alone (the iterates need only the value).
template <bool kSlope = true>
inline bool evaluate(const VaryingErrors& v, const VaryingError& e, double t, int* hint, double& value,
                     double& slope) noexcept {
  const double* s = v.storage.data() + e.offset;
  if (e.kind == VaryingKind::kTable) {
    constexpr int R = kTableRecord;
    const int h = hint ? *hint : -1;
    const double* r = s + R * h;
    if (!(h >= 0 && r[0] <= t && t < r[R])) {
      const double* last = s + R * (e.count - 1);
      if (!(t > s[0] && t < last[0])) {  // at or past an end (NaN: the first)
        const double* end = t > s[0] ? last : s;
        value = end[1];
        if (kSlope) slope = t == end[0] ? end[2] : 0.0;
        return t == end[0] || e.outside == Outside::kHold;
      }
      const int k = locate(e, s, t);
      if (hint) *hint = k;
      r = s + R * k;
    }
    // the interval's cubic in u = t - x[k] (linear: y + u b, np.interp's slope * (t - x[k]) +
    // y[k] to the bit); exact at the knot x[k]
    const double u = t - r[0];
    value = r[1] + u * (r[2] + u * (r[3] + u * r[4]));
    if (kSlope) slope = r[2] + u * (2 * r[3] + 3 * u * r[4]);
    return true;
  }
  const bool inside = t >= e.lower && t <= e.upper;
  const double u = (t < e.lower ? e.lower : t > e.upper ? e.upper : t) * e.scale_in;
  double p = s[e.count - 1], dp = 0;
  for (int k = e.count - 2; k >= 0; --k) {
    dp = dp * u + p;
    p = p * u + s[k];
  }
  value = e.scale_out * p;
  if (kSlope) slope = inside ? e.scale_out * e.scale_in * dp : 0.0;
  return inside || e.outside == Outside::kHold;
}

// true when every varying error whose `outside` is reject holds the axes `q` within range.
inline bool within_ranges(const VaryingErrors& v, const double* q) noexcept {
  for (int i = 0; i < v.count; ++i) {
    const VaryingError& e = v.items[i];
    if (e.outside == Outside::kReject && !(q[e.axis] >= e.lower && q[e.axis] <= e.upper)) return false;
  }
  return true;
}

}  // namespace chaincomp
