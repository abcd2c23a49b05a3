"""Error values from measured tool-tip coordinates: nonlinear least squares on the exact model.

Measurements are a CSV file (see ``read_table``): one row per set-up, one column per axis
and per measured coordinate. The fit is Gauss-Newton on the exact chain. Its Jacobian is
taken by the complex step (the derivative is the imaginary part of the chain evaluated at
an imaginary error, free of the cancellation that makes a difference quotient of 500 mm
coordinates lose eight digits and blur the rank), for all rows and all errors in one
broadcast call. Errors that these set-ups cannot separate (the first-order Jacobian, its
columns scaled to unit norm, has a null space touching them) stay out of the fit's
parameter space and are reported, not given a value; a fit in which no error is left, or
without the redundancy to estimate its own uncertainty, is refused.
"""

from __future__ import annotations

import csv
import math
from dataclasses import dataclass, field

import numpy as np

from .derive import COMPONENTS
from .errors import ChaincompError
from .expressions import MAX_LITERAL
from .machine import Machine
from .numeric import ExactModel
from .units import UNITS
from .yamlsource import read_text

_CSTEP = 1e-20    # complex step, internal units (mm, rad): any tiny value gives the same digits
_STEP = 1e-6      # central-difference step, where the chain cannot take complex values
_RANK_TOL = 1e-9  # singular values below this, relative to the largest, are zero
MAX_ROWS = 20_000  # set-ups in a file or a --setups spec: bounds the fit's memory (rows x errors)


@dataclass
class Table:
    """Rows of a measurement (or set-up) file, in internal units."""
    file: str
    axes: dict[str, np.ndarray]           # axis -> value per row
    coords: np.ndarray                    # (rows, 3) tool tip x, y, z; NaN where not measured
    lines: list[int]                      # line of each row in the file
    columns: list[str] = field(default_factory=list)

    @property
    def measured(self) -> list[str]:
        return [c for i, c in enumerate(COMPONENTS) if not np.isnan(self.coords[:, i]).all()]


def coordinate_named_axes(machine: Machine) -> list:
    """Axes named like a measured coordinate (x, y, z): a column of that name would mean both."""
    return [s for s in machine.axes if s.name in COMPONENTS]


def read_table(path: str, machine: Machine, coords_required: bool = True) -> Table:
    """Read a CSV: '#' comments and blank lines skipped; a header naming every axis of the
    machine (values in each axis' declared unit) and any of x, y, z (tool-tip coordinates in
    the machine's length unit; an empty cell is a coordinate not measured in that row).
    Names are matched exactly as spelt: axis X and coordinate x are different columns."""
    axes = [s.name for s in machine.axes]
    length = UNITS[machine.length_unit].to_internal
    text = read_text(path).removeprefix("\ufeff")     # the byte-order mark spreadsheets write
    header, rows, lines = None, [], []
    for lineno, raw in enumerate(text.split("\n"), 1):
        raw = raw.rstrip("\r")
        if not raw.strip() or raw.lstrip().startswith("#"):
            continue
        try:
            cells = [c.strip() for c in next(csv.reader([raw]))]
        except csv.Error as exc:   # e.g. a field past the csv module's limit of 131072 characters
            raise ChaincompError(f"unreadable CSV row: {exc}", path, lineno) from None
        if header is None:
            header = _header(cells, machine, coords_required, path, lineno)
            continue
        if len(cells) != len(header):
            raise ChaincompError(f"expected {len(header)} values ({', '.join(header)}), got {len(cells)}",
                                 path, lineno)
        if len(rows) == MAX_ROWS:
            raise ChaincompError(f"more than {MAX_ROWS} rows", path, lineno)
        row = {}
        for name, cell in zip(header, cells):
            if cell == "" and name in COMPONENTS:
                row[name] = math.nan
                continue
            try:
                value = float(cell)
            except ValueError:
                value = math.nan
            if not abs(value) <= MAX_LITERAL:
                raise ChaincompError(f"expected a number of magnitude at most {MAX_LITERAL:g}, got {cell!r}"
                                     if math.isfinite(value) else f"expected a number, got {cell!r}",
                                     path, lineno, name)
            row[name] = value
        rows.append(row)
        lines.append(lineno)
    if header is None or not rows:
        raise ChaincompError("no measurements: expected a header row and at least one data row", path)
    table = Table(path, {a: np.array([machine.symbol(a).to_internal(r[a]) for r in rows]) for a in axes},
                  np.array([[r.get(c, math.nan) * length for c in COMPONENTS] for r in rows]),
                  lines, header)
    if coords_required and np.isnan(table.coords).all():
        raise ChaincompError("no measured coordinate: every x, y, z cell is empty", path)
    return table


