"""Errors that vary along an axis: a table over one axis (linear or monotone-cubic
interpolation, held or rejected outside) or a polynomial in one axis, given in a params file
in place of a constant, and evaluated at the axes of each pose.

The same format, limits and messages as the C++ loader (runtime/src/params_io.cpp) and the
same interpolants as the runtime (runtime/include/chaincomp/varying.hpp)::

    values:
      EXX:                       # a table over X
        axis: X
        units: [mm, um]          # position unit (the axis' kind), value unit (the error's kind)
        interpolation: monotone_cubic   # or linear
        outside: hold            # or reject
        table:
          - [-400, 0.0]
          - [-392, 0.31]
      EBX:                       # a polynomial in X: c0 + c1*X + c2*X^2 (X in mm, value in arcsec)
        axis: X
        units: [mm, arcsec]
        polynomial: [0.5, 2.0e-3, -1.5e-6]
        range: [-400, 400]       # optional, with outside: hold or reject
        outside: hold
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from ..errors import ChaincompError
from . import units as U
from .yamlsource import describe, line_of

MAX_TABLE_KNOTS = 4096            # runtime: kMaxTableKnots
MAX_POLYNOMIAL_COEFFICIENTS = 16  # runtime: kMaxPolynomialCoefficients
MAX_VARYING_ERRORS = 64           # runtime: kMaxVaryingErrors
INTERPOLATIONS = ("linear", "monotone_cubic")
OUTSIDE = ("hold", "reject")
TABLE_KEYS = ("axis", "interpolation", "outside", "table", "units")
POLYNOMIAL_KEYS = ("axis", "outside", "polynomial", "range", "units")


def _a(kind: str) -> str:
    return {"length": "a length", "angle": "an angle", "ratio": "a ratio"}[kind]


# ----------------------------------------------------------------------------- interpolants

def monotone_cubic_slopes(x: np.ndarray, y: np.ndarray) -> np.ndarray:
    """Fritsch-Carlson (PCHIP) slopes at the knots: interior slopes by the weighted harmonic
    mean of Fritsch & Butland (zero at a local extremum or next to a flat piece), end slopes
    by the shape-preserving three-point formula; two knots: the line's slope."""
    x = np.asarray(x, float)
    y = np.asarray(y, float)
    n = len(x)
    h = np.diff(x)
    m = np.diff(y) / h
    if n == 2:
        return np.array([m[0], m[0]])
    d = np.zeros(n)
    for k in range(1, n - 1):
        if np.sign(m[k - 1]) != np.sign(m[k]) or m[k - 1] == 0 or m[k] == 0:
            d[k] = 0.0
        else:
            w1, w2 = 2 * h[k] + h[k - 1], h[k] + 2 * h[k - 1]
            d[k] = (w1 + w2) / (w1 / m[k - 1] + w2 / m[k])

    def edge(h0, h1, m0, m1):
        e = ((2 * h0 + h1) * m0 - h0 * m1) / (h0 + h1)
        if np.sign(e) != np.sign(m0):
            e = 0.0
        elif np.sign(m0) != np.sign(m1) and abs(e) > 3 * abs(m0):
            e = 3 * m0
        return e

    d[0] = edge(h[0], h[1], m[0], m[1])
    d[-1] = edge(h[-1], h[-2], m[-1], m[-2])
    return d


def _is_mp(t) -> bool:
    return type(t).__module__.startswith("mpmath")


@dataclass(frozen=True, eq=False)
class Varying:
    """An error that varies along one axis; values in internal units (mm, rad, 1)."""

    error: str
    axis: str
    units: tuple[U.Unit, U.Unit]   # position unit, value unit (as declared)
    outside: str                   # "hold" | "reject"
    lower: float                   # range, internal units (infinite: valid everywhere)
    upper: float
    file: str = ""
    line: int = 0
    axis_unit: U.Unit | None = None  # the axis' declared unit, when parsed against a machine

    @property
    def key(self) -> str:
        return f"values.{self.error}"

    def __call__(self, t):
        """Value at axis position(s) t (internal units; numpy arrays and mpmath scalars).
        Outside the range: held at the nearest end, or NaN where ``outside`` is reject."""
        return self._value_slope(t)[0]

    def slope(self, t):
        """d value / d axis at t (internal units); 0 outside the range."""
        return self._value_slope(t)[1]

    def inside(self, t):
        t = np.asarray(t, float)
        return (t >= self.lower) & (t <= self.upper)

    def check_inside(self, t: float) -> None:
        """ChaincompError naming the file, line and key when t lies outside a rejecting range."""
        if self.outside == "reject" and not bool(self.inside(float(t))):
            pu = self.axis_unit or self.units[0]
            raise ChaincompError(
                f"{self.axis} = {float(t) / pu.to_internal:g} {pu.name} lies outside the "
                f"{'table' if isinstance(self, Table) else 'range'} [{self.lower / pu.to_internal:g}, "
                f"{self.upper / pu.to_internal:g}] {pu.name} of {self.error} (outside: reject)",
                self.file, self.line, self.key)

    def describe(self) -> str:
        raise NotImplementedError

    def _value_slope(self, t):
        raise NotImplementedError


