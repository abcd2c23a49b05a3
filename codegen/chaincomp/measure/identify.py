"""Error values from measured tool-tip coordinates: nonlinear least squares on the exact model.

Measurements are a CSV file (see ``read_table``): one row per set-up, one column per axis
and per measured coordinate (tool point x, y, z; tool direction kx, ky, kz; with a tool frame
its orientation as a unit quaternion qw, qx, qy, qz). The fit is Gauss-Newton on the exact
chain, each coordinate weighted by its standard uncertainty; a measured orientation enters as
the rotation vector ω = log(R_measured·R_modelᵀ) (chaincomp.orientation: about the base
frame's axes), the rows wx, wy, wz. Its Jacobian is taken by the complex step (the derivative
is the imaginary part of the chain evaluated at an imaginary error, free of the cancellation
that makes a difference quotient of 500 mm coordinates lose eight digits and blur the rank),
for all rows and all parameters in one broadcast call (``step_derivatives``).

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
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass, field

import numpy as np

from ..errors import ChaincompError
from ..escape import one_line
from ..model import csvtable
from ..model.display import DEFAULT_UNITS, display_unit, plus_minus, quantity
from ..model.expressions import MAX_LITERAL
from ..model.machine import Machine
from ..model.params import load_params
from ..model.units import INTERNAL, UNITS
from ..model.varying import MAX_POLYNOMIAL_COEFFICIENTS, MAX_TABLE_KNOTS, MAX_VARYING_ERRORS, Varying
from ..model.yamlsource import read_text
from ..output import write_file
from ..symbolic.derive import COMPONENTS
from ..symbolic.numeric import ExactModel
from ..symbolic.orientation import ROWS as ROTATION, cross, rotation_vector

CSTEP = 1e-20     # complex step, internal units (mm, rad): any tiny value gives the same digits
STEP = 1e-6       # central-difference step, where the chain cannot take complex values
_RANK_TOL = 1e-9  # singular values below this, relative to the largest, are zero
MAX_ROWS = 20_000  # set-ups in a file or a --setups spec: bounds the fit's memory (rows x errors)
MAX_JACOBIAN = 5_000_000    # measured coordinates x parameters (40 MB a copy): bounds the fit's memory and time
MAX_PARAMETERS = 1000       # the rank analysis holds parameters x parameters (8 MB)
_CHUNK = 1_000_000          # parameter sets x rows evaluated in one broadcast call of the chain
# The smoothing weight (per squared second difference in the error's declared unit): at 1e12 a
# table is already a straight line to a millionth of a unit; larger weights only swamp the data's
# rows in rounding (at 1e200 the fit saw one combination, at 1e306 none).
MAX_SMOOTH = 1e12
PROGRESS_SIZE = 1_000_000   # parameters x coordinates above which a fit reports its stages (seconds)
_TIE = 1e-9       # pivoted QR: columns this close (relative) to the largest remaining norm tie
DIRECTIONS = ("kx", "ky", "kz")       # measured tool direction (unit vector components)
QUATERNION = ("qw", "qx", "qy", "qz")  # measured tool frame orientation (unit quaternion, scalar first)
COLUMNS = COMPONENTS + DIRECTIONS + QUATERNION     # every measured column a file may have
# every observed component, in the order of Table.observations: a measured orientation is
# observed as the three components of its rotation vector residual (wx, wy, wz)
OBSERVED = COMPONENTS + DIRECTIONS + ROTATION
_NORM_TOL = 0.01  # a measured direction whose three components are given is a unit vector to 1 %
# a measured quaternion is a unit one to 1e-3 (rounded to 4 decimals it is within 1e-4), then
# normalised; beyond that it is more likely a wrong column or another convention than rounding
_QUAT_TOL = 1e-3


def step_derivatives(f, p: np.ndarray, steps: np.ndarray) -> np.ndarray:
    """d/dt f(p + t·s) at t = 0 for each row s of ``steps``: (len(steps), ...) by the complex step
    (f evaluated once at p + i·CSTEP·steps, a row per step), or by central differences where f
    cannot take complex values (numpy has no complex arctan2: an error inside atan2)."""
    try:
        return f(p + 1j * CSTEP * steps).imag / CSTEP
    except TypeError:
        both = f(np.vstack([p + STEP * steps, p - STEP * steps]))
        return (both[:len(steps)] - both[len(steps):]) / (2 * STEP)


def quaternion_matrix(q: np.ndarray) -> np.ndarray:
    """(..., 3, 3) rotation matrices of unit quaternions (..., 4) qw, qx, qy, qz (Hamilton,
    scalar first): the columns are the rotated frame's x, y, z axes."""
    w, x, y, z = np.moveaxis(np.asarray(q, float), -1, 0)
    return np.stack([
        np.stack([1 - 2 * (y * y + z * z), 2 * (x * y + w * z), 2 * (x * z - w * y)], -1),
        np.stack([2 * (x * y - w * z), 1 - 2 * (x * x + z * z), 2 * (y * z + w * x)], -1),
        np.stack([2 * (x * z + w * y), 2 * (y * z - w * x), 1 - 2 * (x * x + y * y)], -1)], -1)


