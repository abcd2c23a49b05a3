"""The error budget of a machine over its working volume (ME220 "Error Budgets").

For every tool error component (dx, dy, dz, and dkx, dky, dkz where the machine has a tool
direction) and every point of a grid over the machine's axes:

- systematic: the error with every error at its --params value (the notes' §8
  "deterministic" reading: the part is off by this, everywhere the same way);
- worst:  sum_i |g_i| b_i, every error at its bound with the signs aligned;
- rss:    sqrt(sum_i (g_i q_i)^2), each error at the half-width q_i that holds it with the
  coverage probability p of the tolerance file's normal bound (3 sigma: p = 99.73 %);
  a normal error bounded at k sigma gives q = b, a uniform one q = p b;
- sigma:  sqrt(sum_i (g_i sigma_i)^2), the standard deviation (uniform: b/sqrt 3, normal: b/k);

where g_i is the gain of error i (the first-order gain matrix; at order 2 the gradient of
the second-order model at the centre, plus a bound of its quadratic terms over the
tolerance box; for the exact model the secant of the exact model across +-b_i). At the
grid point where the worst case is largest, the contributors are ranked by |g_i| b_i, and
a Monte Carlo run of the exact model (seeded) gives the mean, the standard deviation and
the p-quantile of |deviation| that rss and worst should bracket.

Everything runs vectorised: the gains are lambdified once per component and evaluated on
an open mesh of the grid axes, so trig of an axis is computed once per grid value. On a long
chain, whose expanded series would take minutes, the numeric jets carry the same
coefficients through the chain instead (chaincomp.jets), on the same open mesh.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
import sympy as sp

from ..errors import ChaincompError
from ..escape import one_line
from ..model.display import display_unit
from ..model.machine import Machine, Symbol
from ..model.units import UNITS
from ..model.varying import Table, varying_errors
from ..symbolic.derive import EXPANDED_TERMS_LIMIT, Derivation, derive
from ..symbolic.jets import JetModel
from ..symbolic.numeric import ExactModel, TruncatedModel
from ..symbolic.orientation import ROWS as ORIENTATION_ROWS, rotation_vector
from .tolerances import Tolerance, Tolerances

POSITION = ("dx", "dy", "dz")
DIRECTION = ("dkx", "dky", "dkz")
ORIENTATION = ORIENTATION_ROWS  # a tool frame's rotation vector ω (rad, chaincomp.orientation)
ANGULAR = DIRECTION + ORIENTATION
ORDERS = ("1", "2", "exact")
MAX_POINTS = 2_000_000
# The exact model holds every error's gain at every point: 1.9 M points x 29 errors took 2 GB
# (five_axis_ac, 2026-12); 30 M point-errors keep it near 1 GB.
MAX_POINT_ERRORS = 30_000_000
MC_CHUNK = 65536
EXACT_STEP = 1e-6   # FD step (mm or rad) for an error without a tolerance, exact model


# ----------------------------------------------------------------------------- grid

@dataclass
class Grid:
    """A full grid over some axes (declared units); the other axes held fixed."""

    axes: tuple[Symbol, ...]
    points: tuple[np.ndarray, ...]
    fixed: dict[str, float]            # other axes, declared units

    @property
    def shape(self) -> tuple[int, ...]:
        return tuple(len(p) for p in self.points)

    @property
    def size(self) -> int:
        return int(np.prod(self.shape)) if self.points else 1

    def open_mesh(self) -> dict[str, np.ndarray]:
        """Internal values of the grid axes, each shaped to broadcast along its own dimension."""
        out = {}
        n = len(self.axes)
        for k, (a, p) in enumerate(zip(self.axes, self.points)):
            shape = [1] * n
            shape[k] = len(p)
            out[a.name] = a.to_internal(p).reshape(shape)
        return out

    def at(self, index: tuple[int, ...]) -> dict[str, float]:
        """Every axis (declared unit) at a grid index."""
        out = {a.name: float(p[i]) for a, p, i in zip(self.axes, self.points, index)}
        out.update(self.fixed)
        return out


def make_grid(machine: Machine, over: list[str] | None, points: int, fixed_values: dict) -> Grid:
    """The grid of the axes ``over`` (default all), ``points`` values each across their limits;
    the other axes at ``fixed_values`` (internal units) or their default position."""
    names = [a.name for a in machine.axes]
    over = list(over) if over else names
    bad = [n for n in over if n not in names]
    if bad or len(set(over)) != len(over) or not over:
        raise ChaincompError(f"--over expects different axes of {machine.name} ({', '.join(names)}), "
                             f"got {','.join(over)!r}")
    if points < 2:
        raise ChaincompError(f"--grid must be at least 2 points per axis, got {points}")
    total = points ** len(over)
    n_errors = max(len(machine.errors), 1)
    if total > MAX_POINTS or total * n_errors > MAX_POINT_ERRORS:
        raise ChaincompError(f"the grid would hold {points}^{len(over)} = {total} points x {n_errors} errors (limits "
                             f"{MAX_POINTS} points, {MAX_POINT_ERRORS} point-errors): lower --grid or vary fewer "
                             f"axes with --over")
    axes = tuple(machine.symbol(n) for n in over)
    pts = tuple(np.linspace(a.limits[0], a.limits[1], points) for a in axes)
    fixed = {a.name: a.from_internal(fixed_values[a.name]) for a in machine.axes if a.name not in over}
    return Grid(axes, pts, fixed)


# ----------------------------------------------------------------------------- gains

def components(machine: Machine) -> tuple[str, ...]:
    return POSITION + (DIRECTION if machine.tool_direction else ()) + (ORIENTATION if machine.tool_reference else ())


def _exact_parts(model: ExactModel, values: dict, ref) -> list:
    """The components of the exact pose at ``values``; with a frame ω against the frame
    ``ref`` ((z, x) axes: the reference pose of the caller)."""
    p, d, x = model.frame(values)
    out = list(p) + (list(d) if d is not None else [])
    if x is not None:
        out += rotation_vector((d, x), ref)
    return out


def _exact_frame(model: ExactModel, values: dict):
    _, d, x = model.frame(values)
    return (d, x) if x is not None else None


class _Series:
    """Order-1 or order-2 gains from the derivation, lambdified once per component."""

    def __init__(self, machine: Machine, order: int, d: Derivation):
        self.machine, self.order = machine, order
        self.d = d
        self.syms = [s.sym for s in machine.symbols]
        self.n = len(machine.errors)
        vecs = (list(self.d.point) + (list(self.d.direction) if self.d.direction else [])
                + (list(self.d.orientation) if self.d.orientation else []))
        self.series = dict(zip(components(machine), vecs))
        self._fns: dict = {}
        self._truncated: TruncatedModel | None = None

    def _fn(self, comp: str):
        if comp not in self._fns:
            s = self.series[comp]
            lin = [self.d.expr(s.get((i,), 0)) for i in range(self.n)]
            quad = sorted(m for m in s if len(m) == 2) if self.order >= 2 else []
            exprs = lin + [self.d.expr(s[m]) for m in quad]
            self._fns[comp] = (sp.lambdify(self.syms, exprs, modules="numpy", cse=True), quad)
        return self._fns[comp]

    def _gains(self, comp: str, args: dict, centre: dict, bounds: np.ndarray):
        """(gains: list of arrays or scalars, second-order bound or 0) for one component."""
        f, quad = self._fn(comp)
        out = f(*[args[s.name] for s in self.machine.symbols])
        eps = [centre.get(s.name, 0.0) for s in self.machine.errors]
        return _second_order(list(out[:self.n]), zip(quad, out[self.n:]), eps, bounds)

    def gains(self, args: dict, centre: dict, bounds: np.ndarray):
        """Yields (component, gains, second-order bound), one component at a time."""
        for comp in components(self.machine):
            yield (comp, *self._gains(comp, args, centre, bounds))

    def systematic(self, args: dict) -> dict:
        if self._truncated is None:
            self._truncated = TruncatedModel(self.d)
        dp, dd = self._truncated.error(args, self.order, "numpy")
        w = self._truncated.orientation_error(args, self.order, "numpy")
        return dict(zip(components(self.machine), list(dp) + (list(dd) if dd is not None else []) + (w or [])))


def _second_order(g: list, quad, eps: list, bounds: np.ndarray):
    """(gains at the centre, bound of the quadratic terms over the tolerance box): the linear
    gains ``g`` plus the gradient of the quadratic terms ``quad`` ((i, j), coefficient) at the
    centre ``eps``, and sum |c_ij| b_i b_j."""
    qb = 0.0
    for (i, j), c in quad:
        if i == j:
            if eps[i]:
                g[i] = g[i] + 2.0 * c * eps[i]
        else:
            if eps[j]:
                g[i] = g[i] + c * eps[j]
            if eps[i]:
                g[j] = g[j] + c * eps[i]
        if bounds[i] and bounds[j]:
            qb = qb + np.abs(c) * bounds[i] * bounds[j]
    return g, qb


class _Jets:
    """The same gains for a long chain, whose expanded series would take minutes: the numeric
    jets (chaincomp.jets) through the chain on the open mesh, a slice of the first grid axis at
    a time (its jets hold every monomial at every point of the slice)."""

    def __init__(self, machine: Machine, order: int):
        self.machine, self.order = machine, order
        self.jets = JetModel(machine, order)
        self.n = len(machine.errors)

    def gains(self, args: dict, centre: dict, bounds: np.ndarray):
        comps = components(self.machine)
        eps = [centre.get(s.name, 0.0) for s in self.machine.errors]

        def block(values):
            p, d, w = self.jets.pose_jets(values)
            out = []
            for jet in p + (d or []) + (w or []):
                quad = sorted((m, v) for m, v in jet.items() if len(m) == 2)
                g, qb = _second_order([jet.get((i,), 0.0) for i in range(self.n)], quad, eps, bounds)
                out += g + [qb]
            return out

        cols = _by_slices(args, block)
        for k, c in enumerate(comps):
            yield c, cols[k * (self.n + 1):(k + 1) * (self.n + 1) - 1], cols[(k + 1) * (self.n + 1) - 1]

    def systematic(self, args: dict) -> dict:
        def block(values):
            dp, dd, w = self.jets.all_errors(values, self.order)
            return list(dp) + (list(dd) if dd is not None else []) + (w or [])

        return dict(zip(components(self.machine), _by_slices(args, block)))


def _by_slices(args: dict, f) -> list:
    """f(args) (a list of arrays on the open mesh), one slice of the first grid axis at a time,
    the slices joined again."""
    shape = np.broadcast_shapes(*[np.shape(v) for v in args.values()])
    if not shape:
        return f(args)
    parts = [f({k: (v[r:r + 1] if np.ndim(v) and np.shape(v)[0] > 1 else v) for k, v in args.items()})
             for r in range(shape[0])]
    sub = (1,) + shape[1:]
    return [np.concatenate([np.broadcast_to(x, sub) for x in col]) for col in zip(*parts)]


class _Exact:
    """Secant gains of the exact model across each tolerance, at the centre."""

    def __init__(self, machine: Machine):
        self.machine = machine
        self.model = ExactModel(machine)

    def gains(self, args: dict, centre: dict, bounds: np.ndarray):
        """Yields (component, gains, 0): every pose of the exact model is needed for each
        component, so all are computed first."""
        comps = components(self.machine)
        g: dict[str, list] = {c: [] for c in comps}
        ref = _exact_frame(self.model, {**args, **centre})
        for i, s in enumerate(self.machine.errors):
            h = bounds[i] if bounds[i] > 0 else EXACT_STEP
            poses = []
            for sign in (1.0, -1.0):
                v = dict(args)
                v[s.name] = centre.get(s.name, 0.0) + sign * h
                poses.append(_exact_parts(self.model, v, ref))
            for c, hi, lo in zip(comps, *poses):
                g[c].append((hi - lo) / (2.0 * h))
        for c in comps:
            yield c, g[c], 0.0

    def systematic(self, args: dict) -> dict:
        dp, dd = self.model.error(args)
        w = self.model.orientation_error(args)
        return dict(zip(components(self.machine), list(dp) + (list(dd) if dd is not None else []) + (w or [])))


def gain_model(machine: Machine, order: str):
    if order not in ORDERS:
        raise ChaincompError(f"--order must be 1, 2 or exact, got {order!r}")
    if order == "exact":
        return _Exact(machine)
    d = derive(machine, int(order), max_terms=EXPANDED_TERMS_LIMIT)
    return _Series(machine, int(order), d) if d else _Jets(machine, int(order))


# ----------------------------------------------------------------------------- the budget

@dataclass
class ComponentBudget:
    name: str
    scale: float                      # internal -> reported unit
    unit: str
    systematic: np.ndarray            # on the grid, internal units
    worst: np.ndarray
    rss: np.ndarray
    sigma: np.ndarray
    second_order_bound: np.ndarray     # on the grid (zeros unless order 2)
    max_gain: np.ndarray              # per error, max over the grid of |gain| (internal)
    worst_index: tuple[int, ...]
    gains_at_worst: np.ndarray        # per error (internal)
    monte_carlo: dict | None = None


@dataclass
class Budget:
    machine: Machine
    order: str
    tolerances: Tolerances
    grid: Grid
    values: dict[str, float]          # every symbol (internal): constants, fixed axes, --params errors
    centre: dict[str, float]          # error values the deviations are about (internal)
    params_errors: dict[str, float]   # error values of --params (internal)
    components: dict[str, ComponentBudget] = field(default_factory=dict)
    samples: int = 0
    seed: int = 0
    tables: dict[str, float] = field(default_factory=dict)   # error -> its largest |value| on the grid


# ----------------------------------------------------------------------------- tables

# Points per grid axis at which a table or polynomial is evaluated for its range, besides the
# grid's own values and a table's knots: the peak of a cubic between knots is then within
# (span/TABLE_SAMPLES)^2 of the true one.
TABLE_SAMPLES = 2001


def table_bounds(values: dict, grid: Grid) -> dict[str, float]:
    """For each error given as a table or polynomial (values[name] a Varying): its largest
    |value| where the grid takes its axis (the axis' span on the grid, or its fixed value),
    internal units. A budget states one bound per error; this is the one a table implies."""
    out = {}
    axes = {a.name: (a, p) for a, p in zip(grid.axes, grid.points)}
    for name, v in varying_errors(values).items():
        if v.axis in axes:
            a, p = axes[v.axis]
            lo, hi = a.to_internal(float(p[0])), a.to_internal(float(p[-1]))
            t = np.concatenate([a.to_internal(np.asarray(p, float)), np.linspace(lo, hi, TABLE_SAMPLES)])
            if isinstance(v, Table):
                t = np.concatenate([t, v.x[(v.x >= lo) & (v.x <= hi)]])
        else:
            lo = hi = float(values[v.axis])
            t = np.array([lo])
        v.check_inside(lo)
        v.check_inside(hi)
        out[name] = float(np.max(np.abs(np.asarray(v(t), float))))
    return out


def with_tables(values: dict, tolerances: Tolerances | None, tables: dict[str, float],
                machine: Machine) -> tuple[dict, Tolerances | None]:
    """The values with each table replaced by 0 (it has no one systematic value to centre on),
    and the tolerances with each table's range as its bound where the file gives none."""
    values = {k: (0.0 if k in tables else v) for k, v in values.items()}
    if tolerances is None or not tables:
        return values, tolerances
    have = tolerances.by_name()
    items = tuple(have.get(s.name) or Tolerance(s.name, tables[s.name], "uniform", tolerances.sigmas)
                  for s in machine.errors if s.name in have or (s.name in tables and tables[s.name]))
    return values, Tolerances(tolerances.file, tolerances.sigmas, items, tolerances.source)


def identically_zero(cb: "ComponentBudget") -> bool:
    """No error moves this component anywhere on the grid, in the model of the gains."""
    return not bool(np.any(cb.worst))


def _as_grid(x, shape) -> np.ndarray:
    return np.broadcast_to(np.asarray(x, dtype=float), shape)


def _first_max(a: np.ndarray) -> tuple[int, ...]:
    """Index of the largest value; among values equal to it within rounding (symmetric
    poses), the first in grid order, so the choice does not hang on the order of a sum."""
    if not a.shape:
        return ()
    flat = np.asarray(a).reshape(-1)
    top = float(flat.max())
    i = int(np.flatnonzero(flat >= top - 1e-12 * abs(top))[0])
    return tuple(int(k) for k in np.unravel_index(i, a.shape))


def _grouped_sum(terms: list) -> np.ndarray:
    """Sum of arrays on an open mesh: terms of the same shape (a gain of Y alone, of Y and Z,
    a constant) are added in their own few dimensions first, and broadcast to the full grid
    only in the last additions."""
    groups: dict[tuple, np.ndarray] = {}
    for t in terms:
        t = np.asarray(t, dtype=float)
        groups[t.shape] = groups[t.shape] + t if t.shape in groups else t
    total = np.zeros(())
    for key in sorted(groups, key=lambda k: int(np.prod(k)) if k else 1):
        total = total + groups[key]
    return total


def compute(machine: Machine, values: dict, tolerances: Tolerances, grid: Grid, order: str = "1",
            samples: int = 10000, seed: int = 1, centre_on_params: bool = True,
            gains=None, tables: dict[str, float] | None = None) -> Budget:
    """The budget on ``grid``. ``values``: internal values of every symbol (constants and the
    --params error values); errors deviate about those values when ``centre_on_params``,
    about zero otherwise (the params' values were read as bounds)."""
    model = gains or gain_model(machine, order)
    errs = machine.errors
    tol = tolerances.by_name()
    bounds = np.array([tol[s.name].bound if s.name in tol else 0.0 for s in errs])
    quants = np.array([tol[s.name].quantile(tolerances.sigmas) if s.name in tol else 0.0 for s in errs])
    sigmas = np.array([tol[s.name].sigma if s.name in tol else 0.0 for s in errs])
    params_errors = {s.name: values[s.name] for s in errs if values.get(s.name, 0.0) != 0.0}
    centre = dict(params_errors) if centre_on_params else {}

    args = dict(values)
    args.update(grid.open_mesh())
    for s in errs:
        args[s.name] = centre.get(s.name, 0.0)
    if params_errors:
        sys_args = dict(args)
        sys_args.update(params_errors)
        systematic = model.systematic(sys_args)
    else:
        systematic = {c: 0.0 for c in components(machine)}

    shape = grid.shape
    out = Budget(machine, order, tolerances, grid, dict(values), centre, params_errors,
                 samples=samples, seed=seed, tables=dict(tables or {}))
    length_scale = 1.0 / UNITS[machine.length_unit].to_internal
    for comp, g, qb in model.gains(args, centre, bounds):
        terms_w, terms_q, terms_s = [], [], []
        max_gain = np.zeros(len(errs))
        for i, gi in enumerate(g):
            a = np.abs(np.asarray(gi, dtype=float))
            max_gain[i] = float(a.max()) if a.size else 0.0
            if bounds[i]:
                terms_w.append(a * bounds[i])
                terms_q.append((a * quants[i]) ** 2)
                terms_s.append((a * sigmas[i]) ** 2)
        terms_w.append(np.asarray(qb, dtype=float))
        worst = _as_grid(_grouped_sum(terms_w), shape)
        var_q = _grouped_sum(terms_q)
        var_s = _grouped_sum(terms_s)
        idx = _first_max(worst)
        at = np.array([float(_as_grid(gi, shape)[idx]) for gi in g])
        pos = comp in POSITION
        out.components[comp] = ComponentBudget(
            comp, length_scale if pos else 1.0, machine.length_unit if pos else "1",
            _as_grid(systematic[comp], shape), worst, _as_grid(np.sqrt(var_q), shape),
            _as_grid(np.sqrt(var_s), shape), _as_grid(qb, shape), max_gain, tuple(int(i) for i in idx), at)
    if samples:
        monte_carlo(out, samples, seed)
    return out


# ----------------------------------------------------------------------------- Monte Carlo

def draw(tolerances: Tolerances, machine: Machine, n: int, rng: np.random.Generator) -> dict[str, np.ndarray]:
    """n deviations of every toleranced error, in the machine's error order."""
    out = {}
    for t in tolerances.items:
        if t.distribution == "uniform":
            out[t.name] = rng.uniform(-t.bound, t.bound, n)
        else:
            out[t.name] = rng.normal(0.0, t.sigma, n)
    return out


def monte_carlo(b: Budget, n: int, seed: int) -> None:
    """Exact-model deviations at each component's worst point (points shared where equal)."""
    machine, grid = b.machine, b.grid
    exact = ExactModel(machine)
    comps = list(b.components)
    points: dict[tuple, list[str]] = {}
    for c in comps:
        points.setdefault(b.components[c].worst_index, []).append(c)
    p = b.tolerances.coverage
    for index, names in points.items():
        axes = grid.at(index)
        base = dict(b.values)
        for a in machine.axes:
            base[a.name] = a.to_internal(axes[a.name])
        for s in machine.errors:
            base[s.name] = b.centre.get(s.name, 0.0)
        frame = _exact_frame(exact, base)
        ref = [float(v) for v in _exact_parts(exact, base, frame)]
        rng = np.random.default_rng(seed)   # the same draws at every point
        devs = {c: [] for c in comps}
        done = 0
        while done < n:
            m = min(MC_CHUNK, n - done)
            v = dict(base)
            for name, dev in draw(b.tolerances, machine, m, rng).items():
                v[name] = base[name] + dev
            vals = _exact_parts(exact, v, frame)
            for c, val, r in zip(components(machine), vals, ref):
                devs[c].append(np.broadcast_to(np.asarray(val, float) - r, (m,)))
            done += m
        for c in names:
            dev = np.concatenate(devs[c])
            b.components[c].monte_carlo = _mc_stats(dev, p, b.components[c])


def _mc_stats(dev: np.ndarray, p: float, cb: ComponentBudget) -> dict:
    n = len(dev)
    a = np.sort(np.abs(dev))
    q = float(np.quantile(a, p))
    # standard error of the quantile from the order statistics: +-1 binomial sigma of the rank
    half = math.sqrt(n * p * (1.0 - p))
    lo = a[max(0, int(math.floor(n * p - half)) - 1)]
    hi = a[min(n - 1, int(math.ceil(n * p + half)) - 1)]
    q_se = float(hi - lo) / 2.0
    sd = float(dev.std(ddof=1)) if n > 1 else 0.0
    idx = cb.worst_index
    worst, rss = float(cb.worst[idx]), float(cb.rss[idx])
    return {
        "samples": n,
        "mean": float(dev.mean()),
        "mean_se": sd / math.sqrt(n),
        "sigma": sd,
        "sigma_se": sd / math.sqrt(2.0 * (n - 1)) if n > 1 else 0.0,
        "coverage": p,
        "quantile": q,
        "quantile_se": q_se,
        "max": float(a[-1]),
        # nothing to bracket where the model has the component zero: null, not a failure
        "bracketed": None if identically_zero(cb) else bool(rss - 3 * q_se - 1e-15 <= q <= worst + 3 * q_se + 1e-15),
    }


# ----------------------------------------------------------------------------- reports

def contributors(b: Budget, comp: str) -> list[dict]:
    """Toleranced errors at the component's worst point, largest |gain| x bound first
    (ties in the machine's error order)."""
    cb = b.components[comp]
    tol = b.tolerances.by_name()
    rows = []
    for i, s in enumerate(b.machine.errors):
        if s.name not in tol:
            continue
        t = tol[s.name]
        g = float(cb.gains_at_worst[i])
        rows.append({"error": s.name, "gain": g, "bound": t.bound, "distribution": t.distribution,
                     "contribution": abs(g) * t.bound, "variance": (g * t.sigma) ** 2, "_i": i})
    total = sum(r["contribution"] for r in rows)
    var = sum(r["variance"] for r in rows)
    rows.sort(key=lambda r: (-r["contribution"], r["_i"]))
    for r in rows:
        r["share_worst"] = r["contribution"] / total if total else 0.0
        r["share_variance"] = r["variance"] / var if var else 0.0
        del r["_i"]
    return rows


def _display(b: Budget, comp: str, units: str = "people") -> tuple[float, str]:
    """Scale from internal units and unit name for text output (display.py's units): for people
    µm on mm machines (a machine in other units keeps its own) and arcsec for the direction
    components (a change of the unit tool axis: its tilt); internal mm and rad."""
    if comp in ANGULAR:
        u = display_unit("angle", units)
        return 1.0 / u.to_internal, u.name
    unit = b.machine.length_unit
    if units == "internal":
        return 1.0, "mm"
    if unit == "mm":
        return 1e3, "µm"
    return 1.0 / UNITS[unit].to_internal, unit


def _json_scale(b: Budget, comp: str) -> tuple[float, str]:
    if comp in ANGULAR:
        return 1.0, "1"
    unit = b.machine.length_unit
    return 1.0 / UNITS[unit].to_internal, unit


def _axes_at(b: Budget, index) -> dict[str, float]:
    return {a.name: float(f"{v:.12g}") for a, v in
            ((a, b.grid.at(index)[a.name]) for a in b.machine.axes)}


def _argmax(a: np.ndarray) -> tuple[int, ...]:
    return _first_max(a)


def to_json(b: Budget) -> dict:
    m, tol = b.machine, b.tolerances
    tmap = tol.by_name()
    out = {
        "machine": m.name,
        "file": m.file,
        "order": b.order,
        "units": {"length": m.length_unit, "direction": "1 (unit-vector components, ~rad)",
                  "gain": "component unit per the error's declared unit"},
        "tolerances": {
            "file": tol.file,
            "source": tol.source,
            "normal_bound_sigmas": tol.sigmas,
            "coverage": tol.coverage,
            "errors": [{"error": t.name, "bound": t.bound / m.symbol(t.name).unit.to_internal,
                        "unit": m.symbol(t.name).unit.name, "distribution": t.distribution,
                        **({"normal_bound_sigmas": t.sigmas} if t.distribution == "normal" else {}),
                        "sigma": t.sigma / m.symbol(t.name).unit.to_internal} for t in tol.items],
            "not_toleranced": [s.name for s in m.errors if s.name not in tmap],
        },
        "centre": {s: b.centre[s] / m.symbol(s).unit.to_internal for s in b.centre},
        "params_errors": {s: b.params_errors[s] / m.symbol(s).unit.to_internal for s in b.params_errors},
        # errors given as tables: the largest |value| on the grid, declared units (their bound
        # unless the tolerance file gives one)
        "tables": {s: v / m.symbol(s).unit.to_internal for s, v in b.tables.items()},
        "grid": {"axes": [{"name": a.name, "unit": a.unit.name, "from": float(p[0]), "to": float(p[-1]),
                           "points": len(p)} for a, p in zip(b.grid.axes, b.grid.points)],
                 "fixed": b.grid.fixed, "points": b.grid.size},
        "monte_carlo": {"samples": b.samples, "seed": b.seed, "model": "exact"} if b.samples else None,
        "components": {},
        "sensitivity": [],
    }
    for comp, cb in b.components.items():
        k, unit = _json_scale(b, comp)
        iw = cb.worst_index
        ir = _argmax(cb.rss)
        mc = None
        if cb.monte_carlo:
            mc = {key: (v * k if key in ("mean", "mean_se", "sigma", "sigma_se", "quantile", "quantile_se", "max")
                        else v) for key, v in cb.monte_carlo.items()}
        contribs = []
        for r in contributors(b, comp):
            eu = m.symbol(r["error"]).unit
            contribs.append({"error": r["error"], "gain": r["gain"] * eu.to_internal * k,
                             "gain_unit": f"{unit}/{eu.name}", "bound": r["bound"] / eu.to_internal,
                             "bound_unit": eu.name, "distribution": r["distribution"],
                             "contribution": r["contribution"] * k, "share_worst": r["share_worst"],
                             "share_variance": r["share_variance"]})
        out["components"][comp] = {
            "unit": unit,
            "identically_zero": identically_zero(cb),
            "systematic": {"min": float(cb.systematic.min()) * k, "max": float(cb.systematic.max()) * k},
            "worst": {"max": float(cb.worst[iw]) * k, "min": float(cb.worst.min()) * k, "at": _axes_at(b, iw)},
            "rss": {"max": float(cb.rss[ir]) * k, "min": float(cb.rss.min()) * k, "at": _axes_at(b, ir)},
            "sigma": {"max": float(cb.sigma.max()) * k},
            "at_worst": {
                "axes": _axes_at(b, iw),
                "systematic": float(cb.systematic[iw]) * k,
                "worst": float(cb.worst[iw]) * k,
                "rss": float(cb.rss[iw]) * k,
                "sigma": float(cb.sigma[iw]) * k,
                "second_order_bound": float(cb.second_order_bound[iw]) * k,
                "contributors": contribs,
                "monte_carlo": mc,
            },
        }
    for i, s in enumerate(m.errors):
        row = {"error": s.name, "unit": s.unit.name, "max_abs_gain": {}}
        for comp, cb in b.components.items():
            k, _ = _json_scale(b, comp)
            row["max_abs_gain"][comp] = float(cb.max_gain[i]) * s.unit.to_internal * k
        g = max(float(b.components[c].max_gain[i]) for c in POSITION)
        k, _ = _json_scale(b, "dx")
        row["lever_arm"] = g * k if s.unit.kind == "angle" else None
        row["at_bound"] = g * tmap[s.name].bound * k if s.name in tmap else None
        out["sensitivity"].append(row)
    return out


def _fmt(v: float, digits: int = 3) -> str:
    return f"{v:.{digits}f}"


def _bracketed(flag: bool | None) -> str:
    return "zero" if flag is None else "yes" if flag else "NO"


def to_text(b: Budget, top: int = 5, units: str = "people") -> str:
    m, tol = b.machine, b.tolerances
    order = {"1": "first-order gains", "2": "second-order model (gradient at the centre + a bound of "
             "its quadratic terms)", "exact": "exact model (secant gains across each tolerance)"}[b.order]
    lines = [f"BUDGET {m.name} ({one_line(m.file)}), {order}"]
    n_u = sum(t.distribution == "uniform" for t in tol.items)
    n_n = len(tol.items) - n_u
    if tol.source == "params":
        src = "the error values of --params read as bounds (uniform on +-|value|)"
    else:
        src = tol.file
    lines.append(f"Tolerances: {src}: {len(tol.items)} of {len(m.errors)} errors ({n_u} uniform, {n_n} normal"
                 f"{f', normal bound = {tol.sigmas:g} sigma' if n_n or tol.source == 'file' else ''}); "
                 f"RSS and quantiles at coverage {100 * tol.coverage:.2f} %")
    if b.tables:
        def cell(n):
            s = m.symbol(n)
            return f"{n} {b.tables[n] / s.unit.to_internal:.4g} {s.unit.name}"
        lines.append("  tables in --params, not systematic (a table has no one value); their largest |value| on the "
                     "grid is their bound" + (" where the tolerance file gives none" if tol.source == "file" else "")
                     + ": " + ", ".join(cell(n) for n in b.tables))
    not_tol = [s.name for s in m.errors if s.name not in tol.by_name()]
    if not_tol and tol.source == "file":
        lines.append(f"  not toleranced (taken as exact): {', '.join(not_tol)}")
    if b.params_errors:
        about = "the --params values" if b.centre else "zero (the --params values are the bounds)"
        lines.append(f"Errors deviate about {about}; 'systematic' is the error with every error at its "
                     f"--params value")
    else:
        lines.append("Errors deviate about zero; no error values in --params, so nothing is systematic")
    axes = ", ".join(f"{a.name} {p[0]:g}..{p[-1]:g} {a.unit.name}" for a, p in zip(b.grid.axes, b.grid.points))
    lines.append(f"Grid: {axes}; {b.grid.shape[0]} points each, {b.grid.size} points")
    if b.grid.fixed:
        lines.append("Fixed: " + ", ".join(f"{n} = {v:g} {m.symbol(n).unit.name}" for n, v in b.grid.fixed.items()))
    names = [a.name for a in m.axes]
    lines.append("")
    lines.append(f"Tool error over the grid (position in {_display(b, 'dx', units)[1]}, direction in {_display(b, 'dkx', units)[1]})")
    lines.append(f"  {'comp':<5} {'worst max':>10} {'worst min':>10} {'rss max':>10} {'sigma max':>10} "
                 f"{'systematic':>22}   worst at ({', '.join(names)})")
    for comp, cb in b.components.items():
        k, _ = _display(b, comp, units)
        lo, hi = float(cb.systematic.min()) * k, float(cb.systematic.max()) * k
        sysx = f"{lo:+.3f} everywhere" if abs(hi - lo) <= 1e-9 * max(1.0, abs(hi)) else f"{lo:+.3f}..{hi:+.3f}"
        at = ", ".join(f"{v:g}" for v in _axes_at(b, cb.worst_index).values())
        if identically_zero(cb):
            lines.append(f"  {comp:<5} {'0':>10} {'0':>10} {'0':>10} {'0':>10} {sysx:>22}   identically zero: "
                         f"no error moves {comp} in this model")
            continue
        lines.append(f"  {comp:<5} {_fmt(float(cb.worst.max()) * k):>10} {_fmt(float(cb.worst.min()) * k):>10} "
                     f"{_fmt(float(cb.rss.max()) * k):>10} {_fmt(float(cb.sigma.max()) * k):>10} {sysx:>22}   ({at})")
    if b.samples:
        q = f"q{100 * tol.coverage:.2f}"
        lines.append("")
        lines.append(f"At each component's worst point: analytic figures and Monte Carlo of the exact model "
                     f"(N = {b.samples}, seed {b.seed}); {q}: the {100 * tol.coverage:.2f} % quantile of "
                     f"|deviation|, which rss and worst should bracket")
        lines.append(f"  {'comp':<5} {'rss':>9} {'MC ' + q:>18} {'worst':>9}  {'bracketed':<9} {'sigma':>9} "
                     f"{'MC sigma':>17} {'MC mean':>9} {'MC max':>9}")
        for comp, cb in b.components.items():
            k, _ = _display(b, comp, units)
            mc, i = cb.monte_carlo, cb.worst_index
            lines.append(f"  {comp:<5} {_fmt(float(cb.rss[i]) * k):>9} "
                         f"{_fmt(mc['quantile'] * k) + ' ± ' + _fmt(mc['quantile_se'] * k):>18} "
                         f"{_fmt(float(cb.worst[i]) * k):>9}  {_bracketed(mc['bracketed']):<9} "
                         f"{_fmt(float(cb.sigma[i]) * k):>9} "
                         f"{_fmt(mc['sigma'] * k) + ' ± ' + _fmt(mc['sigma_se'] * k):>17} "
                         f"{_fmt(mc['mean'] * k):>9} {_fmt(mc['max'] * k):>9}")
        for comp, cb in b.components.items():
            if identically_zero(cb):
                lines.append(f"  {comp}: zero in this model, so nothing to bracket; the Monte Carlo's "
                             f"{_fmt(cb.monte_carlo['max'] * _display(b, comp, units)[0])} {_display(b, comp, units)[1]} at most is "
                             f"the exact model's part of higher order")
    for comp, cb in b.components.items():
        rows = contributors(b, comp)
        if not rows or float(cb.worst[cb.worst_index]) == 0.0:
            continue
        k, unit = _display(b, comp, units)
        at = ", ".join(f"{n} = {v:g}" for n, v in _axes_at(b, cb.worst_index).items())
        lines.append("")
        shown = rows if top <= 0 else rows[:top]
        lines.append(f"Dominant contributors to {comp} at its worst point ({at}): worst "
                     f"{_fmt(float(cb.worst[cb.worst_index]) * k)} {unit}"
                     + (f", top {len(shown)} of {len(rows)}" if len(shown) < len(rows) else ""))
        lines.append(f"  {'rank':>4}  {'error':<10} {'bound':>16} {'dist':<8} {'gain':>24} {'contribution':>14} "
                     f"{'share':>7} {'of var.':>8}")
        for r, row in enumerate(shown, 1):
            eu = m.symbol(row["error"]).unit
            gain = f"{row['gain'] * eu.to_internal * k:+.4g} {unit}/{eu.name}"
            bound = f"{row['bound'] / eu.to_internal:g} {eu.name}"
            lines.append(f"  {r:>4}  {row['error']:<10} {bound:>16} {row['distribution']:<8} {gain:>24} "
                         f"{_fmt(row['contribution'] * k) + ' ' + unit:>14} {100 * row['share_worst']:>6.1f}% "
                         f"{100 * row['share_variance']:>7.1f}%")
        qb = float(cb.second_order_bound[cb.worst_index])
        if qb:
            lines.append(f"        second-order terms: at most {_fmt(qb * k)} {unit} (in the worst case, not in "
                         f"the shares)")
    lines.append("")
    comps = list(b.components)
    lines.append("Sensitivity: max |gain| over the grid, per declared unit of the error (position in "
                 f"{_display(b, 'dx', units)[1]}, direction in {_display(b, 'dkx', units)[1]})")
    lines.append("  arm: the largest |gain| in position of an angular error, in mm per rad = its lever arm "
                 "(a length error: its factor); at bound: that times the bound")
    kpos, upos = _display(b, "dx", units)
    lines.append(f"  {'error':<10} {'unit':<7} " + " ".join(f"{c:>10}" for c in comps)
                 + f" {'arm':>12} {'at bound':>12}")
    tmap = tol.by_name()
    for i, s in enumerate(m.errors):
        cells = []
        for c in comps:
            k, _ = _display(b, c, units)
            cells.append(f"{float(b.components[c].max_gain[i]) * s.unit.to_internal * k:>10.4g}")
        g = max(float(b.components[c].max_gain[i]) for c in POSITION)
        arm = f"{g:.4g} mm" if s.unit.kind == "angle" else f"x{g:.4g}"
        if b.machine.length_unit != "mm" and s.unit.kind == "angle":
            arm = f"{g * UNITS['mm'].to_internal / UNITS[b.machine.length_unit].to_internal:.4g} " \
                  f"{b.machine.length_unit}"
        at_bound = f"{g * tmap[s.name].bound * kpos:.3f} {upos}" if s.name in tmap else "-"
        lines.append(f"  {s.name:<10} {s.unit.name:<7} " + " ".join(cells) + f" {arm:>12} {at_bound:>12}")
    return "\n".join(lines)