@dataclass(frozen=True, eq=False)
class Table(Varying):
    interpolation: str = "linear"
    x: np.ndarray = field(default=None, repr=False)   # positions, internal units
    y: np.ndarray = field(default=None, repr=False)   # values, internal units
    d: np.ndarray = field(default=None, repr=False)   # slopes at the knots
    # per interval k, the cubic y[k] + u (b + u (c + u e)) in u = t - x[k] (linear: c = e = 0),
    # as the runtime evaluates it
    b: np.ndarray = field(default=None, repr=False)
    c: np.ndarray = field(default=None, repr=False)
    e: np.ndarray = field(default=None, repr=False)

    def describe(self) -> str:
        pu = self.units[0]
        return (f"table over {self.axis}, {len(self.x)} points in [{self.x[0] / pu.to_internal:g}, "
                f"{self.x[-1] / pu.to_internal:g}] {pu.name}, {self.interpolation.replace('_', ' ')}, "
                f"outside: {self.outside}")

    def _value_slope(self, t):
        if _is_mp(t):
            return self._scalar(t)
        arr = np.asarray(t, dtype=float)
        x, y, n = self.x, self.y, len(self.x)
        k = np.clip(np.searchsorted(x, arr, side="right") - 1, 0, n - 2)
        u = arr - x[k]
        b, c, e = self.b[k], self.c[k], self.e[k]
        v = y[k] + u * (b + u * (c + u * e))
        s = b + u * (2 * c + 3 * u * e)
        first = arr <= x[0]
        last = arr >= x[-1]
        v = np.where(first, y[0], np.where(last, y[-1], v))
        s = np.where(arr == x[0], self.d[0], np.where(arr == x[-1], self.d[-1], np.where(first | last, 0.0, s)))
        if self.outside == "reject":
            out = ~((arr >= x[0]) & (arr <= x[-1]))
            v = np.where(out, np.nan, v)
            s = np.where(out, np.nan, s)
        if v.ndim == 0:
            return float(v), float(s)
        return v, s

    def _scalar(self, t):
        """mpmath: the interval found in floats, the cubic in t's precision."""
        import mpmath
        x, y, n = self.x, self.y, len(self.x)
        tf = float(t)
        if self.outside == "reject" and not x[0] <= tf <= x[-1]:
            return mpmath.mpf("nan"), mpmath.mpf("nan")
        if tf <= x[0] or tf >= x[-1]:
            i = 0 if tf <= x[0] else n - 1
            return mpmath.mpf(float(y[i])), mpmath.mpf(float(self.d[i]) if tf == x[i] else 0)
        k = int(min(max(np.searchsorted(x, tf, side="right") - 1, 0), n - 2))
        u = t - mpmath.mpf(float(x[k]))
        b, c, e = (mpmath.mpf(float(a[k])) for a in (self.b, self.c, self.e))
        return mpmath.mpf(float(y[k])) + u * (b + u * (c + u * e)), b + u * (2 * c + 3 * u * e)


def cubic_coefficients(x: np.ndarray, y: np.ndarray, d: np.ndarray, interpolation: str):
    """Per interval, b, c, e of y[k] + u (b + u (c + u e)), u = t - x[k]: the Hermite cubic with
    the knots' slopes d (monotone cubic), or the secant (linear; c = e = 0)."""
    h = np.diff(x)
    delta = np.diff(y) / h
    if interpolation == "linear":
        return delta, np.zeros_like(delta), np.zeros_like(delta)
    return d[:-1].copy(), (3 * delta - 2 * d[:-1] - d[1:]) / h, (d[:-1] + d[1:] - 2 * delta) / (h * h)