def matrix_quaternion(r: np.ndarray) -> np.ndarray:
    """(..., 4) unit quaternions qw, qx, qy, qz (qw >= 0) of rotation matrices (..., 3, 3), the
    inverse of quaternion_matrix (Shepperd: from the largest of the four squares)."""
    r = np.asarray(r, float)
    t = np.stack([1 + r[..., 0, 0] + r[..., 1, 1] + r[..., 2, 2], 1 + r[..., 0, 0] - r[..., 1, 1] - r[..., 2, 2],
                  1 - r[..., 0, 0] + r[..., 1, 1] - r[..., 2, 2], 1 - r[..., 0, 0] - r[..., 1, 1] + r[..., 2, 2]], -1)
    k = np.argmax(t, axis=-1)[..., None]
    s = np.sqrt(np.maximum(np.take_along_axis(t, k, -1), 1e-300)) * 2        # 4 |q_k|
    a = r[..., 2, 1] - r[..., 1, 2]   # 4 w x
    b = r[..., 0, 2] - r[..., 2, 0]   # 4 w y
    c = r[..., 1, 0] - r[..., 0, 1]   # 4 w z
    d = r[..., 0, 1] + r[..., 1, 0]   # 4 x y
    e = r[..., 0, 2] + r[..., 2, 0]   # 4 x z
    f = r[..., 1, 2] + r[..., 2, 1]   # 4 y z
    tk = np.take_along_axis(t, k, -1)[..., 0]
    cand = np.stack([np.stack([tk, a, b, c], -1), np.stack([a, tk, d, e], -1),
                     np.stack([b, d, tk, f], -1), np.stack([c, e, f, tk], -1)], -2)
    q = np.take_along_axis(cand, k[..., None], -2)[..., 0, :] / s
    return q * np.where(q[..., :1] < 0, -1.0, 1.0)


def numeric_rank(singular_values: np.ndarray) -> int:
    """How many singular values (largest first) are not zero at _RANK_TOL relative to the largest."""
    s = singular_values
    return int((s > _RANK_TOL * s[0]).sum()) if len(s) else 0


@dataclass
class Table:
    """Rows of a measurement (or set-up) file, in internal units."""
    file: str
    axes: dict[str, np.ndarray]           # axis -> value per row
    coords: np.ndarray                    # (rows, 3) tool tip x, y, z; NaN where not measured
    lines: list[int]                      # line of each row in the file
    columns: list[str] = field(default_factory=list)
    directions: np.ndarray | None = None  # (rows, 3) tool direction kx, ky, kz; NaN where not measured
    rotations: np.ndarray | None = None   # (rows, 3, 3) measured tool frame (columns x, y, z); NaN where not

    @property
    def observations(self) -> np.ndarray:
        """(rows, 9): x, y, z, kx, ky, kz and wx, wy, wz; NaN where not measured. An orientation
        is observed through its residual ω = log(R_measured·R_modelᵀ), whose measured value is 0."""
        nan = np.full_like(self.coords, math.nan)
        d = self.directions if self.directions is not None else nan
        w = nan if self.rotations is None else np.where(np.isnan(self.rotations[:, :, 0]), math.nan, 0.0)
        return np.concatenate([self.coords, d, w], axis=1)

    @property
    def measured(self) -> list[str]:
        return [c for i, c in enumerate(OBSERVED) if not np.isnan(self.observations[:, i]).all()]


def coordinate_named_axes(machine: Machine) -> list:
    """Axes named like a measured coordinate (x, y, z): a column of that name would mean both."""
    return [s for s in machine.axes if s.name in COMPONENTS]


def measured_columns(machine: Machine) -> tuple[str, ...]:
    """The measured columns a file for ``machine`` may have: the tool direction only where the
    machine defines one, the orientation quaternion only where it defines a tool frame."""
    return COMPONENTS + (DIRECTIONS if machine.tool_direction is not None else ()) \
        + (QUATERNION if machine.tool_reference is not None else ())


def read_table(path: str, machine: Machine, coords_required: bool = True) -> Table:
    """Read a CSV: '#' comments and blank lines skipped; a header naming every axis of the
    machine (values in each axis' declared unit) and any of x, y, z (tool-tip coordinates in
    the machine's length unit) and kx, ky, kz (the measured tool direction, components of a unit
    vector, where the machine has a tool direction) and qw, qx, qy, qz (the measured tool frame's
    orientation in the base frame as a unit quaternion, Hamilton, scalar first: R(q)'s columns
    are the frame's x, y, z axes; where the machine has a tool frame); an empty cell is a
    coordinate not measured in that row (a quaternion is measured whole or not at all). Names
    are matched exactly as spelt: axis X and coordinate x are different columns."""
    axes = [s.name for s in machine.axes]
    length = UNITS[machine.length_unit].to_internal
    data = csvtable.read(path, max_rows=MAX_ROWS)
    header = _header(data.header, machine, coords_required, path, data.line)
    rows, lines = [], []
    for r in data.rows:
        lineno = r.line
        row = {}
        for k, (name, cell) in enumerate(zip(header, r.cells)):
            if cell == "" and name not in axes:
                row[name] = math.nan
                continue
            value = data.number(r, k)
            if not abs(value) <= MAX_LITERAL:
                raise ChaincompError(f"expected a number of magnitude at most {MAX_LITERAL:g}, got {cell!r}",
                                     path, lineno, name)
            row[name] = value
        k = [row.get(c, math.nan) for c in DIRECTIONS]
        if not np.isnan(k).any() and not abs(math.sqrt(sum(v * v for v in k)) - 1) <= _NORM_TOL:
            raise ChaincompError(f"the measured tool direction (kx, ky, kz) = ({', '.join(f'{v:g}' for v in k)}) "
                                 f"is not a unit vector (length {math.sqrt(sum(v * v for v in k)):.4g})",
                                 path, lineno, "kx")
        _check_quaternion(row, header, path, lineno)
        rows.append(row)
        lines.append(lineno)
    if not rows:
        raise ChaincompError("no measurements: expected a header row and at least one data row", path)
    quats = np.array([[r.get(c, math.nan) for c in QUATERNION] for r in rows])
    quats /= np.linalg.norm(quats, axis=1, keepdims=True)            # NaN rows stay NaN
    table = Table(path, {a: np.array([machine.symbol(a).to_internal(r[a]) for r in rows]) for a in axes},
                  np.array([[r.get(c, math.nan) * length for c in COMPONENTS] for r in rows]),
                  lines, header, np.array([[r.get(c, math.nan) for c in DIRECTIONS] for r in rows]),
                  quaternion_matrix(quats) if any(c in header for c in QUATERNION) else None)
    if coords_required and np.isnan(table.observations).all():
        raise ChaincompError(f"no measured coordinate: every {', '.join(c for c in header if c in COLUMNS)} "
                             f"cell is empty", path)
    return table