def _header(cells, machine, coords_required, path, lineno) -> list[str]:
    axes = [s.name for s in machine.axes]
    header = []
    for cell in cells:
        if cell in axes and cell in COMPONENTS:
            raise ChaincompError(f"column {cell!r} is ambiguous: it is both the axis {cell} "
                                 f"({machine.file}:{machine.symbol(cell).line}) and the measured tool-tip "
                                 f"coordinate {cell}; rename the axis in the machine file", path, lineno, "header")
        if cell not in axes and cell not in COMPONENTS:
            near = [n for n in axes + list(COMPONENTS) if n.lower() == cell.lower()]
            raise ChaincompError(f"unknown column {cell!r} (expected the axes {', '.join(axes)} and "
                                 f"measured coordinates x, y, z)"
                                 + (f"; names are case-sensitive: did you mean {near[0]!r}?" if near else ""),
                                 path, lineno, "header")
        if cell in header:
            raise ChaincompError(f"column {cell!r} appears twice", path, lineno, "header")
        header.append(cell)
    for a in axes:
        if a not in header:
            raise ChaincompError(f"missing column for axis {a} (every axis of the machine needs one)",
                                 path, lineno, "header")
    if coords_required and not any(c in header for c in COMPONENTS):
        raise ChaincompError("no measured coordinate column (x, y or z)", path, lineno, "header")
    return header


def write_table(path: str, machine: Machine, axes: dict[str, np.ndarray], coords: np.ndarray,
                measure, comments=()) -> None:
    """Write measurements in the format ``read_table`` reads (full float precision)."""
    length = UNITS[machine.length_unit].to_internal
    names = [s.name for s in machine.axes]
    idx = [COMPONENTS.index(c) for c in measure]
    with open(path, "w", encoding="utf-8") as f:
        for c in comments:
            f.write(f"# {c}\n")
        f.write(",".join(names + list(measure)) + "\n")
        for r in range(coords.shape[0]):
            cells = [f"{machine.symbol(a).from_internal(axes[a][r]):.15g}" for a in names]
            cells += [f"{coords[r, i] / length:.17g}" for i in idx]
            f.write(",".join(cells) + "\n")


def pose_points(machine: Machine, model: ExactModel, axes: dict[str, np.ndarray], errors: dict) -> np.ndarray:
    """Tool points (..., rows, 3) for error values that may carry leading dimensions."""
    values = machine.nominal_values()
    values.update(axes)
    values.update(errors)
    point, _ = model.pose(values)
    shape = np.broadcast_shapes(*[np.shape(v) for v in point])
    return np.stack([np.broadcast_to(v, shape) for v in point], axis=-1)


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


@dataclass
class Fit:
    machine: Machine
    fitted: list[str]                      # errors in the fit (not assumed zero), machine order
    assumed_zero: list[str]
    estimates: dict[str, float]            # identifiable errors, internal units
    uncertainties: dict[str, float]        # standard uncertainties, internal units
    unidentifiable: dict[str, str]         # error -> reason
    suggested_zero: list[str]              # assumed zero as well, these leave every other one identifiable
    rank: int                              # independent combinations of the errors the data see
    condition: float
    correlations: list[tuple[str, str, float]]
    rms: float                             # rms residual, internal length
    observations: int
    setups: int
    dof: int
    iterations: int
    converged: bool
    measured: list[str]