@dataclass(frozen=True, eq=False)
class Polynomial(Varying):
    coefficients: tuple[float, ...] = ()   # declared units: value_unit / position_unit^k

    def describe(self) -> str:
        pu = self.units[0]
        deg = len(self.coefficients) - 1
        rng = ("" if math.isinf(self.lower) else
               f" over [{self.lower / pu.to_internal:g}, {self.upper / pu.to_internal:g}] {pu.name}, "
               f"outside: {self.outside}")
        return f"polynomial of degree {deg} in {self.axis}{rng}"

    def _value_slope(self, t):
        pu, vu = self.units
        c = self.coefficients
        if _is_mp(t):
            import mpmath
            tf = float(t)
            if self.outside == "reject" and not self.lower <= tf <= self.upper:
                return mpmath.mpf("nan"), mpmath.mpf("nan")
            inside = self.lower <= tf <= self.upper
            tc = t if inside else mpmath.mpf(min(max(tf, self.lower), self.upper))
            u = tc / mpmath.mpf(pu.to_internal)
        else:
            arr = np.asarray(t, dtype=float)
            inside = (arr >= self.lower) & (arr <= self.upper)
            u = np.clip(arr, self.lower, self.upper) / pu.to_internal
        p = c[-1] + 0 * u
        dp = 0 * u
        for ck in reversed(c[:-1]):
            dp = dp * u + p
            p = p * u + ck
        value = p * vu.to_internal
        slope = dp * vu.to_internal / pu.to_internal
        if _is_mp(t):
            return value, slope if inside else slope * 0
        slope = np.where(inside, slope, 0.0)
        if self.outside == "reject":
            value = np.where(inside, value, np.nan)
            slope = np.where(inside, slope, np.nan)
        if np.ndim(value) == 0:
            return float(value), float(slope)
        return value, slope


# ----------------------------------------------------------------------------- evaluation

def resolve(values: dict) -> dict:
    """``values`` with each varying error replaced by its value at the axis values given there."""
    varying = [(k, v) for k, v in values.items() if isinstance(v, Varying)]
    if not varying:
        return values
    out = dict(values)
    for k, v in varying:
        out[k] = v(values[v.axis])
    return out


def check_inside(values: dict) -> None:
    """A ChaincompError (file, line, key) for an axis outside a range that rejects."""
    for v in values.values():
        if isinstance(v, Varying) and np.ndim(values[v.axis]) == 0:
            v.check_inside(values[v.axis])


def varying_errors(values: dict) -> dict[str, Varying]:
    return {k: v for k, v in values.items() if isinstance(v, Varying)}


# ----------------------------------------------------------------------------- parsing

def _number(value, fail) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        fail(f"expected a number, got {describe(value)}")
    try:
        number = float(value)
    except OverflowError:  # an int beyond any float
        number = math.inf if value > 0 else -math.inf
    if not math.isfinite(number):
        fail(f"expected finite numbers, got {value!r}")
    return number


