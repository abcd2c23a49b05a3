"""Measurement tables of ``identify``: the CSV of set-ups and measured tool points, directions
and orientations (``read_table``, ``write_table``), read into a ``Table`` in internal units.

One row per set-up, one column per axis and per measured coordinate (tool point x, y, z; tool
direction kx, ky, kz; with a tool frame its orientation as a unit quaternion qw, qx, qy, qz).
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass, field

import numpy as np

from ..errors import ChaincompError
from ..escape import one_line
from ..model import csvtable
from ..model.expressions import MAX_LITERAL
from ..model.machine import Machine
from ..model.units import UNITS
from ..output import write_file
from ..symbolic.derive import COMPONENTS
from ..symbolic.orientation import ROWS as ROTATION

MAX_ROWS = 20_000  # set-ups in a file or a --setups spec: bounds the fit's memory (rows x errors)

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
                       f"[{lo:g}, {hi:g}] ({count(bad.size, 'row')} of {len(v)}; "
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


def count(k: int, what: str) -> str:
    """'1 row', '3 rows'."""
    return f"{k} {what}{'' if k == 1 else 's'}"