def identify(machine: Machine, table: Table, assume_zero=(), sigma: float | None = None,
             max_iterations: int = 50, model: ExactModel | None = None) -> Fit:
    """Fit the errors of ``machine`` (all but ``assume_zero``) to the measured tool tips.
    ``model``: the machine's ExactModel, to reuse its compiled functions across fits.
    Raises ChaincompError when the data identify no error, leave no redundancy to estimate
    the uncertainty (without ``sigma``), or give non-finite values."""
    model = model or ExactModel(machine)
    free = [s.name for s in machine.errors if s.name not in assume_zero]
    if not free:
        raise ChaincompError("--assume-zero: every error is assumed zero, nothing is left to fit")
    mask = ~np.isnan(table.coords)
    y = table.coords[mask]
    n, m = len(free), int(mask.sum())
    measured = [c for i, c in enumerate(COMPONENTS) if mask[:, i].any()]
    data = f"{_count(m, 'coordinate')} ({', '.join(measured)}) at {_count(len(table.lines), 'set-up')}"
    nonfinite = ChaincompError(f"the fit went to non-finite values on these {data} (coordinates in "
                               f"{machine.length_unit}? axes in their declared units?)", table.file)

    def predict(P: np.ndarray) -> np.ndarray:            # (k, n) parameter sets -> (k, m)
        errs = {name: P[:, j:j + 1] for j, name in enumerate(free)}
        f = pose_points(machine, model, table.axes, errs)[:, mask]
        if not np.isfinite(f).all():
            raise nonfinite
        return f

    def jacobian(p: np.ndarray) -> np.ndarray:           # (m, n)
        try:
            return predict(p + 1j * _CSTEP * np.eye(n)).imag.T / _CSTEP
        except TypeError:      # numpy has no complex arctan2: an error inside atan2
            f = predict(np.vstack([p + _STEP * np.eye(n), p - _STEP * np.eye(n)]))
            return ((f[:n] - f[n:]) / (2 * _STEP)).T

    p = np.zeros(n)
    j0 = jacobian(p)                                      # first-order gains at these set-ups
    scale = np.linalg.norm(j0, axis=0)
    visible = scale > 1e-12 * max(scale.max(initial=0.0), 1e-300)
    unidentifiable = {}
    for j in np.flatnonzero(~visible):
        unidentifiable[free[j]] = (f"does not move the measured coordinates ({', '.join(measured)}) "
                                   f"at any of these set-ups")
    cols = np.flatnonzero(visible)
    d = np.zeros(n)
    d[cols] = 1.0 / scale[cols]
    scaled = j0[:, cols] * d[cols]
    s, vt = np.zeros(0), np.zeros((0, 0))
    if len(cols):
        # with fewer data than errors the reduced vt lacks part of the null space; only then is
        # the full one needed (and small: U is data x data)
        _, s, vt = np.linalg.svd(scaled, full_matrices=len(scaled) < len(cols))
    rank = int((s > _RANK_TOL * s[0]).sum()) if len(s) else 0
    if rank == 0:
        raise ChaincompError(f"none of the {n} errors fitted moves the {data}: nothing to identify", table.file)
    null = vt[rank:]
    proj = null.T @ null        # projector on the null space: its blocks do not depend on the basis
    for k, j in enumerate(cols):
        if proj[k, k] > 1e-12:
            unidentifiable[free[j]] = _inseparable_reason(machine, free, cols, proj, k, d)
    ident = [j for j in range(n) if free[j] not in unidentifiable]
    if not ident:
        raise ChaincompError(f"no error can be identified from these {data}: the {n} errors fitted "
                             f"move them only in {_count(rank, 'combination')} that isolate{'s' if rank == 1 else ''} "
                             f"none of them; "
                             f"measure more coordinates or set-ups, or assume errors zero (--assume-zero)",
                             table.file)
    if sigma is None and m <= rank:
        raise ChaincompError(f"no redundancy: {data} for {_count(rank, 'independent unknown')}, nothing "
                             f"left to estimate the uncertainty from; measure more, or give --sigma", table.file)
    kept = set(cols[_spanning(scaled, rank)])
    suggested = [free[j] for j in cols if j not in kept]
    basis = np.zeros((n, rank))                           # p = basis @ z: the combinations the data see
    basis[cols] = d[cols, None] * vt[:rank].T

    iterations, converged = 0, False
    for iterations in range(1, max_iterations + 1):
        r = y - predict(p[None])[0]
        jz = jacobian(p) @ basis
        dz = np.linalg.lstsq(jz, r, rcond=None)[0]
        p = p + basis @ dz
        z = np.linalg.lstsq(basis, p, rcond=None)[0]
        # done when the step is negligible against the estimates or below the coordinates' precision
        if (np.linalg.norm(dz) <= 1e-10 * np.linalg.norm(z)
                or np.linalg.norm(jz @ dz) <= 1e-14 * np.linalg.norm(y)):
            converged = True
            break
    r = y - predict(p[None])[0]
    jz = jacobian(p) @ basis
    rss = float(r @ r)
    dof = m - rank
    var = sigma ** 2 if sigma is not None else rss / dof
    sv = np.linalg.svd(jz, compute_uv=False)
    cov = var * basis @ np.linalg.pinv(jz.T @ jz) @ basis.T
    std = np.sqrt(np.abs(np.diag(cov)))
    corr = []
    for a_, b_ in ((a, b) for i, a in enumerate(ident) for b in ident[i + 1:]):
        if std[a_] > 0 and std[b_] > 0:
            c = cov[a_, b_] / (std[a_] * std[b_])
            if abs(c) > 0.9:
                corr.append((free[a_], free[b_], float(c)))
    fit = Fit(machine, free, [s.name for s in machine.errors if s.name in assume_zero],
              {free[j]: float(p[j]) for j in ident}, {free[j]: float(std[j]) for j in ident},
              unidentifiable, suggested, rank, float(sv[0] / sv[-1]), corr,
              math.sqrt(rss / m), m, len(table.lines), dof, iterations, converged, measured)
    if not all(math.isfinite(v) for v in [*fit.estimates.values(), *fit.uncertainties.values(),
                                          fit.condition, fit.rms]):
        raise nonfinite
    return fit