def parse_varying(node, name: str, path: str, line: int, machine=None) -> Varying:
    """One error given as a table or polynomial (a mapping in a params file's ``values``).

    With ``machine`` the axis, the error and the units' kinds are checked against it;
    without, only what the entry itself states (for ``chaincomp plot --table``)."""
    base = f"values.{name}"

    def fail(msg, at_line=None, key=None):
        raise ChaincompError(msg, path, at_line or line, key or base)

    if machine is not None:
        sym = machine.symbol(name)
        if sym.role != "error":
            fail(f"only error symbols may vary along an axis; {name!r} is a {sym.role}")
    is_table, is_poly = "table" in node, "polynomial" in node
    if is_table == is_poly:
        fail("give either 'table' or 'polynomial', not both" if is_table
             else "expected a number, or a mapping with 'table' or 'polynomial'")
    allowed = TABLE_KEYS if is_table else POLYNOMIAL_KEYS
    for key in node:
        if key not in allowed:
            fail(f"unknown field {key!r} (expected one of: {', '.join(allowed)})", line_of(node, key, line),
                 f"{base}.{key}")
    kline = lambda k: line_of(node, k, line)  # noqa: E731

    if "axis" not in node:
        fail("missing required field 'axis'")
    axis = node["axis"]
    axis_sym = None
    if machine is not None:
        names = [a.name for a in machine.axes]
        if not isinstance(axis, str) or axis not in names:
            shown = repr(axis) if isinstance(axis, str) else describe(axis)
            fail(f"{shown} is not an axis of {machine.name} (axes: {', '.join(names)})", kline("axis"),
                 f"{base}.axis")
        axis_sym = machine.symbol(axis)
    elif not isinstance(axis, str):
        fail(f"expected an axis name, got {describe(axis)}", kline("axis"), f"{base}.axis")

    if "units" not in node:
        fail("missing required field 'units' ([position unit, value unit], e.g. [mm, um])")
    raw_units = node["units"]
    if not isinstance(raw_units, list) or len(raw_units) != 2 or not all(isinstance(u, str) for u in raw_units):
        fail(f"expected [position unit, value unit], e.g. [mm, um], got {describe(raw_units)}", kline("units"),
             f"{base}.units")
    try:
        pu, vu = U.unit(raw_units[0]), U.unit(raw_units[1])
    except KeyError as exc:
        fail(exc.args[0], kline("units"), f"{base}.units")
    if axis_sym is not None and pu.kind != axis_sym.unit.kind:
        fail(f"position unit {pu.name!r} is {_a(pu.kind)} unit, but axis {axis} is {_a(axis_sym.unit.kind)} "
             f"(declared in {axis_sym.unit.name!r})", kline("units"), f"{base}.units")
    if machine is not None:
        sym = machine.symbol(name)
        if vu.kind != sym.unit.kind:
            fail(f"value unit {vu.name!r} is {_a(vu.kind)} unit, but {name} is {_a(sym.unit.kind)} "
                 f"(declared in {sym.unit.name!r})", kline("units"), f"{base}.units")

    has_range = is_poly and "range" in node
    outside = "hold"
    if is_table or has_range:
        if "outside" not in node:
            fail("missing required field 'outside' (hold or reject)")
        outside = node["outside"]
        if outside not in OUTSIDE:
            fail(f"outside must be hold or reject, got {describe(outside)}", kline("outside"), f"{base}.outside")
    elif "outside" in node:
        fail("'outside' applies to a polynomial's 'range' (give range: [low, high] in the position unit)",
             kline("outside"), f"{base}.outside")

    common = dict(error=name, axis=axis, units=(pu, vu), outside=outside, file=path, line=line,
                  axis_unit=axis_sym.unit if axis_sym is not None else None)
    if is_table:
        if "interpolation" not in node:
            fail("missing required field 'interpolation' (linear or monotone_cubic)")
        interp = node["interpolation"]
        if interp not in INTERPOLATIONS:
            fail(f"interpolation must be linear or monotone_cubic, got {describe(interp)}", kline("interpolation"),
                 f"{base}.interpolation")
        rows = node["table"]
        if not isinstance(rows, list):
            fail(f"expected a list of [position, value] rows, got {describe(rows)}", kline("table"), f"{base}.table")
        n = len(rows)
        if n < 2:
            fail(f"a table needs at least 2 points, got {n}", kline("table"), f"{base}.table")
        if n > MAX_TABLE_KNOTS:
            fail(f"a table holds at most {MAX_TABLE_KNOTS} points, got {n}", kline("table"), f"{base}.table")
        xs, ys = [], []
        for i, row in enumerate(rows):
            rline = line_of(rows, i, kline("table"))
            rkey = f"{base}.table[{i}]"
            rfail = lambda msg, rline=rline, rkey=rkey: fail(msg, rline, rkey)  # noqa: E731
            if not isinstance(row, list) or len(row) != 2:
                rfail(f"expected [position, value], got {describe(row)}")
            p, v = _number(row[0], rfail), _number(row[1], rfail)
            if xs and p == xs[-1]:
                rfail(f"duplicate position {row[0]!r}")
            if xs and p < xs[-1]:
                rfail(f"positions must increase: {row[0]!r} follows {rows[i - 1][0]!r}")
            if not (math.isfinite(p * pu.to_internal) and math.isfinite(v * vu.to_internal)):
                rfail("not finite in internal units (mm, rad)")
            xs.append(p)
            ys.append(v)
        x = np.array(xs) * pu.to_internal
        y = np.array(ys) * vu.to_internal
        if interp == "monotone_cubic":
            d = monotone_cubic_slopes(x, y)
        else:  # one-sided at the ends, as the runtime
            secant = np.diff(y) / np.diff(x)
            d = np.concatenate([secant, secant[-1:]])
        b, c, e = cubic_coefficients(x, y, d, interp)
        for a in (x, y, d, b, c, e):
            a.setflags(write=False)
        return Table(**common, lower=float(x[0]), upper=float(x[-1]), interpolation=interp, x=x, y=y, d=d,
                     b=b, c=c, e=e)

    coeffs = node["polynomial"]
    if not isinstance(coeffs, list) or not 1 <= len(coeffs) <= MAX_POLYNOMIAL_COEFFICIENTS:
        fail(f"expected a list of 1 to {MAX_POLYNOMIAL_COEFFICIENTS} coefficients [c0, c1, ...] "
             f"(c0 + c1*x + ...), got {describe(coeffs)}", kline("polynomial"), f"{base}.polynomial")
    c = tuple(_number(v, lambda msg, i=i: fail(msg, line_of(coeffs, i, kline("polynomial")),
                                                     f"{base}.polynomial[{i}]"))
              for i, v in enumerate(coeffs))
    lower, upper = -math.inf, math.inf
    if has_range:
        r = node["range"]
        rfail = lambda msg: fail(msg, kline("range"), f"{base}.range")  # noqa: E731
        if not isinstance(r, list) or len(r) != 2:
            rfail(f"expected [low, high] in the position unit, got {describe(r)}")
        lo, hi = _number(r[0], rfail), _number(r[1], rfail)
        if not lo < hi:
            rfail(f"low {r[0]!r} must be below high {r[1]!r}")
        lower, upper = lo * pu.to_internal, hi * pu.to_internal
    return Polynomial(**common, lower=lower, upper=upper, coefficients=c)
