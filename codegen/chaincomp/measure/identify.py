"""Error values from measured tool-tip coordinates: nonlinear least squares on the exact model.

Measurements are a CSV file (see ``table.read_table``): one row per set-up, one column per axis
and per measured coordinate (tool point x, y, z; tool direction kx, ky, kz; with a tool frame
its orientation as a unit quaternion qw, qx, qy, qz). The fit is Gauss-Newton on the exact
chain, each coordinate weighted by its standard uncertainty; a measured orientation enters as
the rotation vector ω = log(R_measured·R_modelᵀ) (chaincomp.orientation: about the base
frame's axes), the rows wx, wy, wz. Its Jacobian is taken by the complex step (the derivative
is the imaginary part of the chain evaluated at an imaginary error, free of the cancellation
that makes a difference quotient of 500 mm coordinates lose eight digits and blur the rank),
for all rows and all parameters in one broadcast call (``lsq.step_derivatives``).

The parameters are the errors' values, or, for an error fitted as varying along an axis
(``Vary``), its values at given knots (piecewise linear between them) or its polynomial
coefficients: either way the error at a set-up is linear in its parameters (a basis matrix
per error), so complex steps pass through.

Parameters that these set-ups cannot separate (the first-order Jacobian, its columns scaled
to unit norm, has a null space touching them) stay out of the fit's parameter space and are
reported, not given a value; or, with ``minimal``, a minimal identifiable set is chosen by QR
with column pivoting and fitted alone, every other parameter held at zero and reported with
the combination of the chosen ones that carries it. A fit in which nothing is left, or
without the redundancy to estimate its own uncertainty, is refused.

The least-squares machinery (Gauss-Newton, rank and gauge, covariance, Huber's weights, the
chi-square test) is measure.lsq's; the measurement file is measure.table's, the report's words
and the params file measure.identify_report's. This module is the model: the observations, the
parameters of each error and what the numbers mean for them.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from ..errors import ChaincompError
from ..model.machine import Machine
from ..model.params import load_params
from ..model.varying import MAX_POLYNOMIAL_COEFFICIENTS, MAX_TABLE_KNOTS, MAX_VARYING_ERRORS
from ..symbolic.derive import COMPONENTS
from ..symbolic.numeric import ExactModel
from ..symbolic.orientation import ROWS as ROTATION, cross, rotation_vector
from . import lsq
from .table import DIRECTIONS, OBSERVED, Table, count, matrix_quaternion

MAX_JACOBIAN = 5_000_000    # measured coordinates x parameters (40 MB a copy): bounds the fit's memory and time
MAX_PARAMETERS = 1000       # the rank analysis holds parameters x parameters (8 MB)
_CHUNK = 1_000_000          # parameter sets x rows evaluated in one broadcast call of the chain
# The smoothing weight (per squared second difference in the error's declared unit): at 1e12 a
# table is already a straight line to a millionth of a unit; larger weights only swamp the data's
# rows in rounding (at 1e200 the fit saw one combination, at 1e306 none).
MAX_SMOOTH = 1e12
PROGRESS_SIZE = 1_000_000   # parameters x coordinates above which a fit reports its stages (seconds)


def pose_points(machine: Machine, model: ExactModel, axes: dict[str, np.ndarray], errors: dict) -> np.ndarray:
    """Tool points (..., rows, 3) for error values that may carry leading dimensions."""
    values = machine.nominal_values()
    values.update(axes)
    values.update(errors)
    point, _ = model.pose(values)
    shape = np.broadcast_shapes(*[np.shape(v) for v in point])
    return np.stack([np.broadcast_to(v, shape) for v in point], axis=-1)


def pose_frames(machine: Machine, model: ExactModel, axes: dict[str, np.ndarray], errors: dict) -> np.ndarray:
    """Tool points, directions and frames' x axes (..., rows, 9) for error values that may carry
    leading dimensions (direction and x axis zero where the machine has none)."""
    values = machine.nominal_values()
    values.update(axes)
    values.update(errors)
    point, direction, x_axis = model.frame(values)
    parts = point + (direction if direction is not None else [0.0] * 3) + (x_axis if x_axis is not None else [0.0] * 3)
    shape = np.broadcast_shapes(*[np.shape(v) for v in parts])
    return np.stack([np.broadcast_to(v, shape) for v in parts], axis=-1)


def _observed(frames: np.ndarray, rotations: np.ndarray | None) -> np.ndarray:
    """(..., rows, 9) predictions in the order of Table.observations from pose_frames' output:
    the point, the direction and, where an orientation is measured, minus the residual
    log(R_measured·R_modelᵀ) (so that measured 0 minus the prediction is the residual)."""
    out = frames.copy()
    if rotations is None:
        return out
    z, x = np.moveaxis(frames[..., 3:6], -1, 0), np.moveaxis(frames[..., 6:9], -1, 0)
    zm, xm = np.moveaxis(rotations[..., 2], -1, 0), np.moveaxis(rotations[..., 0], -1, 0)
    with np.errstate(invalid="ignore"):            # rows without a measured orientation are NaN
        w = rotation_vector((list(zm), list(xm)), (list(z), list(x)))
    out[..., 6:9] = -np.stack(np.broadcast_arrays(*w), axis=-1)
    return out


def _observed_derivatives(frames: np.ndarray, d: np.ndarray) -> np.ndarray:
    """(k, rows, 9) derivatives of the observations from those of pose_frames (``d``, (k, rows,
    9)) at the frames ``frames`` (rows, 9): the orientation's rows are the model frame's
    rotation δω = ½ Σ_v v × δv over its axes x, y, z (δv = δω × v for an orthonormal frame), y =
    z × x, δy = δz × x + z × δx; the residual log(R_measured·R_modelᵀ) moves by −δω."""
    out = d.copy()
    z, x = np.moveaxis(frames[..., 3:6], -1, 0), np.moveaxis(frames[..., 6:9], -1, 0)
    dz, dx = np.moveaxis(d[..., 3:6], -1, 0), np.moveaxis(d[..., 6:9], -1, 0)
    y = cross(z, x)
    dy = [a + b for a, b in zip(cross(dz, x), cross(z, dx))]
    parts = [cross(x, dx), cross(y, dy), cross(z, dz)]
    out[..., 6:9] = np.stack([0.5 * (parts[0][i] + parts[1][i] + parts[2][i]) for i in range(3)], axis=-1)
    return out


def residuals(machine: Machine, table: Table, errors: dict, model: ExactModel | None = None) -> np.ndarray:
    """(rows, 9) measured minus predicted at the error values ``errors`` (internal units, by name):
    x, y, z, kx, ky, kz, and for a measured orientation the rotation vector ω = log(R_measured·
    R_modelᵀ) (rad, about the base frame's axes); NaN where not measured."""
    f = pose_frames(machine, model or ExactModel(machine), table.axes, errors)
    f = np.broadcast_to(f, (len(table.lines), 9))
    return table.observations - _observed(f, table.rotations)


def simulate(machine: Machine, values: dict, axes: dict[str, np.ndarray], noise: float,
             rng: np.random.Generator, measure=COMPONENTS, model: ExactModel | None = None) -> np.ndarray:
    """Tool points (rows, 3) with the errors (and constants) in ``values`` plus Gaussian noise
    of standard deviation ``noise`` (internal units); NaN in coordinates not measured."""
    rows = len(next(iter(axes.values())))
    pts = pose_points(machine, model or ExactModel(machine), {k: np.asarray(v) for k, v in axes.items()}, values)
    pts = np.broadcast_to(pts, (rows, 3)) + noise * rng.standard_normal((rows, 3))
    for i, c in enumerate(COMPONENTS):
        if c not in measure:
            pts[:, i] = math.nan
    return pts


def rotation_matrix(w: np.ndarray) -> np.ndarray:
    """(..., 3, 3) exp([w]×) of rotation vectors (..., 3) (Rodrigues; its series below 1e-8 rad)."""
    w = np.asarray(w, float)
    t = np.linalg.norm(w, axis=-1)[..., None, None]
    k = np.zeros(w.shape[:-1] + (3, 3))
    k[..., 0, 1], k[..., 0, 2], k[..., 1, 2] = -w[..., 2], w[..., 1], -w[..., 0]
    k = k - np.swapaxes(k, -1, -2)
    small = t < 1e-8
    a = np.where(small, 1.0, np.sin(t) / np.where(small, 1.0, t))
    b = np.where(small, 0.5, (1 - np.cos(t)) / np.where(small, 1.0, t) ** 2)
    return np.eye(3) + a * k + b * (k @ k)


def simulate_orientations(machine: Machine, values: dict, axes: dict[str, np.ndarray], noise: float,
                          rng: np.random.Generator, model: ExactModel | None = None) -> np.ndarray:
    """Measured tool frame orientations (rows, 4) as unit quaternions qw, qx, qy, qz (qw >= 0),
    with the errors in ``values``: the actual frame turned by a rotation vector about the base
    axes with Gaussian components of standard deviation ``noise`` (rad)."""
    rows = len(next(iter(axes.values())))
    f = np.broadcast_to(pose_frames(machine, model or ExactModel(machine),
                                    {k: np.asarray(v) for k, v in axes.items()}, values), (rows, 9))
    z, x = f[:, 3:6], f[:, 6:9]
    frame = np.stack([x, np.cross(z, x), z], axis=-1)                  # columns x, y, z
    return matrix_quaternion(rotation_matrix(noise * rng.standard_normal((rows, 3))) @ frame)


# ----------------------------------------------------------------------------- parameters

@dataclass(frozen=True)
class Vary:
    """An error fitted as varying along ``axis``: a table on ``knots`` (internal units,
    increasing; piecewise linear in the knot values, held at the end values beyond them), or a
    polynomial of ``degree`` in the axis' declared unit (held beyond the measured span)."""
    error: str
    axis: str
    kind: str                       # "table" | "poly"
    knots: tuple[float, ...] = ()
    degree: int = 0


@dataclass(frozen=True)
class Param:
    """One fitted number: an error's constant value, a table's value at a knot, or a
    polynomial coefficient."""
    name: str            # the error's name, EXX@X=100 (knot at X = 100 in X's unit) or EXX.c2
    error: str
    kind: str            # unit kind of the error's value
    unit: str            # declared unit: the error's, per the axis' unit^power for a coefficient
    to_internal: float   # a value in ``unit`` times this is internal (mm, rad, 1 per mm^k or rad^k)
    power: int = 0       # a polynomial coefficient's power of the axis
    axis: str | None = None
    knot: bool = False   # a table's value at a knot


def _hat(x: np.ndarray, t: np.ndarray) -> np.ndarray:
    """(rows, knots): the piecewise linear interpolant's weights of each knot value at t, the
    end values held beyond the ends (the params format's linear table with outside: hold)."""
    k = np.clip(np.searchsorted(x, t, side="right") - 1, 0, len(x) - 2)
    u = np.clip((t - x[k]) / (x[k + 1] - x[k]), 0.0, 1.0)
    b = np.zeros((len(t), len(x)))
    b[np.arange(len(t)), k] = 1 - u
    b[np.arange(len(t)), k + 1] += u
    return b


def _parameters(machine: Machine, free: list[str], varies: dict[str, Vary], table: Table):
    """The parameters (machine order; an error's together), each error's (parameter indices,
    basis matrix (rows, its parameters)) so that its value per row is basis @ parameters, a
    polynomial's range (the measured span, internal) and notes for the report."""
    params, bases, ranges, notes = [], {}, {}, []
    rows = len(table.lines)
    for name in free:
        s = machine.symbol(name)
        v = varies.get(name)
        first = len(params)
        if v is None:
            params.append(Param(name, name, s.unit.kind, s.unit.name, s.unit.to_internal))
            bases[name] = (list(range(first, first + 1)), np.ones((rows, 1)))
            continue
        a = machine.symbol(v.axis)
        t = np.asarray(table.axes[v.axis], float)
        if v.kind == "table":
            x = np.array(v.knots, float)
            params += [Param(f"{name}@{v.axis}={a.from_internal(k):.10g}", name, s.unit.kind, s.unit.name,
                             s.unit.to_internal, axis=v.axis, knot=True) for k in x]
            basis = _hat(x, t)
            out = int(((t < x[0]) | (t > x[-1])).sum())
            if out:
                notes.append(f"{count(out, 'set-up')} lie{'s' if out == 1 else ''} outside {name}'s knots "
                             f"[{a.from_internal(x[0]):g}, {a.from_internal(x[-1]):g}] {a.unit.name} of "
                             f"{v.axis}: the table holds its end values there")
        else:
            lo, hi = float(t.min()), float(t.max())
            if not lo < hi:
                raise ChaincompError(f"--vary {name}: every set-up has {v.axis} = {a.from_internal(lo):g} "
                                     f"{a.unit.name}; a polynomial along {v.axis} needs measurements at "
                                     f"different positions", table.file)
            ranges[name] = (lo, hi)
            tc = np.clip(t, lo, hi)
            for k in range(v.degree + 1):
                unit = s.unit.name if k == 0 else f"{s.unit.name}/{a.unit.name}" + (f"^{k}" if k > 1 else "")
                params.append(Param(f"{name}.c{k}", name, s.unit.kind, unit,
                                    s.unit.to_internal / a.unit.to_internal ** k, k, v.axis))
            basis = np.stack([tc ** k for k in range(v.degree + 1)], axis=1)
        bases[name] = (list(range(first, len(params))), basis)
    return params, bases, ranges, notes


def _check_vary(machine: Machine, vary, assume_zero) -> dict[str, Vary]:
    out = {}
    for v in vary:
        s = machine.symbol(v.error)
        if s.role != "error" or machine.symbol(v.axis).role != "axis":
            raise ChaincompError(f"--vary {v.error}@{v.axis}: expected an error and an axis of {machine.name}")
        if v.error in assume_zero:
            raise ChaincompError(f"--vary {v.error}: it is also assumed zero (--assume-zero)")
        if v.error in out:
            raise ChaincompError(f"--vary {v.error}: given twice")
        if v.kind == "table" and not (2 <= len(v.knots) <= MAX_TABLE_KNOTS and np.all(np.diff(v.knots) > 0)):
            raise ChaincompError(f"--vary {v.error}: a table needs 2 to {MAX_TABLE_KNOTS} increasing knots")
        if v.kind == "poly" and not 0 <= v.degree < MAX_POLYNOMIAL_COEFFICIENTS:
            raise ChaincompError(f"--vary {v.error}: the degree must be 0 to {MAX_POLYNOMIAL_COEFFICIENTS - 1}")
        if v.kind not in ("table", "poly"):
            raise ChaincompError(f"--vary {v.error}: expected table or poly, got {v.kind!r}")
        a = machine.symbol(v.axis)
        if len({f"{a.from_internal(k):.10g}" for k in v.knots}) < len(v.knots):
            raise ChaincompError(f"--vary {v.error}: knots must differ in 10 significant digits")
        out[v.error] = v
    if len(out) > MAX_VARYING_ERRORS:
        raise ChaincompError(f"--vary: at most {MAX_VARYING_ERRORS} varying errors (the params format's limit), "
                             f"got {len(out)}")
    return out


def _weights(sigma, measured: list[str], mask: np.ndarray, smooth: float):
    """Per observation 1/sigma (or 1 where no sigma is given) and the sigmas by column."""
    if sigma is None:
        sig = {}
    elif isinstance(sigma, dict):
        sig = dict(sigma)
    else:
        sig = {c: float(sigma) for c in COMPONENTS}
    angles = DIRECTIONS + ROTATION
    pos = [c for c in measured if c in COMPONENTS]
    ang = [c for c in measured if c in angles]
    for c, value in sig.items():
        if c not in OBSERVED or not value > 0:
            raise ChaincompError(f"--sigma: expected positive values for columns of {', '.join(OBSERVED)}, "
                                 f"got {c}={value!r}")
    if any(c in angles for c in sig) and not ang:
        raise ChaincompError("--sigma gives an angle, the standard uncertainty of the measured tool direction "
                             "or orientation, but the measurements have no kx, ky, kz (or qw, qx, qy, qz) column")
    if any(c in COMPONENTS for c in sig) and not pos:
        raise ChaincompError("--sigma gives a length, the standard uncertainty of the measured tool point, but "
                             "the measurements have no x, y, z column")
    sig = {c: v for c, v in sig.items() if c in measured}
    if sig:
        missing = [c for c in measured if c not in sig]
        if missing:
            raise ChaincompError(f"--sigma gives no standard uncertainty for the measured "
                                 f"{'columns' if len(missing) > 1 else 'column'} {', '.join(missing)} "
                                 f"(give a length for x, y, z and an angle for kx, ky, kz and wx, wy, wz, the "
                                 f"measured orientation's rotation vector; e.g. --sigma 20um,10arcsec)")
    elif pos and ang:
        what = "directions (kx, ky, kz)" if ang[0] in DIRECTIONS else "orientations (qw, qx, qy, qz)"
        raise ChaincompError(f"tool points (x, y, z) and {what} are both measured: weighing one "
                             "against the other needs their standard uncertainties; give --sigma LENGTH,ANGLE "
                             "(e.g. --sigma 20um,10arcsec)")
    if smooth and not sig:
        raise ChaincompError("--smooth weighs the tables' second differences against the measurements' standard "
                             "uncertainty: give --sigma as well")
    col = np.array([1.0 / sig[c] if c in sig else 1.0 for c in OBSERVED])
    return np.broadcast_to(col, mask.shape)[mask], sig


def _penalty(params: list[Param], varies: dict[str, Vary], smooth: float) -> np.ndarray:
    """Rows whose squares sum to smooth * sum of (second difference of a table's knot values,
    in the error's declared unit)^2."""
    n = len(params)
    rows = []
    for e, v in varies.items():
        if not smooth or v.kind != "table":
            continue
        idx = [i for i, p in enumerate(params) if p.error == e]
        f = params[idx[0]].to_internal
        for k in range(len(idx) - 2):
            r = np.zeros(n)
            r[idx[k:k + 3]] = np.array([1.0, -2.0, 1.0]) * math.sqrt(smooth) / f
            rows.append(r)
    return np.array(rows).reshape(-1, n)


@dataclass
class Fit:
    machine: Machine
    fitted: list[str]                      # errors in the fit (not assumed zero), machine order
    assumed_zero: list[str]
    estimates: dict[str, float]            # identified parameters by name, internal units
    uncertainties: dict[str, float]        # standard uncertainties, internal units
    unidentifiable: dict[str, str]         # parameter -> reason
    suggested_zero: list[str]              # assumed zero as well, these leave every other one identifiable
    rank: int                              # independent combinations of the parameters the data see
    condition: float
    correlations: list[tuple[str, str, float]]
    rms: float                             # rms residual of the tool point, internal length (nan: not measured)
    observations: int
    setups: int
    dof: float
    iterations: int
    converged: bool
    measured: list[str]
    params: list[Param] = field(default_factory=list)
    varying: dict[str, Vary] = field(default_factory=dict)
    ranges: dict[str, tuple[float, float]] = field(default_factory=dict)   # polynomials' span, internal
    minimal: bool = False
    redundant: dict[str, str] = field(default_factory=dict)        # minimal: held at zero -> the combination
    carried: dict[str, dict[str, float]] = field(default_factory=dict)   # ... as coefficients (internal units)
    sigma: dict[str, float] = field(default_factory=dict)           # given standard uncertainty by column
    chi2: float | None = None              # weighted residual sum of squares / dof, with sigma given
    rms_direction: float = math.nan        # rms residual of the tool direction (rad; nan: not measured)
    smooth: float = 0.0
    notes: list[str] = field(default_factory=list)
    rms_orientation: float = math.nan      # rms of the orientation residual's components (rad; nan: not measured)
    worst: list[tuple[int, float]] = field(default_factory=list)   # (CSV line, |weighted residual|), largest first
    misfit: str | None = None              # with sigma: why chi2/dof says the fit does not fit (misfit())
    # (set-ups, 9) measured minus model in the order of Table.observations, internal units, NaN where
    # not measured: with every fitted error zero, and at the estimates (the calibration report's numbers)
    residuals_before: np.ndarray | None = None
    residuals_after: np.ndarray | None = None
    correlation: np.ndarray | None = None  # of the estimates, in their order
    huber: float | None = None             # Huber's k (in standard uncertainties), None: least squares
    outliers: list[tuple[int, str, float, float]] = field(default_factory=list)  # Huber: (line, column, u, weight)


def misfit(fit: Fit) -> str | None:
    """With --sigma, a chi2/dof beyond its lsq.MISFIT_PROBABILITY quantile says the residuals are larger
    than the given uncertainties allow: the words saying so and naming the worst set-ups; else None."""
    limit = lsq.chi2_limit(fit.chi2, fit.dof)
    if limit is None:
        return None
    worst = ", ".join(f"line {line} ({r:.3g} sigma)" for line, r in fit.worst)
    return (f"chi2/dof {fit.chi2:.3g} is beyond its {lsq.MISFIT_PROBABILITY:.1%} quantile for {fit.dof:.4g} degrees of "
            f"freedom ({limit:.3g}): the residuals are larger than --sigma allows (a sigma too small, outliers, "
            f"or an error the model lacks); the largest residuals: {worst}")


def identify(machine: Machine, table: Table, assume_zero=(), sigma=None, max_iterations: int = 50,
             model: ExactModel | None = None, vary=(), smooth: float = 0.0, minimal: bool = False,
             prefer=(), progress=None, huber: float | None = None) -> Fit:
    """Fit the errors of ``machine`` (all but ``assume_zero``) to the measured tool points,
    directions and orientations.

    ``sigma``: None (one standard uncertainty for all, estimated from the residuals), a length
    for x, y, z (internal units), or {column: sigma} (lengths for x, y, z, angles in rad for
    kx, ky, kz and for wx, wy, wz, the components of a measured orientation's residual).
    ``vary``: ``Vary`` specs of errors fitted as tables or polynomials along an axis;
    ``smooth``: the weight of their tables' second differences (declared unit). ``minimal``:
    fit a minimal identifiable set, every other parameter held at zero; ``prefer``: errors to take
    into that set (and keep out of the suggested assume-zero set) first; ``progress``: called with
    a line of text at each stage of a large fit (parameters x coordinates above PROGRESS_SIZE); ``huber``:
    Huber's k, for a robust fit by iteratively reweighted least squares (each coordinate's weight
    recomputed from its standardized residual at every Gauss-Newton step: by --sigma, or without it
    by 1.4826 x the median absolute weighted residual). ``model``: the machine's
    ExactModel, to reuse its compiled functions across fits. Raises ChaincompError when the data
    identify nothing, leave no redundancy to estimate the uncertainty (without ``sigma``), or
    give non-finite values."""
    model = model or ExactModel(machine)
    varies = _check_vary(machine, vary, assume_zero)
    if not 0 <= smooth <= MAX_SMOOTH:
        raise ChaincompError(f"--smooth: must be at least 0 and at most {MAX_SMOOTH:g}, got {smooth!r}")
    if smooth and not any(v.kind == "table" and len(v.knots) > 2 for v in varies.values()):
        raise ChaincompError("--smooth: no error is fitted as a table of 3 or more knots (--vary NAME=table:...) "
                             "to smooth")
    free = [s.name for s in machine.errors if s.name not in assume_zero]
    both = [n for n in prefer if n in assume_zero]
    if both:
        raise ChaincompError(f"--prefer {both[0]}: it is also assumed zero (--assume-zero)")
    if not free:
        raise ChaincompError("--assume-zero: every error is assumed zero, nothing is left to fit")
    obs = table.observations
    mask = ~np.isnan(obs)
    y = obs[mask]
    measured = [c for i, c in enumerate(OBSERVED) if mask[:, i].any()]
    w, sig = _weights(sigma, measured, mask, smooth)
    params, bases, ranges, notes = _parameters(machine, free, varies, table)
    penalty = _penalty(params, varies, smooth)
    names = [p.name for p in params]
    n, m = len(params), int(mask.sum())
    if n > MAX_PARAMETERS:
        raise ChaincompError(f"{n} parameters to fit (errors, knots and coefficients), more than {MAX_PARAMETERS}; "
                             f"fit fewer knots")
    if n * (m + len(penalty)) > MAX_JACOBIAN:
        raise ChaincompError(f"{n} parameters for {m} measured coordinates: the fit's Jacobian would hold "
                             f"{n * (m + len(penalty)):.3g} numbers, more than {MAX_JACOBIAN:.0e}; fit fewer knots "
                             f"or use fewer set-ups", table.file)
    data = f"{count(m, 'coordinate')} ({', '.join(measured)}) at {count(len(table.lines), 'set-up')}"
    nonfinite = ChaincompError(f"the fit went to non-finite values on these {data} (coordinates in "
                               f"{machine.length_unit}? axes in their declared units?)", table.file)

    rows = len(table.lines)

    def frames(P: np.ndarray) -> np.ndarray:             # (k, n) parameter sets -> (k, rows, 9)
        errs = {e: P[:, idx] @ basis.T for e, (idx, basis) in bases.items()}
        f = np.broadcast_to(pose_frames(machine, model, table.axes, errs), (len(P), rows, 9))
        if not np.isfinite(f).all():
            raise nonfinite
        return f

    def predict(P: np.ndarray) -> np.ndarray:            # (k, n) parameter sets -> (k, m)
        return _observed(frames(P), table.rotations)[:, mask]

    chunk = max(1, _CHUNK // rows)                        # parameters per broadcast call: bounded memory

    def jacobian(p: np.ndarray) -> np.ndarray:           # (m + penalty rows, n), weighted
        eye = np.eye(n)
        d = np.concatenate([lsq.step_derivatives(frames, p, eye[i:i + chunk]) for i in range(0, n, chunk)])
        j = _observed_derivatives(frames(p[None])[0], d)[:, mask].T
        return np.vstack([w[:, None] * j, penalty])

    def residual(p: np.ndarray) -> np.ndarray:
        return np.concatenate([w * (y - predict(p[None])[0]), -penalty @ p])

    def report(text):
        if progress is not None and n * m > PROGRESS_SIZE:
            progress(text)

    report(f"{n} parameters, {data}: the Jacobian and its rank")
    p = np.zeros(n)
    zero = {e: np.zeros((1, n))[:, idx] @ basis.T for e, (idx, basis) in bases.items()}
    with np.errstate(all="ignore"):
        start = np.broadcast_to(pose_frames(machine, model, table.axes, zero), (1, rows, 9))[0]
    bad = np.flatnonzero(~np.isfinite(start).all(axis=1))
    if bad.size:   # the model itself, before any fit: name the set-up rather than blame the fit
        r = int(bad[0])
        at = ", ".join(f"{s.name} = {s.from_internal(table.axes[s.name][r]):g} {s.unit.name}" for s in machine.axes)
        raise ChaincompError(f"the model's tool pose is not finite at this set-up ({at}) with every error zero "
                             f"({count(bad.size, 'set-up')} of {rows}): the machine's expressions leave their domain "
                             "there (e.g. sqrt or acos of an axis beyond its limits)", table.file, table.lines[r])
    j0 = jacobian(p)                                      # first-order gains at these set-ups
    rank, basis, unidentifiable, redundant, carried, suggested = _analyse(j0, params, measured, prefer, minimal)
    report(f"rank {rank}; Gauss-Newton on the exact model")
    if rank == 0:
        raise ChaincompError(f"none of the {n} parameters fitted moves the {data}: nothing to identify",
                             table.file)
    ident = [j for j in range(n) if names[j] not in unidentifiable and names[j] not in redundant]
    if not ident:
        raise ChaincompError(f"no error can be identified from these {data}: the {n} parameters fitted "
                             f"move them only in {count(rank, 'combination')} that isolate{'s' if rank == 1 else ''} "
                             f"none of them; "
                             f"measure more coordinates or set-ups, assume errors zero (--assume-zero), "
                             f"or fit a minimal set (--minimal)", table.file)
    if not sig and m <= rank:
        raise ChaincompError(f"no redundancy: {data} for {count(rank, 'independent unknown')}, nothing "
                             f"left to estimate the uncertainty from; measure more, or give --sigma", table.file)

    robust = np.ones(m)                                   # Huber's weights per coordinate (IRLS); 1: squares

    def reweighted(r: np.ndarray, j: np.ndarray):
        """The rows of the data times the square root of Huber's weights at these residuals."""
        if huber is not None:
            scale = 1.0 if sig else lsq.MAD_SCALE * float(np.median(np.abs(r[:m])))
            robust[:] = lsq.huber_weights(r[:m] / max(scale, 1e-300), huber)
        f = np.concatenate([np.sqrt(robust), np.ones(len(r) - m)])
        return f * r, f[:, None] * j

    yw = np.linalg.norm(w * y)

    def linearise(z: np.ndarray):
        p = basis @ z
        return reweighted(residual(p), jacobian(p) @ basis)

    def small(dz, z, jz):
        # done when the step is negligible against the estimates or below the coordinates' precision
        return np.linalg.norm(dz) <= 1e-10 * np.linalg.norm(z) or np.linalg.norm(jz @ dz) <= 1e-14 * yw

    def iterated(iteration, r):
        report(f"iteration {iteration}: weighted rms residual {np.linalg.norm(r) / math.sqrt(len(r)):.4g}")

    # p = basis @ z throughout, from p = 0
    z, iterations, converged = lsq.gauss_newton(linearise, np.zeros(rank), max_iterations, small, iterated)
    p = basis @ z
    full = residual(p)
    unweighted = full[:m]                                 # weighted by 1/sigma only
    r, jz = reweighted(full, jacobian(p) @ basis)
    r = r[:m]
    rss = float(r @ r)
    inv, sv = lsq.svd_inverse(jz)                         # jz has full column rank
    if len(penalty):          # effective number of parameters: the trace of the data's hat matrix
        jd = jz[:m]
        dof = float(m - np.trace(jd @ inv @ jd.T))
    else:
        dof = m - rank
    var = 1.0 if sig else lsq.residual_variance(r, dof)
    cov = var * basis @ inv @ basis.T
    std = np.sqrt(np.abs(np.diag(cov)))
    corr = lsq.strong_correlations(cov, std, names, ident)
    raw = (y - predict(p[None])[0])
    kinds = np.broadcast_to(np.arange(9) // 3, mask.shape)[mask]     # 0 point, 1 direction, 2 orientation

    def rms(sel):
        return math.sqrt(float(np.mean(raw[sel] ** 2))) if sel.any() else math.nan

    # each set-up's weighted residual (its coordinates in y = obs[mask] are row-major), largest first
    per_setup = np.sqrt(np.bincount(np.nonzero(mask)[0], weights=r ** 2, minlength=len(table.lines)))
    worst = [(table.lines[i], float(per_setup[i])) for i in np.argsort(-per_setup, kind="stable")[:3]]

    fit = Fit(machine, free, [s.name for s in machine.errors if s.name in assume_zero],
              {names[j]: float(p[j]) for j in ident}, {names[j]: float(std[j]) for j in ident},
              unidentifiable, suggested, rank, float(sv[0] / sv[-1]), corr,
              rms(kinds == 0), m, len(table.lines), dof, iterations, converged, measured,
              params, varies, ranges, minimal, redundant, carried, sig,
              rss / dof if sig else None, rms(kinds == 1), smooth, notes, rms(kinds == 2), worst)
    if not all(math.isfinite(v) for v in [*fit.estimates.values(), *fit.uncertainties.values(),
                                          fit.condition, dof]):
        raise nonfinite
    if not dof > 0:
        raise ChaincompError(f"no redundancy: {data} leave no degrees of freedom", table.file)
    if huber is not None:
        fit.huber = huber
        scale = 1.0 if sig else lsq.MAD_SCALE * float(np.median(np.abs(unweighted)))   # as reweighted() took it
        rows_, cols_ = np.nonzero(mask)
        fit.outliers = sorted(((table.lines[rows_[i]], OBSERVED[cols_[i]], float(unweighted[i] / scale),
                                float(robust[i])) for i in np.flatnonzero(robust < 1)), key=lambda o: -abs(o[2]))
    fit.misfit = misfit(fit)
    fit.residuals_before, fit.residuals_after = np.full(obs.shape, math.nan), np.full(obs.shape, math.nan)
    fit.residuals_before[mask] = y - predict(np.zeros((1, n)))[0]
    fit.residuals_after[mask] = raw
    fit.correlation = lsq.correlation_matrix(cov[np.ix_(ident, ident)], std[ident])
    return fit


def _analyse(j0: np.ndarray, params: list[Param], measured: list[str], prefer, minimal: bool):
    """What the first-order Jacobian ``j0`` (weighted) tells: its rank (columns scaled to unit
    norm), the basis p = basis @ z of the fit's parameter space (the combinations the data see,
    or the minimal set), the unidentifiable parameters with the reason, the ones held at zero
    outside the minimal set with the combination that carries them, and a suggested set to
    assume zero."""
    names = [p.name for p in params]
    n = len(params)
    g = lsq.scaled_columns(j0)
    cols, d, s, vt, rank = g.cols, g.scale, g.s, g.vt, g.rank
    unseen = sorted(set(range(n)) - set(cols.tolist()))
    unidentifiable = {names[j]: f"does not move the measured coordinates ({', '.join(measured)}) at any of "
                                f"these set-ups" for j in unseen}
    basis = np.zeros((n, rank))
    if rank == 0:
        return rank, basis, unidentifiable, {}, {}, []
    first = [k for name in prefer for k, j in enumerate(cols) if params[j].error == name]
    # s vt has the columns' lengths and angles of the scaled columns in (at most) n rows: cheaper to pivot
    kept = [int(cols[k]) for k in lsq.spanning(s[:, None] * vt[:len(s)], rank, first)]
    members: dict[str, list[int]] = {}
    for i, q in enumerate(params):
        members.setdefault(q.error, []).append(i)
    redundant, carried = {}, {}
    if minimal:
        others = [int(j) for j in cols if j not in kept]
        if others:
            c = lsq.solve(j0[:, kept], j0[:, others])      # one solve for all of them
            norms = np.linalg.norm(j0[:, kept], axis=0)
            for col, j in enumerate(others):
                redundant[names[j]], carried[names[j]] = _carried(params, members, kept, j, c[:, col], norms)
        basis[sorted(kept), np.arange(rank)] = d[sorted(kept)]      # the minimal set, scaled
        return rank, basis, unidentifiable, redundant, carried, []
    proj = g.null_projector()
    for k, j in enumerate(cols):
        if proj[k, k] > 1e-12:
            unidentifiable[names[j]] = _inseparable_reason(params, members, cols, proj, k, d)
    basis[cols] = d[cols, None] * vt[:rank].T                      # the combinations the data see
    return rank, basis, unidentifiable, redundant, carried, [names[j] for j in cols if j not in kept]


def _grouped(params: list[Param], members: dict[str, list[int]], pairs) -> list[tuple[str, float, str, str]]:
    """(name, coefficient, unit, short name) per term; a table whose knots all take part alike
    is one term, 'every knot of EXX' ("EXX's knots"): a constant the table carries.
    ``members``: each error's parameter indices."""
    out, done = [], set()
    coeff = dict(pairs)
    for i, x in pairs:
        if i in done:
            continue
        p = params[i]
        knots = members[p.error] if p.knot else [i]
        if len(knots) > 1 and all(k in coeff and abs(coeff[k] - x) <= 1e-6 * abs(x) for k in knots):
            out.append((f"every knot of {p.error}", x, p.unit, f"{p.error}'s knots"))
            done.update(knots)
        else:
            out.append((p.name, x, p.unit, p.name))
            done.add(i)
    return out


SHOWN = 8   # terms of a combination written out in a reason (JSON has them all)


def _listed(items: list[str]) -> str:
    more = len(items) - SHOWN
    return ", ".join(items[:SHOWN]) + (f" and {more} more" if more > 0 else "")


def _terms(terms) -> str:
    return _listed([f"{x:+.4g} {unit} in {name}" for name, x, unit, _ in terms])


def _carried(params: list[Param], members, kept: list[int], j: int, c: np.ndarray, norms: np.ndarray):
    """Parameter j, outside the minimal set: c, the change of the kept ones (internal units) that
    moves the measurements as a unit change of j does (first order), as text in declared units
    and as internal coefficients. ``norms``: the kept columns' lengths."""
    size = np.abs(c * norms)
    pairs = [(i, c[k] * params[j].to_internal / params[i].to_internal)
             for k, i in enumerate(kept) if size[k] > 1e-6 * size.max()]
    me = params[j]
    terms = _grouped(params, members, pairs)
    text = (f"to first order a change of 1 {me.unit} in {me.name} moves the measured coordinates as "
            f"{_terms(terms)} {'does' if len(pairs) == 1 else 'do'}: carried by "
            f"{_listed([short for *_, short in terms])}")
    return text, {params[i].name: float(x * params[i].to_internal / params[j].to_internal) for i, x in pairs}


def _inseparable_reason(params: list[Param], members, cols, proj, k, d) -> str:
    """'a change of 1 arcsec in A with -0.64 arcsec in B moves no measured coordinate'."""
    v = proj[:, k] * d[cols]          # a null vector through parameter k, unscaled internal units
    me = params[cols[k]]
    pairs = [(int(j), v[i] / v[k] * me.to_internal / params[j].to_internal) for i, j in enumerate(cols)
             if i != k and abs(proj[i, k]) > 1e-6 * proj[k, k]]
    terms = _grouped(params, members, pairs)
    return (f"cannot be told apart from {_listed([short for *_, short in terms])} at these set-ups: "
            f"a change of 1 {me.unit} in {me.name} with {_terms(terms)} moves no measured "
            f"coordinate (to first order)")


def held_values(machine, path: str | None, assume_zero=()) -> dict:
    """--hold P.yaml: the errors it gives, by name, internal units (a table along an axis as
    read); an error both held and assumed zero is refused."""
    if not path:
        return {}
    held = load_params(path, machine)
    constants = [n for n in held if machine.symbol(n).role != "error"]
    if constants:
        raise ChaincompError(f"--hold {path}: {constants[0]} is a constant of {machine.name}, not an error: --hold "
                             f"takes errors (a constant's value belongs in the machine file)")
    both = [n for n in held if n in assume_zero]
    if both:
        raise ChaincompError(f"--hold {path}: {both[0]} is also assumed zero (--assume-zero): give it once")
    if not held:
        raise ChaincompError(f"--hold {path}: the file gives no error of {machine.name}")
    return held


class HeldModel(ExactModel):
    """The exact model with some errors (or constants) held at given values, numbers or tables
    along an axis (internal units), whatever the caller passes for them: ``identify`` with these
    errors assumed zero and this model fits the others around the held values (--hold)."""

    def __init__(self, machine: Machine, held: dict):
        super().__init__(machine)
        self.held = dict(held)

    def frame(self, values: dict, backend: str = "numpy"):
        return super().frame({**values, **self.held}, backend)