def outside_limits(machine: Machine, table: Table, skip=()) -> list[str]:
    """'FILE:LINE: AXIS: ...' for each axis whose values in ``table`` leave its limits: the first
    such row and how many. Not refused (a file may hold set-ups from beyond soft limits), but a
    value far outside is often one written in another unit (rad for deg, m for mm)."""
    out = []
    for s in machine.axes:
        if s.name in skip:
            continue
        lo, hi = s.limits
        v = s.from_internal(table.axes[s.name])
        bad = np.flatnonzero((v < lo) | (v > hi))
        if bad.size:
            i = int(bad[0])
            out.append(f"{table.file}:{table.lines[i]}: {s.name}: {v[i]:g} {s.unit.name} is outside its limits "
                       f"[{lo:g}, {hi:g}] ({_count(bad.size, 'row')} of {len(v)}; "
                       f"{'is it' if bad.size == 1 else 'are they'} in {s.unit.name}?)")
    return out


def _check_quaternion(row: dict, header: list[str], path, lineno) -> None:
    """A measured quaternion: all four components or none, a unit one to _QUAT_TOL."""
    given = [c for c in QUATERNION if c in header and not math.isnan(row.get(c, math.nan))]
    if not given:
        return
    missing = [c for c in QUATERNION if c not in given]
    if missing:
        raise ChaincompError(f"the measured orientation needs all four quaternion components qw, qx, qy, qz: "
                             f"{', '.join(missing)} {'is' if len(missing) == 1 else 'are'} empty "
                             f"(leave all four empty where the orientation is not measured)", path, lineno, missing[0])
    q = [row[c] for c in QUATERNION]
    norm = math.sqrt(sum(v * v for v in q))
    if not abs(norm - 1) <= _QUAT_TOL:
        raise ChaincompError(f"the measured orientation (qw, qx, qy, qz) = ({', '.join(f'{v:g}' for v in q)}) is not "
                             f"a unit quaternion (norm {norm:.6g}, expected 1 within {_QUAT_TOL:g})",
                             path, lineno, "qw")


def _header(cells, machine, coords_required, path, lineno) -> list[str]:
    axes = [s.name for s in machine.axes]
    columns = measured_columns(machine)
    header = []
    if len(cells) == 1 and "|" in cells[0]:
        raise ChaincompError(f"the header is one cell {cells[0]!r}: columns are separated by commas, semicolons "
                             "or tabs, not '|' (export the sheet as comma-separated CSV)", path, lineno, "header")
    for cell in cells:
        named = re.fullmatch(r"(\S+)\s*[\[(].*[\])]", cell)
        if named and named.group(1) in axes + list(columns):
            n = named.group(1)
            read = (f"in its declared unit ({machine.symbol(n).unit.name})" if n in axes else
                    f"in the machine's length unit ({machine.length_unit})" if n in COMPONENTS else
                    "as a component of a unit vector or quaternion (no unit)")
            raise ChaincompError(f"column {cell!r}: the header holds names only, no units; {n} is read {read}: "
                                 f"write {n!r} and its values in that unit", path, lineno, "header")
        if cell in DIRECTIONS and cell not in columns and cell not in axes:
            raise ChaincompError(f"column {cell!r} is a measured tool direction, but {machine.name} has no tool "
                                 f"direction (tool: direction in {machine.file})", path, lineno, "header")
        if cell in QUATERNION and cell not in columns and cell not in axes:
            raise ChaincompError(f"column {cell!r} is a measured tool frame orientation, but {machine.name} has no "
                                 f"tool frame (tool: reference or rotation in {machine.file})", path, lineno, "header")
        if cell in axes and cell in columns:
            raise ChaincompError(f"column {cell!r} is ambiguous: it is both the axis {cell} "
                                 f"({machine.file}:{machine.symbol(cell).line}) and the measured tool-tip "
                                 f"coordinate {cell}; rename the axis in the machine file", path, lineno, "header")
        if cell not in axes and cell not in columns:
            near = [n for n in axes + list(columns) if n.lower() == cell.lower()]
            raise ChaincompError(f"unknown column {cell!r} (expected the axes {', '.join(axes)} and "
                                 f"measured coordinates {', '.join(columns)})"
                                 + (f"; names are case-sensitive: did you mean {near[0]!r}?" if near else ""),
                                 path, lineno, "header")
        if cell in header:
            raise ChaincompError(f"column {cell!r} appears twice", path, lineno, "header")
        header.append(cell)
    for a in axes:
        if a not in header:
            raise ChaincompError(f"missing column for axis {a} (every axis of the machine needs one)",
                                 path, lineno, "header")
    quat = [c for c in QUATERNION if c in header]
    if quat and len(quat) < 4:
        raise ChaincompError(f"the measured orientation needs all four quaternion columns qw, qx, qy, qz; "
                             f"missing {', '.join(c for c in QUATERNION if c not in header)}", path, lineno, "header")
    if quat and any(c in header for c in DIRECTIONS):
        raise ChaincompError("columns kx, ky, kz and qw, qx, qy, qz both measure the tool axis (the quaternion's "
                             "frame holds the direction as its z axis): give one of them", path, lineno, "header")
    if coords_required and not any(c in header for c in columns):
        raise ChaincompError(f"no measured coordinate column ({', '.join(columns)})", path, lineno, "header")
    return header