def _count(k: int, what: str) -> str:
    return f"{k} {what}{'' if k == 1 else 's'}"


def _spanning(a: np.ndarray, rank: int) -> list[int]:
    """``rank`` columns of ``a`` that span its column space, picked greedily, each time the one
    least explained by those already picked (QR with column pivoting)."""
    a = a.copy()
    picked = []
    for _ in range(rank):
        j = int(np.argmax(np.linalg.norm(a, axis=0)))
        q = a[:, j] / np.linalg.norm(a[:, j])
        a -= np.outer(q, q @ a)
        picked.append(j)
    return picked


def _inseparable_reason(machine, free, cols, proj, k, d) -> str:
    """'a change of 1 arcsec in A with -0.64 arcsec in B moves no measured coordinate'."""
    v = proj[:, k] * d[cols]          # a null vector through error k, unscaled internal units
    me = machine.symbol(free[cols[k]])
    pairs = [(machine.symbol(free[j]), v[i]) for i, j in enumerate(cols)
             if i != k and abs(proj[i, k]) > 1e-6 * proj[k, k]]
    others = [o for o, _ in pairs]
    parts = [f"{x / v[k] * me.unit.to_internal / o.unit.to_internal:+.4g} {o.unit.name} in {o.name}"
             for o, x in pairs]
    return (f"cannot be told apart from {', '.join(o.name for o in others)} at these set-ups: "
            f"a change of 1 {me.unit.name} in {me.name} with {', '.join(parts)} moves no measured "
            f"coordinate (to first order)")


# ----------------------------------------------------------------------------- reports

def _declared(machine, name, value):
    return machine.symbol(name).from_internal(value)