def write_table(path: str, machine: Machine, axes: dict[str, np.ndarray], coords: np.ndarray,
                measure, comments=(), quaternions: np.ndarray | None = None) -> None:
    """Write measurements in the format ``read_table`` reads (full float precision): the tool
    point coordinates in ``measure`` and, if given, the orientation quaternions (rows, 4)."""
    length = UNITS[machine.length_unit].to_internal
    names = [s.name for s in machine.axes]
    idx = [COMPONENTS.index(c) for c in measure]
    out = [f"# {one_line(c)}\n" for c in comments]
    out.append(",".join(names + list(measure) + (list(QUATERNION) if quaternions is not None else [])) + "\n")
    for r in range(coords.shape[0]):
        cells = [f"{machine.symbol(a).from_internal(axes[a][r]):.15g}" for a in names]
        cells += [f"{coords[r, i] / length:.17g}" for i in idx]
        cells += [f"{v:.17g}" for v in (quaternions[r] if quaternions is not None else ())]
        out.append(",".join(cells) + "\n")
    # beside it, then renamed: a full disk leaves no short file that identify would read as whole
    write_file(path, "".join(out))


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
                notes.append(f"{_count(out, 'set-up')} lie{'s' if out == 1 else ''} outside {name}'s knots "
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


HUBER_K = 1.345   # Huber's k: 95 % efficiency at normal residuals (Huber 1981; Holland & Welsch 1977)
MAD_SCALE = 1.4826  # median |r| of normal residuals times this is their standard deviation


def huber_weights(u: np.ndarray, k: float) -> np.ndarray:
    """IRLS weights of Huber's loss at standardized residuals u: 1 within k, k/|u| beyond
    (rho(u) = u^2/2 within k, k|u| - k^2/2 beyond; weight = rho'(u)/u)."""
    a = np.abs(u)
    return np.where(a <= k, 1.0, k / np.maximum(a, 1e-300))


MISFIT_PROBABILITY = 0.999   # chi2/dof beyond this quantile of its distribution: the fit does not fit


def chi2_quantile(probability: float, dof: float) -> float:
    """The chi-square distribution's quantile: x with P(X <= x) = probability for ``dof``
    degrees of freedom, from the regularized incomplete gamma function (mpmath), by bisection."""
    import mpmath

    def upper(x):  # P(X > x)
        return float(mpmath.gammainc(dof / 2, 0, x / 2, regularized=True))
    lo, hi = 0.0, max(1.0, dof)
    while upper(hi) < probability:
        hi *= 2
    for _ in range(200):
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if upper(mid) < probability else (lo, mid)
        if hi - lo <= 1e-12 * hi:
            break
    return 0.5 * (lo + hi)


def misfit(fit: Fit) -> str | None:
    """With --sigma, a chi2/dof beyond its MISFIT_PROBABILITY quantile says the residuals are larger
    than the given uncertainties allow: the words saying so and naming the worst set-ups; else None."""
    if fit.chi2 is None or not fit.dof > 0:
        return None
    limit = chi2_quantile(MISFIT_PROBABILITY, fit.dof) / fit.dof
    if fit.chi2 <= limit:
        return None
    worst = ", ".join(f"line {line} ({r:.3g} sigma)" for line, r in fit.worst)
    return (f"chi2/dof {fit.chi2:.3g} is beyond its {MISFIT_PROBABILITY:.1%} quantile for {fit.dof:.4g} degrees of "
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
    data = f"{_count(m, 'coordinate')} ({', '.join(measured)}) at {_count(len(table.lines), 'set-up')}"
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
        d = np.concatenate([step_derivatives(frames, p, eye[i:i + chunk]) for i in range(0, n, chunk)])
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
                             f"({_count(bad.size, 'set-up')} of {rows}): the machine's expressions leave their domain "
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
                             f"move them only in {_count(rank, 'combination')} that isolate{'s' if rank == 1 else ''} "
                             f"none of them; "
                             f"measure more coordinates or set-ups, assume errors zero (--assume-zero), "
                             f"or fit a minimal set (--minimal)", table.file)
    if not sig and m <= rank:
        raise ChaincompError(f"no redundancy: {data} for {_count(rank, 'independent unknown')}, nothing "
                             f"left to estimate the uncertainty from; measure more, or give --sigma", table.file)

    robust = np.ones(m)                                   # Huber's weights per coordinate (IRLS); 1: squares

    def reweighted(r: np.ndarray, j: np.ndarray):
        """The rows of the data times the square root of Huber's weights at these residuals."""
        if huber is not None:
            scale = 1.0 if sig else MAD_SCALE * float(np.median(np.abs(r[:m])))
            robust[:] = huber_weights(r[:m] / max(scale, 1e-300), huber)
        f = np.concatenate([np.sqrt(robust), np.ones(len(r) - m)])
        return f * r, f[:, None] * j

    iterations, converged = 0, False
    yw = np.linalg.norm(w * y)
    z = np.zeros(rank)                                    # p = basis @ z throughout (p starts at 0)
    for iterations in range(1, max_iterations + 1):
        r, jz = reweighted(residual(p), jacobian(p) @ basis)
        dz = np.linalg.lstsq(jz, r, rcond=None)[0]
        z = z + dz
        p = basis @ z
        report(f"iteration {iterations}: weighted rms residual {np.linalg.norm(r) / math.sqrt(len(r)):.4g}")
        # done when the step is negligible against the estimates or below the coordinates' precision
        if np.linalg.norm(dz) <= 1e-10 * np.linalg.norm(z) or np.linalg.norm(jz @ dz) <= 1e-14 * yw:
            converged = True
            break
    full = residual(p)
    unweighted = full[:m]                                 # weighted by 1/sigma only
    r, jz = reweighted(full, jacobian(p) @ basis)
    r = r[:m]
    rss = float(r @ r)
    _, sv, vz = np.linalg.svd(jz, full_matrices=False)
    inv = (vz.T / sv ** 2) @ vz                           # (jz' jz)^-1: jz has full column rank
    if len(penalty):          # effective number of parameters: the trace of the data's hat matrix
        jd = jz[:m]
        dof = float(m - np.trace(jd @ inv @ jd.T))
    else:
        dof = m - rank
    var = 1.0 if sig else rss / dof
    cov = var * basis @ inv @ basis.T
    std = np.sqrt(np.abs(np.diag(cov)))
    corr = []
    for a_, b_ in ((a, b) for i, a in enumerate(ident) for b in ident[i + 1:]):
        if std[a_] > 0 and std[b_] > 0:
            c = cov[a_, b_] / (std[a_] * std[b_])
            if abs(c) > 0.9:
                corr.append((names[a_], names[b_], float(c)))
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
        scale = 1.0 if sig else MAD_SCALE * float(np.median(np.abs(unweighted)))   # as reweighted() took it
        rows_, cols_ = np.nonzero(mask)
        fit.outliers = sorted(((table.lines[rows_[i]], OBSERVED[cols_[i]], float(unweighted[i] / scale),
                                float(robust[i])) for i in np.flatnonzero(robust < 1)), key=lambda o: -abs(o[2]))
    fit.misfit = misfit(fit)
    fit.residuals_before, fit.residuals_after = np.full(obs.shape, math.nan), np.full(obs.shape, math.nan)
    fit.residuals_before[mask] = y - predict(np.zeros((1, n)))[0]
    fit.residuals_after[mask] = raw
    s_ident = std[ident]
    with np.errstate(invalid="ignore", divide="ignore"):
        fit.correlation = np.nan_to_num(cov[np.ix_(ident, ident)] / np.outer(s_ident, s_ident))
    return fit


def _analyse(j0: np.ndarray, params: list[Param], measured: list[str], prefer, minimal: bool):
    """What the first-order Jacobian ``j0`` (weighted) tells: its rank (columns scaled to unit
    norm), the basis p = basis @ z of the fit's parameter space (the combinations the data see,
    or the minimal set), the unidentifiable parameters with the reason, the ones held at zero
    outside the minimal set with the combination that carries them, and a suggested set to
    assume zero."""
    names = [p.name for p in params]
    n = len(params)
    scale = np.linalg.norm(j0, axis=0)
    visible = scale > 1e-12 * max(scale.max(initial=0.0), 1e-300)
    unidentifiable = {names[j]: f"does not move the measured coordinates ({', '.join(measured)}) at any of "
                                f"these set-ups" for j in np.flatnonzero(~visible)}
    cols = np.flatnonzero(visible)
    d = np.zeros(n)
    d[cols] = 1.0 / scale[cols]
    scaled = j0[:, cols] * d[cols]
    s, vt = np.zeros(0), np.zeros((0, 0))
    if len(cols):
        # with fewer data than parameters the reduced vt lacks part of the null space; only then
        # is the full one needed (and small: U is data x data)
        _, s, vt = np.linalg.svd(scaled, full_matrices=len(scaled) < len(cols))
    rank = numeric_rank(s)
    basis = np.zeros((n, rank))
    if rank == 0:
        return rank, basis, unidentifiable, {}, {}, []
    first = [k for name in prefer for k, j in enumerate(cols) if params[j].error == name]
    # s vt has the columns' lengths and angles of ``scaled`` in (at most) n rows: cheaper to pivot
    kept = [int(cols[k]) for k in _spanning(s[:, None] * vt[:len(s)], rank, first)]
    members: dict[str, list[int]] = {}
    for i, q in enumerate(params):
        members.setdefault(q.error, []).append(i)
    redundant, carried = {}, {}
    if minimal:
        others = [int(j) for j in cols if j not in kept]
        if others:
            c = np.linalg.lstsq(j0[:, kept], j0[:, others], rcond=None)[0]   # one solve for all of them
            norms = np.linalg.norm(j0[:, kept], axis=0)
            for col, j in enumerate(others):
                redundant[names[j]], carried[names[j]] = _carried(params, members, kept, j, c[:, col], norms)
        basis[sorted(kept), np.arange(rank)] = d[sorted(kept)]      # the minimal set, scaled
        return rank, basis, unidentifiable, redundant, carried, []
    null = vt[rank:]
    proj = null.T @ null        # projector on the null space: its blocks do not depend on the basis
    for k, j in enumerate(cols):
        if proj[k, k] > 1e-12:
            unidentifiable[names[j]] = _inseparable_reason(params, members, cols, proj, k, d)
    basis[cols] = d[cols, None] * vt[:rank].T                      # the combinations the data see
    return rank, basis, unidentifiable, redundant, carried, [names[j] for j in cols if j not in kept]


def _count(k: int, what: str) -> str:
    return f"{k} {what}{'' if k == 1 else 's'}"


def _spanning(a: np.ndarray, rank: int, first=()) -> list[int]:
    """``rank`` columns of ``a`` (unit norm) that span its column space: the columns ``first``
    in that order, each that still adds a direction (remaining norm above 1e-6), then, greedily,
    each time the one least explained by those already picked (QR with column pivoting). Ties
    (remaining norms within 1e-9 of the largest, relative) go to the first column: machine order."""
    a = a.copy()
    picked: list[int] = []

    def pick(j):
        q = a[:, j] / np.linalg.norm(a[:, j])
        a[:] -= np.outer(q, q @ a)
        picked.append(j)

    for j in first:
        if len(picked) < rank and j not in picked and np.linalg.norm(a[:, j]) > 1e-6:
            pick(j)
    while len(picked) < rank:
        norms = np.linalg.norm(a, axis=0)
        pick(int(np.flatnonzero(norms >= norms.max() * (1 - _TIE))[0]))
    return picked


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


_SHOWN = 8   # terms of a combination written out in a reason (JSON has them all)


def _listed(items: list[str]) -> str:
    more = len(items) - _SHOWN
    return ", ".join(items[:_SHOWN]) + (f" and {more} more" if more > 0 else "")


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


# ----------------------------------------------------------------------------- reports

def _shown(fit: Fit, p: Param, units: str) -> tuple[float, str]:
    """A parameter's display unit: its kind's (µm, arcsec, µm/m; or internal), per the axis'
    declared unit (internal: mm, rad) to the power for a polynomial coefficient."""
    vu = display_unit(p.kind, units)
    if not p.power:
        return vu.to_internal, vu.name
    au = fit.machine.symbol(p.axis).unit
    if units != "people":
        au = UNITS[INTERNAL[au.kind]]
    return vu.to_internal / au.to_internal ** p.power, f"{vu.name}/{au.name}" + (f"^{p.power}" if p.power > 1 else "")


def _internal_unit(p: Param, fit: Fit) -> str:
    """The internal unit of a parameter: mm, rad or 1, per mm^k or rad^k for a coefficient."""
    name = INTERNAL[p.kind]
    if not p.power:
        return name
    pos = INTERNAL[fit.machine.symbol(p.axis).unit.kind]
    return f"{name}/{pos}" + (f"^{p.power}" if p.power > 1 else "")


def _varying_json(fit: Fit, e: str, v: Vary) -> dict:
    """A varying error's parameters, internal units (named in ``units``, as in a params file)."""
    m = fit.machine
    a, s = m.symbol(v.axis), m.symbol(e)
    ps = [p for p in fit.params if p.error == e]
    units = [INTERNAL[a.unit.kind], INTERNAL[s.unit.kind]]
    out = {"axis": v.axis, "units": units, "parameters": [p.name for p in ps],
           "uncertainties": [fit.uncertainties.get(p.name) for p in ps], "outside": "hold"}
    vals = [fit.estimates.get(p.name) for p in ps]
    if v.kind == "table":
        return {"kind": "table", **out, "interpolation": "linear", "positions": list(v.knots), "values": vals}
    return {"kind": "polynomial", **out, "degree": v.degree, "coefficients": vals, "range": list(fit.ranges[e])}


def to_json(fit: Fit, source: str) -> dict:
    """Every value in internal units (mm, rad, 1), named beside it; None where not measured or
    not identified."""
    byname = {p.name: p for p in fit.params}
    constant = {n: {"value": v, "uncertainty": fit.uncertainties[n], "unit": _internal_unit(byname[n], fit)}
                for n, v in fit.estimates.items() if byname[n].error not in fit.varying}
    return {
        "machine": fit.machine.name, "measurements": source, "units": "internal (mm, rad, 1)",
        "setups": fit.setups, "observations": fit.observations,
        "measured": fit.measured, "fitted": fit.fitted, "assumed_zero": fit.assumed_zero,
        "estimates": {n: e for n, e in constant.items() if not _registration(fit, n)},
        "registration": {n: e for n, e in constant.items() if _registration(fit, n)},
        "varying": {e: _varying_json(fit, e, v) for e, v in fit.varying.items()},
        "parameters": len(fit.params), "minimal": fit.minimal,
        "redundant": {n: {"reason": why, "carried_by": fit.carried[n]} for n, why in fit.redundant.items()},
        "unidentifiable": fit.unidentifiable,
        "suggested_assume_zero": fit.suggested_zero, "rank": fit.rank,
        "condition_number": fit.condition,
        "correlations": [{"errors": [a, b], "value": c} for a, b, c in fit.correlations],
        "rms_residual": None if math.isnan(fit.rms) else fit.rms, "length_unit": "mm",
        "rms_direction_residual": None if math.isnan(fit.rms_direction) else fit.rms_direction,
        "direction_unit": "rad",
        "rms_orientation_residual": None if math.isnan(fit.rms_orientation) else fit.rms_orientation,
        "sigma": {c: {"value": v, "unit": "mm" if c in COMPONENTS else "rad"} for c, v in fit.sigma.items()},
        "chi2_per_dof": fit.chi2, "misfit": fit.misfit, "smooth": fit.smooth, "notes": fit.notes,
        "degrees_of_freedom": fit.dof, "iterations": fit.iterations, "converged": fit.converged,
        "loss": "squares" if fit.huber is None else {"huber": fit.huber},
        "outliers": [{"line": line, "column": c, "standardized_residual": u, "weight": wt}
                     for line, c, u, wt in fit.outliers],
    }


def _residuals(fit: Fit, units: str) -> str:
    """'rms residual 0.785 µm', or with directions '... 0.785 µm (tool point), 9.8 arcsec (tool
    direction)', with orientations '..., 9.8 arcsec (tool orientation, per component of ω)'."""
    point, direction = not math.isnan(fit.rms), not math.isnan(fit.rms_direction)
    orientation = not math.isnan(fit.rms_orientation)
    parts = ([quantity(fit.rms, "length", units) + (" (tool point)" if direction or orientation else "")]
             if point else []) \
        + ([quantity(fit.rms_direction, "angle", units) + " (tool direction)"] if direction else []) \
        + ([quantity(fit.rms_orientation, "angle", units) + " (tool orientation, per component of ω)"]
           if orientation else [])
    return "rms residual " + ", ".join(parts)


def to_text(fit: Fit, source: str, units: str = DEFAULT_UNITS) -> str:
    m = fit.machine
    what = _count(len(fit.fitted), "error") + (f" as {len(fit.params)} parameters"
                                              if len(fit.params) != len(fit.fitted) else "")
    lines = [f"identify {m.name} from {source}: {fit.observations} coordinates "
             f"({', '.join(fit.measured)}) at {fit.setups} set-ups; {what} fitted"
             + (f" (the data see {fit.rank} independent combinations of them)"
                if fit.rank < len(fit.params) else "")
             + (f", assumed zero: {', '.join(fit.assumed_zero)}" if fit.assumed_zero else "")]
    for e, v in fit.varying.items():
        a = m.symbol(v.axis)
        if v.kind == "table":
            lines.append(f"{e} varies along {v.axis}: a table on {len(v.knots)} knots, linear between them, "
                         f"held beyond [{a.from_internal(v.knots[0]):g}, {a.from_internal(v.knots[-1]):g}] "
                         f"{a.unit.name}")
        else:
            lo, hi = fit.ranges[e]
            lines.append(f"{e} varies along {v.axis}: a polynomial of degree {v.degree} in {v.axis} "
                         f"({a.unit.name}) over the measured [{a.from_internal(lo):g}, {a.from_internal(hi):g}] "
                         f"{a.unit.name}, held beyond")
    if fit.smooth:
        lines.append(f"smoothing: {fit.smooth:g} x the squared second differences of the tables' knot values "
                     f"(declared unit) added to the weighted sum of squares")
    if fit.minimal:
        lines.append(f"minimal set: {len(fit.estimates)} of {len(fit.params)} parameters fitted (chosen by QR "
                     f"with column pivoting), {len(fit.redundant) + len(fit.unidentifiable)} held at zero")
    if fit.sigma:
        groups: dict[str, list[str]] = {}
        for c, v in fit.sigma.items():
            u = display_unit("length" if c in COMPONENTS else "angle", units)
            groups.setdefault(f"{v / u.to_internal:.4g} {u.name}", []).append(c)
        given = ", ".join(f"{', '.join(cs)} {v}" for v, cs in groups.items())
        weights = f"; sigma {given}; chi2/dof {fit.chi2:.3g}"
    else:
        weights = ""
    lines.append(f"{'converged' if fit.converged else 'NOT converged'} after {fit.iterations} Gauss-Newton "
                 f"iterations on the exact model; {_residuals(fit, units)}; {fit.dof:.4g} degrees of freedom"
                 + weights)
    width = max([12] + [len(n) for n in fit.estimates])
    lines.append(f"  {'parameter':<{width}}  estimate ± standard uncertainty")
    byname = {p.name: p for p in fit.params}
    registration = [n for n in fit.estimates if _registration(fit, n)]
    for n, v in fit.estimates.items():
        f, unit = _shown(fit, byname[n], units)
        if n not in registration:
            lines.append(f"  {n:<{width}}  {plus_minus(v / f, fit.uncertainties[n] / f)} {unit}")
    if registration:
        lines.append("registration (the base in the measuring instrument's frame: not a machine error, identified "
                     "with the errors, written to the params as zero):")
        for n in registration:
            f, unit = _shown(fit, byname[n], units)
            lines.append(f"  {n:<{width}}  {plus_minus(fit.estimates[n] / f, fit.uncertainties[n] / f)} {unit}")
    lines.append(f"condition number {fit.condition:.4g} (Jacobian columns scaled to unit norm)")
    lines.append("correlations above 0.9: " + (", ".join(f"{a}/{b} {c:+.3f}" for a, b, c in fit.correlations)
                                                 or "none"))
    if fit.redundant:
        lines.append("held at zero, not in the minimal set (each carried by the fitted ones):")
        lines += [f"  {n}: {why}" for n, why in fit.redundant.items()]
    if fit.unidentifiable:
        lines.append("not identifiable from these set-ups ("
                     + ("held at zero):" if fit.minimal else "no value given):"))
        lines += [f"  {n}: {why}" for n, why in fit.unidentifiable.items()]
    if fit.suggested_zero:
        constants = [n for n in fit.suggested_zero if n in fit.fitted and n not in fit.varying]
        lines.append("to give every other parameter a value, fit a minimal set (--minimal)"
                     + (f", or assume these zero as well (one choice of many): --assume-zero "
                        + ",".join(fit.assumed_zero + constants) if len(constants) == len(fit.suggested_zero) else ""))
    if fit.huber is not None:
        lines.append(_outliers(fit))
    lines += [f"note: {note}" for note in fit.notes]
    return "\n".join(lines)


def _outliers(fit: Fit) -> str:
    """'Huber loss (k = 1.345): 3 of 150 coordinates down-weighted: line 14 y -41.2 sigma (weight 0.033), ...'."""
    head = f"Huber loss (k = {fit.huber:g}): {len(fit.outliers)} of {fit.observations} " \
           f"coordinates down-weighted (weight below 1; residuals in standard uncertainties)"
    shown = [f"line {line} {c} {u:+.3g} sigma (weight {wt:.3g})" for line, c, u, wt in fit.outliers[:_SHOWN]]
    more = len(fit.outliers) - _SHOWN
    return head + (": " + ", ".join(shown) + (f" and {more} more (JSON has them all)" if more > 0 else "")
                   if shown else "")


def _num(v: float) -> str:
    text = f"{v:.12g}"
    return "0" if text == "-0" else text


def _registration(fit: Fit, name: str) -> bool:
    """A parameter of an error marked registration (the base block: the instrument's frame)."""
    return fit.machine.symbol(name).registration if name in fit.fitted else False


def params_yaml(fit: Fit, source: str, held: dict | None = None) -> str:
    """A params file (machine + values as 'VALUE UNIT', tables and polynomials in the params
    format) that load_params and chaincompd read; ``held``: the values the fit held (--hold, by
    name, internal units or a table along an axis), written as they were given."""
    m = fit.machine
    held = held or {}
    out = [f"# Error values identified by chaincomp identify from {one_line(source)}:",
           f"# {fit.observations} coordinates at {fit.setups} set-ups, {_residuals(fit, 'internal')}, "
           f"condition number {fit.condition:.4g}."]
    if fit.huber is not None:
        out.append(f"# Huber loss (k = {fit.huber:g}): {len(fit.outliers)} of {fit.observations} coordinates "
                   "down-weighted (identify's report lists them).")
    if fit.minimal:
        out.append(f"# Minimal identifiable set: {len(fit.estimates)} of {len(fit.params)} parameters fitted; "
                   f"every other one is written as zero (held at zero in the fit).")
    elif fit.unidentifiable:
        out.append(f"# Not identifiable, no value given: {', '.join(fit.unidentifiable)}.")
    out += [f"machine: {m.name}", "values:"]
    params = {p.name: p for p in fit.params}

    def note(name):
        if name in fit.estimates:
            return f"standard uncertainty {fit.uncertainties[name] / params[name].to_internal:.3g} " \
                   f"{params[name].unit}"
        if name in fit.redundant:
            return "held at zero: redundant, carried by " + ", ".join(fit.carried[name])
        return "held at zero: moves no measured coordinate"

    for s in m.errors:
        if s.name in held:
            out += _held_entry(s, held[s.name])
        elif s.name in fit.varying:
            v = fit.varying[s.name]
            ps = [p for p in fit.params if p.error == s.name]
            if not fit.minimal and any(p.name in fit.unidentifiable for p in ps):
                out.append(f"  # {s.name}: not written, not identifiable: "
                           + ", ".join(p.name for p in ps if p.name in fit.unidentifiable))
                continue
            a = m.symbol(v.axis)
            val = [fit.estimates.get(p.name, 0.0) / p.to_internal for p in ps]
            out += [f"  {s.name}:   # identified as a {'table' if v.kind == 'table' else 'polynomial'} along {v.axis}",
                    f"    axis: {v.axis}", f"    units: [{a.unit.name}, {s.unit.name}]"]
            if v.kind == "table":
                out += ["    interpolation: linear", "    outside: hold", "    table:"]
                out += [f"      - [{_num(a.from_internal(k))}, {_num(x)}]   # {note(p.name)}"
                        for k, x, p in zip(v.knots, val, ps)]
            else:
                lo, hi = fit.ranges[s.name]
                out.append(f"    polynomial: [{', '.join(_num(x) for x in val)}]")
                out += [f"    # {p.name}: {note(p.name)}" for p in ps]
                out += [f"    range: [{_num(a.from_internal(lo))}, {_num(a.from_internal(hi))}]", "    outside: hold"]
        elif s.name in fit.estimates and s.registration:   # the instrument's frame: never compensated
            out.append(f'  {s.name}: "0 {s.unit.name}"   # registration, not a machine error: identified '
                       f'{_num(s.from_internal(fit.estimates[s.name]))} {s.unit.name}, {note(s.name)}')
        elif s.name in fit.estimates:
            out.append(f'  {s.name}: "{_num(s.from_internal(fit.estimates[s.name]))} {s.unit.name}"   # {note(s.name)}')
        elif s.name in fit.assumed_zero:
            out.append(f'  {s.name}: "0 {s.unit.name}"   # assumed zero')
        elif fit.minimal:
            out.append(f'  {s.name}: "0 {s.unit.name}"   # {note(s.name)}')
    return "\n".join(out) + "\n"


def _held_entry(s, value) -> list[str]:
    """A held error's lines: a number as 'VALUE UNIT', a table or polynomial as the lines of its
    entry in the params file it was read from."""
    if not isinstance(value, Varying):
        return [f'  {s.name}: "{_num(s.from_internal(value))} {s.unit.name}"   # held at a given value (--hold)']
    lines = read_text(value.file).splitlines()
    first = lines[value.line - 1]
    indent = len(first) - len(first.lstrip())
    block = [first]
    for line in lines[value.line:]:
        if line.strip() and not line.lstrip().startswith("#") and len(line) - len(line.lstrip()) <= indent:
            break
        block.append(line)
    return [f"  # {s.name}: held as given in {one_line(value.file)} (--hold)"] + \
        ["  " + line[indent:] for line in block if line.strip()]


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