def to_json(fit: Fit, source: str) -> dict:
    m = fit.machine
    lu = UNITS[m.length_unit].to_internal
    return {
        "machine": m.name, "measurements": source, "setups": fit.setups, "observations": fit.observations,
        "measured": fit.measured, "fitted": fit.fitted, "assumed_zero": fit.assumed_zero,
        "estimates": {n: {"value": _declared(m, n, v), "uncertainty": _declared(m, n, fit.uncertainties[n]),
                          "unit": m.symbol(n).unit.name} for n, v in fit.estimates.items()},
        "unidentifiable": fit.unidentifiable,
        "suggested_assume_zero": fit.suggested_zero, "rank": fit.rank,
        "condition_number": fit.condition,
        "correlations": [{"errors": [a, b], "value": c} for a, b, c in fit.correlations],
        "rms_residual": fit.rms / lu, "length_unit": m.length_unit,
        "degrees_of_freedom": fit.dof, "iterations": fit.iterations, "converged": fit.converged,
    }


def to_text(fit: Fit, source: str) -> str:
    m = fit.machine
    lu = UNITS[m.length_unit].to_internal
    lines = [f"identify {m.name} from {source}: {fit.observations} coordinates "
             f"({', '.join(fit.measured)}) at {fit.setups} set-ups; {len(fit.fitted)} errors fitted"
             + (f" (the data see {fit.rank} independent combinations of them)"
                if fit.rank < len(fit.fitted) else "")
             + (f", assumed zero: {', '.join(fit.assumed_zero)}" if fit.assumed_zero else ""),
             f"{'converged' if fit.converged else 'NOT converged'} after {fit.iterations} Gauss-Newton "
             f"iterations on the exact model; rms residual {fit.rms / lu:.4g} {m.length_unit}; "
             f"{fit.dof} degrees of freedom",
             f"  {'error':<12} {'estimate':>16}   {'std. uncertainty':>16}"]
    for n, v in fit.estimates.items():
        unit = m.symbol(n).unit.name
        lines.append(f"  {n:<12} {_declared(m, n, v):>16.8g}   {_declared(m, n, fit.uncertainties[n]):>16.3g}"
                     f" {unit}")
    lines.append(f"condition number {fit.condition:.4g} (Jacobian columns scaled to unit norm)")
    lines.append("correlations above 0.9: " + (", ".join(f"{a}/{b} {c:+.3f}" for a, b, c in fit.correlations)
                                                 or "none"))
    if fit.unidentifiable:
        lines.append("not identifiable from these set-ups (no value given):")
        lines += [f"  {n}: {why}" for n, why in fit.unidentifiable.items()]
    if fit.suggested_zero:
        lines.append("to give every other error a value, assume these zero as well (one choice of many): "
                     "--assume-zero " + ",".join(fit.assumed_zero + fit.suggested_zero))
    return "\n".join(lines)


def params_yaml(fit: Fit, source: str) -> str:
    """A params file (machine + values as 'VALUE UNIT') that load_params and chaincompd read."""
    m = fit.machine
    out = [f"# Error values identified by chaincomp identify from {source}:",
           f"# {fit.observations} coordinates at {fit.setups} set-ups, rms residual "
           f"{fit.rms / UNITS[m.length_unit].to_internal:.4g} {m.length_unit}, "
           f"condition number {fit.condition:.4g}."]
    if fit.unidentifiable:
        out.append(f"# Not identifiable, no value given: {', '.join(fit.unidentifiable)}.")
    out += [f"machine: {m.name}", "values:"]
    for s in m.errors:
        if s.name in fit.estimates:
            u = s.from_internal(fit.uncertainties[s.name])
            out.append(f'  {s.name}: "{s.from_internal(fit.estimates[s.name]):.12g} {s.unit.name}"'
                       f"   # standard uncertainty {u:.3g} {s.unit.name}")
        elif s.name in fit.assumed_zero:
            out.append(f'  {s.name}: "0 {s.unit.name}"   # assumed zero')
    return "\n".join(out) + "\n"
