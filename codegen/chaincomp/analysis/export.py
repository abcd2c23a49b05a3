"""Compensation in the controllers' own formats (``chaincomp export``), each fitted to the
exact model and replayed with the controller's own rule, so the residual it reports is the
tool error the controller will leave (on the model), not the fit's.

Two shapes of correction cover the formats:

- per-joint tables (LinuxCNC ``[JOINT_n]COMP_FILE``): a trim t_j(q_j) added to each joint's
  command, a function of that joint alone, linear between entries and held outside them
  (src/emc/motion/control.c compute_screw_comp, command.c EMCMOT_SET_JOINT_COMP, LinuxCNC);
- a 3x3 matrix on the linear axes (LinuxCNC ``matrixkins``, src/hal/components/matrixkins.comp,
  on LinuxCNC's master since 2022-11-27, not in 2.9: joint = C . axis; the printer
  firmwares' skew factors are its strictly upper-triangular part).

Every fit runs on the exact model: the tool point with the errors at the corrected joint
positions against the nominal tool point at the commanded ones."""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field

import numpy as np

from ..errors import ChaincompError
from ..model.machine import Machine, Symbol
from ..model.varying import Table, varying_errors
from ..symbolic.numeric import ExactModel

# LinuxCNC: motion.h EMCMOT_COMP_SIZE; a larger file is refused entry by entry
LINUXCNC_MAX_ENTRIES = 256
MAX_POINTS = 2_000_000      # exact-model evaluations held at once by one fit or check
MAX_BREAKDOWN = 120_000_000  # errors x check points of the breakdown (each error alone): about a minute
DEFAULT_GRID_POINTS = 100_000  # the default check grid's size: 9 per axis up to five axes


def default_grid(n_axes: int) -> int:
    """Points per axis of the default check grid: 9, or fewer where 9^n would be too many."""
    n = 9
    while n > 3 and n ** n_axes > DEFAULT_GRID_POINTS:
        n -= 1
    return n


FD_STEP = 1e-4              # mm or rad: differences of the nominal model (exact for linear axes), kept inside the limits


@dataclass
class Residual:
    """Largest and RMS norm of the tool-point error over the check grid, mm."""
    max: float
    rms: float

    @classmethod
    def of(cls, dp) -> Residual:
        """Of a (3, ...) error, or of a list of them (the check sets)."""
        n = np.concatenate([np.sqrt(np.sum(d * d, axis=0)).ravel() for d in (dp if isinstance(dp, list) else [dp])])
        return cls(float(n.max()), float(np.sqrt(np.mean(n * n))))


@dataclass
class ErrorShare:
    """One error alone: its tool error without compensation and what the format leaves."""
    name: str
    before: Residual
    after: Residual
    carried: bool | None = None   # False: the format has no place for it at all (isg-volcomp)

    @property
    def represented(self) -> str:
        """"yes" (at most 1 % of it, or under 0.1 um, is left), "no" (more than 90 %, or not
        carried at all), else "partly"."""
        if self.carried is False:
            return "no"
        if self.after.max <= max(0.01 * self.before.max, 1e-4):
            return "yes"
        return "no" if self.after.max > 0.9 * self.before.max else "partly"


@dataclass
class JointTable:
    """One joint's compensation table: nominal positions and the trims added to its command
    moving forward and in reverse, in the axis' declared unit."""
    axis: Symbol
    nominal: np.ndarray
    forward: np.ndarray
    reverse: np.ndarray
    mean_reversal: float = 0.0   # B̄ (ISO 230-2, declared unit) the trims take out: with_reversal

    def trim(self, position: np.ndarray) -> np.ndarray:
        """LinuxCNC's trim at ``position`` (declared unit) moving forward: linear between
        entries, the end entries' trims held outside, trims stored as float (motion.h)."""
        return np.interp(position, self.nominal, self.forward.astype(np.float32).astype(float))


@dataclass
class Uncorrected:
    """The check points where a printer firmware does not apply its skew (skew_window): Marlin
    passes them through uncorrected, Klipper refuses the move. ``after`` and ``after_offset``
    of the Export are over the other points; here, what is left at these."""
    points: int
    of: int
    rule: str
    past_limits: float               # mm: how far the skewed X or Y leaves the limits, at most
    left: Residual | None = None     # marlin: the tool error there, once touched off (uncorrected)


@dataclass
class Export:
    """What an exporter fitted, and what it leaves."""
    format: str
    machine: Machine
    grid: int              # check points per axis over the limits
    grid_points: int       # every point checked (with the points between table entries)
    before: Residual
    after: Residual
    tables: list[JointTable] = field(default_factory=list)
    matrix: np.ndarray | None = None     # C (joint = C . axis) on `linear`
    linear: list[str] = field(default_factory=list)
    joints: list[Symbol] = field(default_factory=list)   # the axes in the controller's joint order
    offset: np.ndarray | None = None     # constant tool-point offset left to the work offset, mm
    after_offset: Residual | None = None  # the residual once that offset is touched off
    shares: list[ErrorShare] = field(default_factory=list)
    isg: object | None = None            # isg_volcomp.IsgFile: the file's axes, chain, names
    knot_axes: list[str] = field(default_factory=list)   # joints checked at the params' table knots too
    uncorrected: Uncorrected | None = None   # marlin, klipper: the check points the firmware leaves or refuses
    without_z: Residual | None = None    # marlin: the residual, touched off, with I alone (J, K need
                                         # SKEW_CORRECTION_FOR_Z)


def _errors_only(machine: Machine, values: dict, keep: set[str] | None) -> dict:
    """``values`` with the errors outside ``keep`` dropped (zero); all of them with None."""
    if keep is None:
        return values
    return {k: v for k, v in values.items() if machine.symbol(k).role != "error" or k in keep}


def _nominal(machine: Machine, values: dict) -> dict:
    return {k: v for k, v in values.items() if machine.symbol(k).role != "error"}


def _shape(q: dict) -> tuple[int, ...]:
    """The shape the axis values of ``q`` broadcast to."""
    return np.broadcast_shapes(*(np.shape(v) for v in q.values()))


def tool_error(exact: ExactModel, values: dict, commanded: dict, actual: dict) -> np.ndarray:
    """(3, ...) tool-point error: the model with its errors at the ``actual`` joint positions
    minus the nominal model at the ``commanded`` ones (internal units)."""
    p1, _ = exact.pose({**values, **actual})
    p0, _ = exact.pose({**_nominal(exact.machine, values), **commanded})
    shape = _shape(commanded)
    return np.stack([np.broadcast_to(np.asarray(a, float) - np.asarray(b, float), shape) for a, b in zip(p1, p0)])


def _jacobian_column(exact: ExactModel, values: dict, q: dict, axis: str) -> np.ndarray:
    """d(nominal tool point)/d(axis) at ``q`` by differences (internal units): central, and
    one-sided at the limits (the model need not exist beyond them: sqrt(X) from X = 0)."""
    nominal = _nominal(exact.machine, values)
    lo, hi = (exact.machine.symbol(axis).to_internal(v) for v in exact.machine.symbol(axis).limits)
    up, down = np.minimum(q[axis] + FD_STEP, max(lo, hi)), np.maximum(q[axis] - FD_STEP, min(lo, hi))
    plus, _ = exact.pose({**nominal, **q, axis: up})
    minus, _ = exact.pose({**nominal, **q, axis: down})
    shape = _shape(q)
    jac = np.stack([np.broadcast_to((np.asarray(a, float) - np.asarray(b, float)) / (up - down), shape)
                    for a, b in zip(plus, minus)])
    _check_finite(exact.machine, jac, q, f"the derivative along {axis} of the nominal tool point")
    return jac


def _check_finite(machine: Machine, dp: np.ndarray, q: dict, what: str) -> None:
    """Refuse a model that is not finite somewhere on the points checked, naming the first."""
    bad = ~np.isfinite(dp).all(axis=0)
    if bad.any():
        k = np.unravel_index(int(np.argmax(bad.ravel())), bad.shape)
        at = ", ".join(f"{n} = {machine.symbol(n).from_internal(float(np.broadcast_to(v, bad.shape)[k])):.6g} "
                       f"{machine.symbol(n).unit.name}" for n, v in q.items())
        raise ChaincompError(f"{machine.name}: {what} is not finite at {at} ({machine.file}: an expression "
                             f"undefined inside the axes' limits, e.g. sqrt or a division): nothing written")


def axes_of(machine: Machine, joints: list[str] | None) -> list[Symbol]:
    """The machine's axes in joint order (``joints``: every axis once; default the file's order)."""
    names = [a.name for a in machine.axes]
    if joints is None:
        return list(machine.axes)
    if sorted(joints) != sorted(names):
        raise ChaincompError(f"--joints expects every axis of {machine.name} once ({', '.join(names)}), "
                             f"got {','.join(joints)!r}")
    return [machine.symbol(n) for n in joints]


def check_grid(machine: Machine, axes: list[Symbol], points: int) -> list[np.ndarray]:
    """The check grid: ``points`` values across each axis' limits (declared units)."""
    total = points ** len(axes)
    if total > MAX_POINTS:
        raise ChaincompError(f"--grid {points}: the check grid would hold {points}^{len(axes)} = {total} points "
                             f"(at most {MAX_POINTS}): lower --grid")
    return [np.linspace(a.limits[0], a.limits[1], points) for a in axes]


def _mesh(axes: list[Symbol], values_per_axis: list[np.ndarray]) -> dict:
    """Internal values of a full grid, each axis broadcasting along its own dimension."""
    n = len(axes)
    out = {}
    for k, (a, v) in enumerate(zip(axes, values_per_axis)):
        shape = [1] * n
        shape[k] = len(v)
        out[a.name] = a.to_internal(np.asarray(v, float)).reshape(shape)
    return out


# ----------------------------------------------------------------------------- per-joint tables

def apply_tables(tables: list[JointTable], q: dict) -> dict:
    """Joint positions a controller drives to for commands ``q`` (internal): q + trim(q)."""
    out = dict(q)
    for t in tables:
        a = t.axis
        out[a.name] = q[a.name] + a.to_internal(t.trim(a.from_internal(q[a.name])))
    return out


def check_table_sizes(axes: list[Symbol], entries: int, grid: list[np.ndarray]) -> None:
    """Refuse tables whose fit would hold too many points at once: per joint its entries x
    the grid of the other joints (table_slices; between_entries takes one fewer)."""
    for j, a in enumerate(axes):
        size = entries * int(np.prod([len(g) for k, g in enumerate(grid) if k != j]))
        if size > MAX_POINTS:
            raise ChaincompError(f"fitting joint {a.name} would take {size} points ({entries} entries x the grid "
                                 f"of the other joints; at most {MAX_POINTS}): lower --entries or --grid")


def table_slices(machine: Machine, values: dict, axes: list[Symbol], entries: int, grid: list[np.ndarray]):
    """Per joint: the fit's sample points (its entries x the check grid of the other joints)
    and the nominal tool point's derivative along it there (the errors do not enter: one
    computation serves every fit on these points)."""
    exact = ExactModel(machine)
    slices = []
    for j, a in enumerate(axes):
        nominal = np.linspace(a.limits[0], a.limits[1], entries)
        q = _mesh(axes, [nominal if k == j else grid[k] for k in range(len(axes))])
        jac = _jacobian_column(exact, values, q, a.name)
        slices.append((q, np.moveaxis(jac, j + 1, 1).reshape(3, entries, -1)))
    return slices


def fit_tables(machine: Machine, values: dict, axes: list[Symbol], entries: int, slices, sweeps: int = 4) -> list[JointTable]:
    """Per-joint trims on ``entries`` equally spaced positions per joint, fitted to the exact
    model by sweeps over the joints: each entry's trim takes the least-squares step that
    cancels the tool error, along its joint's direction of motion, over the check grid of
    the other joints (``slices``: table_slices; the trims of all joints applied as the
    controller applies them)."""
    exact = ExactModel(machine)
    tables = [JointTable(a, np.linspace(a.limits[0], a.limits[1], entries), np.zeros(entries), np.zeros(entries))
              for a in axes]
    for _ in range(sweeps):
        largest = 0.0
        for j, (a, (q, jac)) in enumerate(zip(axes, slices)):
            r = tool_error(exact, values, q, apply_tables(tables, q))
            r = np.moveaxis(r, j + 1, 1).reshape(3, entries, -1)
            num = np.sum(jac * r, axis=(0, 2))
            den = np.sum(jac * jac, axis=(0, 2))
            step = np.where(den > 1e-12 * max(float(den.max()), 1e-300), -num / np.where(den > 0, den, 1), 0.0)
            tables[j].forward = tables[j].forward + a.from_internal(step)
            largest = max(largest, float(np.max(np.abs(a.to_internal(1.0) * a.from_internal(step)))))
        if largest < 1e-9:
            break
    for t in tables:
        t.reverse = t.forward.copy()
    return tables


def with_reversal(tables: list[JointTable], reversal: dict[str, float]) -> None:
    """The signed mean reversal B̄ per axis (ISO 230-2:2014: B̄ = (1/m) sum B_i, B_i = x̄_i↑ -
    x̄_i↓, the mean deviations approached forward minus in reverse; declared unit): the forward
    trim takes -B̄/2 more, the reverse trim +B̄/2, so both directions land on their mean. Not
    B = max |B_i|: that is >= 0, and ordinary lost motion has B_i < 0."""
    for t in tables:
        b = reversal.get(t.axis.name, 0.0)
        t.forward, t.reverse, t.mean_reversal = t.forward - b / 2, t.forward + b / 2, b


# ----------------------------------------------------------------------------- matrix on the linear axes

def linear_axes(machine: Machine, axes: list[Symbol], fmt: str) -> list[Symbol]:
    lin = [a for a in axes if a.unit.kind == "length"]
    if len(lin) < 3:
        raise ChaincompError(f"--controller {fmt} needs three linear axes (X, Y, Z); {machine.name} has "
                             f"{len(lin)} ({', '.join(a.name for a in lin) or 'none'})")
    return lin[:3]


def apply_matrix(lin: list[Symbol], c: np.ndarray, q: dict) -> dict:
    out = dict(q)
    for i, a in enumerate(lin):
        out[a.name] = sum(c[i, k] * q[b.name] for k, b in enumerate(lin))
    return out


@dataclass
class MatrixDesign:
    """The normal equations of the matrix fit on the check grid: the nominal model's
    derivatives enter, not the errors, so one design serves every fit on the grid."""
    q: dict
    jac: np.ndarray          # (3, 3, S): d(tool point)/d(linear axis)
    pos: np.ndarray          # (3, S): the linear axes' commands
    free: list[tuple[int, int]]
    ata: np.ndarray


def matrix_design(machine: Machine, values: dict, axes: list[Symbol], lin: list[Symbol], grid: list[np.ndarray],
                  free: np.ndarray) -> MatrixDesign:
    """Minimise |r + A.step - offset|^2 over rows (component i, sample s), columns the free
    entries of C (jac[i, j, s] pos[k, s]) then the offset left (-1 on its component), by the
    normal equations: A (3 S rows) is never formed, only A'A here and A'r in fit_matrix."""
    exact = ExactModel(machine)
    q = _mesh(axes, grid)
    jac = np.stack([_jacobian_column(exact, values, q, a.name).reshape(3, -1) for a in lin], axis=1)
    pos = np.stack([np.broadcast_to(q[a.name], _shape(q)).ravel()
                    for a in lin])
    idx = [(j, k) for j in range(3) for k in range(3) if free[j, k]]
    gram = np.einsum("ijs,ils,ks,ms->jklm", jac, jac, pos, pos, optimize=True)    # (j,k) x (l,m)
    cross = np.einsum("ijs,ks->ijk", jac, pos)                                     # offset i x (j,k)
    n = len(idx)
    ata = np.zeros((n + 3, n + 3))
    for a, (j, k) in enumerate(idx):
        for b, (l, m) in enumerate(idx):
            ata[a, b] = gram[j, k, l, m]
        ata[a, n:] = ata[n:, a] = -cross[:, j, k]
    ata[n:, n:] = np.eye(3) * pos.shape[1]
    return MatrixDesign(q, jac, pos, idx, ata)


def fit_matrix(machine: Machine, values: dict, lin: list[Symbol], d: MatrixDesign,
               iterations: int = 3) -> tuple[np.ndarray, np.ndarray]:
    """C (joint = C . axis on ``lin``; the free entries fitted, the others those of the
    identity) and the constant offset that best cancel the exact tool error over the grid
    (Gauss-Newton on the exact model, r recomputed each time; the offset is the work
    offset's, not the matrix's)."""
    exact = ExactModel(machine)
    c, offset, n = np.eye(3), np.zeros(3), len(d.free)
    for _ in range(iterations):
        r = tool_error(exact, values, d.q, apply_matrix(lin, c, d.q)).reshape(3, -1)
        rc = np.einsum("ijs,ks,is->jk", d.jac, d.pos, r)
        atr = np.concatenate([[rc[j, k] for j, k in d.free], -r.sum(axis=1)])
        step, *_ = np.linalg.lstsq(d.ata, -atr, rcond=None)
        for a, (j, k) in enumerate(d.free):
            c[j, k] += step[a]
        offset = step[n:]
    return c, offset


# ----------------------------------------------------------------------------- the exporters

FORMATS = ("linuxcnc-comp", "linuxcnc-matrixkins", "klipper", "marlin", "rrf")
SKEW = np.array([[False, True, True], [False, False, True], [False, False, False]])


def between_entries(axes: list[Symbol], entries: int, grid: list[np.ndarray]) -> list[dict]:
    """Per joint, the midpoints of its table's entries x the check grid of the other joints:
    where a table's linear rule is furthest from the model (a grid of 9 on 33 entries would
    fall on entries only)."""
    sets = []
    for j, a in enumerate(axes):
        nominal = np.linspace(a.limits[0], a.limits[1], entries)
        sets.append(_mesh(axes, [(nominal[1:] + nominal[:-1]) / 2 if k == j else grid[k] for k in range(len(axes))]))
    return sets


def table_knots(axes: list[Symbol], values: dict) -> dict[str, np.ndarray]:
    """Per joint, the knots of the params' tables along it that lie inside its limits (declared
    unit): a table's error bends there, so its largest residual may lie there and not at the
    grid, the entries or their midpoints."""
    knots: dict[str, set[float]] = {}
    for v in varying_errors(values).values():
        if isinstance(v, Table):
            knots.setdefault(v.axis, set()).update(np.asarray(v.x, float).tolist())
    out = {}
    for a in axes:
        lo, hi = sorted(a.to_internal(float(x)) for x in a.limits)
        inside = [a.from_internal(x) for x in sorted(knots.get(a.name, ())) if lo <= x <= hi]
        if inside:
            out[a.name] = np.asarray(inside, float)
    return out


def at_knots(axes: list[Symbol], knots: dict[str, np.ndarray], grid: list[np.ndarray]) -> list[dict]:
    """Per joint with knots (table_knots), its knots x the check grid of the other joints."""
    return [_mesh(axes, [knots[a.name] if k == j else grid[k] for k in range(len(axes))])
            for j, a in enumerate(axes) if a.name in knots]


CHECK_CHUNK = 250_000   # check points evaluated at once


def distinct(sets: list[dict]) -> list[dict]:
    """The check points of ``sets`` (meshes of the same axes) once each, flattened, in chunks of
    at most CHECK_CHUNK: a point in two sets (a knot on the grid, an entry's midpoint on a knot)
    counts once in the report."""
    names = list(sets[0])
    pts = np.concatenate([np.stack([np.broadcast_to(q[n], _shape(q)).ravel() for n in names]) for q in sets], axis=1)
    _, first = np.unique(np.round(pts, 9), axis=1, return_index=True)   # 1e-9 mm or rad: one point
    keep = pts[:, np.sort(first)]
    return [{n: keep[i, k:k + CHECK_CHUNK] for i, n in enumerate(names)} for k in range(0, keep.shape[1], CHECK_CHUNK)]


def _where(dp: list[np.ndarray], windows: list[np.ndarray] | None) -> list[np.ndarray]:
    """The (3, N) errors of each chunk at the points its window keeps (all with None)."""
    return dp if windows is None else [d[:, w] for d, w in zip(dp, windows)]


def export(machine: Machine, values: dict, fmt: str, joints: list[str] | None, points: int, entries: int,
           reversal: dict[str, float] | None = None, shares: bool = True, progress=None) -> Export:
    """Fit the format to the model (``values``: internal units, every symbol) and replay it
    over the check grid (for tables also between every two entries of each joint), and along
    each joint at the params' table knots, each point once; with
    ``shares`` also each nonzero error alone."""
    if fmt not in FORMATS:
        raise ChaincompError(f"--controller {fmt!r}: expected one of {', '.join(FORMATS)}")
    axes = axes_of(machine, joints)
    if fmt == "linuxcnc-comp" and not 2 <= entries <= LINUXCNC_MAX_ENTRIES:
        raise ChaincompError(f"--entries {entries}: a LinuxCNC compensation file holds 2 to "
                             f"{LINUXCNC_MAX_ENTRIES} entries (motion.h EMCMOT_COMP_SIZE)")
    unknown = sorted(set(reversal or {}) - {a.name for a in axes})
    if unknown:
        raise ChaincompError(f"--mean-reversal {unknown[0]}: not an axis of {machine.name}")
    grid = check_grid(machine, axes, points)
    values = _held_at_the_ends(machine, values)
    lin = linear_axes(machine, axes, fmt) if fmt != "linuxcnc-comp" else []
    if fmt == "linuxcnc-matrixkins" and axes[:3] != lin:
        raise ChaincompError(f"--controller {fmt}: matrixkins drives joints 0, 1, 2 from X, Y, Z, but the joints of "
                             f"{machine.name} begin {', '.join(a.name for a in axes[:3])}: put "
                             f"{', '.join(a.name for a in lin)} first with --joints")
    free = np.ones((3, 3), bool) if fmt == "linuxcnc-matrixkins" else SKEW
    exact = ExactModel(machine)
    knots = table_knots(axes, values)
    sets = [_mesh(axes, grid)] + at_knots(axes, knots, grid)
    if fmt == "linuxcnc-comp":
        check_table_sizes(axes, entries, grid)
        sets += between_entries(axes, entries, grid)
    sets = distinct(sets)
    n_points = sum(int(np.prod(_shape(q))) for q in sets)
    names = [s.name for s in machine.errors if _nonzero(values.get(s.name, 0.0))]
    if shares and len(names) * n_points > MAX_BREAKDOWN:
        raise ChaincompError(f"the breakdown would fit each of {len(names)} errors alone on {n_points} points "
                             f"(at most {MAX_BREAKDOWN} in all): lower --grid or add --no-breakdown")
    before = [tool_error(exact, values, q, q) for q in sets]
    for b, q in zip(before, sets):
        _check_finite(machine, b, q, "the tool point with the errors given")
    slices = table_slices(machine, values, axes, entries, grid) if fmt == "linuxcnc-comp" else None
    design = matrix_design(machine, values, axes, lin, grid, free) if lin else None

    def fit(vals, alone=False):
        """The format fitted to ``vals``; ``alone``: one error's share, to a few per cent (2
        sweeps of the tables, 1 Gauss-Newton step of the matrix: linear in C to first order)."""
        if fmt == "linuxcnc-comp":
            tables = fit_tables(machine, vals, axes, entries, slices, 2 if alone else 4)
            return tables, None, None, [tool_error(exact, vals, q, apply_tables(tables, q)) for q in sets]
        c, offset = fit_matrix(machine, vals, lin, design, iterations=1 if alone else 3)
        return [], c, offset, [tool_error(exact, vals, q, apply_matrix(lin, c, q)) for q in sets]

    def shifted(dp: list[np.ndarray], by: np.ndarray) -> list[np.ndarray]:
        return [d - by.reshape(3, *([1] * (d.ndim - 1))) for d in dp]

    tables, c, offset, after = fit(values)
    for a, q in zip(after, sets):
        _check_finite(machine, a, q, f"the tool point with {fmt}'s correction")
    windows = [skew_window(fmt, lin, c, q) for q in sets] if fmt in ("marlin", "klipper") else None
    if windows is not None and not any(w.any() for w in windows):
        raise ChaincompError(f"--controller {fmt}: the firmware would correct none of the {n_points} check points "
                             f"({MARLIN_WINDOW if fmt == 'marlin' else KLIPPER_WINDOW}): nothing written")
    kept = _where(after, windows)
    out = Export(fmt, machine, points, n_points, Residual.of(before), Residual.of(kept),
                 tables, c, [a.name for a in lin], axes, offset, knot_axes=list(knots))
    # what the format does beyond a touch-off (a matrix leaves the constant to the work offset),
    # against no compensation on the same points
    left, base = out.after, out.before
    if offset is not None:
        out.after_offset = left = Residual.of(shifted(kept, offset))
        base = _touched_off(_where(before, windows))
        if windows is not None:   # the fit's offset is over every point: both by their mean where it corrects
            left = _touched_off(kept)
    if windows is not None:
        out.uncorrected = _uncorrected(fmt, lin, c, sets, windows, shifted(before, offset))
    if fmt == "marlin":
        out.without_z = _touched_off(_where(_xy_only(lin, c, sets, exact, values),
                                            [skew_window(fmt, lin, _i_alone(c), q) for q in sets]))
    if not left.max < base.max * (1 - 1e-3) - 1e-7:   # 0.1 nm: rounding, not compensation
        worse = left.max > base.max + 1e-7   # a fit on a coarse grid, worse between its points
        raise ChaincompError(f"--controller {fmt} " + ("leaves more tool error than no compensation" if worse else
                             "represents none of the errors given") + f" for {machine.name} (largest tool error "
                             f"{base.max * 1e3:.3f} um without it, {left.max * 1e3:.3f} um with it, on "
                             f"{n_points} points" + ("; a finer --grid fits on more" if worse else "") +
                             "): nothing written")
    if shares:
        if progress:
            progress(f"{fmt} fitted and checked on {n_points} points; now each of the {len(names)} errors alone")
        for name in names:
            vals = _errors_only(machine, values, {name})
            _, _, off, res = fit(vals, alone=True)
            if off is not None:   # a matrix leaves an error's constant part to the work offset
                res = shifted(res, off)
            out.shares.append(ErrorShare(name, Residual.of([tool_error(exact, vals, q, q) for q in sets]),
                                         Residual.of(res)))
    if reversal:
        with_reversal(tables, reversal)
    return out


def _i_alone(c: np.ndarray) -> np.ndarray:
    """The matrix Marlin applies with M852's I alone: built without SKEW_CORRECTION_FOR_Z its
    M852 reads no J or K and planner.h skew() moves x by -xy.y only."""
    only = np.eye(3)
    only[0, 1] = c[0, 1]
    return only


def _xy_only(lin: list[Symbol], c: np.ndarray, sets: list[dict], exact: ExactModel, values: dict) -> list[np.ndarray]:
    """The tool error when Marlin applies M852's I alone (_i_alone)."""
    return [tool_error(exact, values, q, apply_matrix(lin, _i_alone(c), q)) for q in sets]


MARLIN_WINDOW = ("Marlin's skew() corrects a point only with X and Y at least 1 mm above their minimum and the "
                 "corrected X and Y inside the limits (planner.h)")
KLIPPER_WINDOW = "Klipper refuses a move whose corrected X or Y leaves the limits ('Move out of range')"


def skew_window(fmt: str, lin: list[Symbol], c: np.ndarray, q: dict) -> np.ndarray:
    """Where a printer firmware (marlin, klipper) applies its skew at the commands ``q`` (flat):
    Marlin planner.h skew() only where X_MIN_POS + 1 <= X <= X_MAX_POS and likewise Y, and the
    skewed X and Y within [MIN_POS, MAX_POS] (elsewhere the point passes uncorrected); Klipper's
    toolhead refuses a move whose skewed position leaves an axis' limits (skew_correction.py
    transforms the move before the kinematics' check). The machine's limits of the first two
    linear axes stand for the firmware's X and Y limits (mm)."""
    skewed = apply_matrix(lin, c, q)
    ok = np.ones(_shape(q), bool)
    for a in lin[:2]:
        lo, hi = sorted(a.to_internal(float(v)) for v in a.limits)
        ok &= (skewed[a.name] >= lo) & (skewed[a.name] <= hi)
        if fmt == "marlin":
            ok &= (q[a.name] >= lo + 1.0) & (q[a.name] <= hi)
    return ok


def _uncorrected(fmt: str, lin: list[Symbol], c: np.ndarray, sets: list[dict], windows: list[np.ndarray],
                 touched_off: list[np.ndarray]) -> Uncorrected:
    """The check points outside the firmware's windows (skew_window), and what they keep."""
    past = 0.0
    for q, w in zip(sets, windows):
        skewed = apply_matrix(lin, c, q)
        for a in lin[:2]:
            lo, hi = sorted(a.to_internal(float(v)) for v in a.limits)
            past = max(past, float(np.maximum(lo - skewed[a.name], skewed[a.name] - hi)[~w].max(initial=0.0)))
    outside = [~w for w in windows]
    n = sum(int(np.count_nonzero(o)) for o in outside)
    left = Residual.of(_where(touched_off, outside)) if fmt == "marlin" and n else None
    return Uncorrected(n, sum(w.size for w in windows), MARLIN_WINDOW if fmt == "marlin" else KLIPPER_WINDOW,
                       past, left)


def _touched_off(dp: list[np.ndarray]) -> Residual:
    """The residual once the constant error is touched off (its mean over the check points)."""
    mean = np.concatenate([d.reshape(3, -1) for d in dp], axis=1).mean(axis=1)
    return Residual.of([d - mean.reshape(3, *([1] * (d.ndim - 1))) for d in dp])


def _held_at_the_ends(machine: Machine, values: dict) -> dict:
    """A table or polynomial that rejects outside its range must cover its axis' limits (the
    grid reaches them); the corrected positions then pass its ends by the trims (um), where it
    is held: the error there is the end's."""
    out = dict(values)
    for name, v in varying_errors(values).items():
        if v.outside == "reject":
            lo, hi = machine.symbol(v.axis).limits
            for t in (lo, hi):
                v.check_inside(machine.symbol(v.axis).to_internal(t))
            out[name] = dataclasses.replace(v, outside="hold")
    return out


def _nonzero(v) -> bool:
    return not isinstance(v, (int, float)) or v != 0.0


# ----------------------------------------------------------------------------- writers

def linuxcnc_comp_text(table: JointTable, file_type: int) -> str:
    """The COMP_FILE: one "nominal forward reverse" triplet per line, nothing else (LinuxCNC's
    reader, usrmotintf.cc usrmotLoadComp, stops at the first line that is not three numbers).
    Type 0 gives the positions the axis reaches (nominal - trim), type 1 the trims. Numbers
    are written to round trip (repr); a table whose entries or trims the file cannot carry
    (entries too close for their magnitude, a trim lost in nominal - trim) is refused."""
    lines = []
    for nom, fwd, rev in zip(table.nominal, table.forward, table.reverse):
        if file_type == 0:
            fwd, rev = nom - fwd, nom - rev
        lines.append(f"{float(nom)!r} {float(fwd)!r} {float(rev)!r}")
    a = table.axis
    read = np.array([[float(v) for v in line.split()] for line in lines])
    if not np.all(np.diff(read[:, 0]) > 0):
        raise ChaincompError(f"joint {a.name}: {len(lines)} entries over [{a.limits[0]:g}, {a.limits[1]:g}] "
                             f"{a.unit.name} cannot be told apart in a compensation file: lower --entries")
    trims = read[:, :1] - read[:, 1:] if file_type == 0 else read[:, 1:]
    lost = np.abs(a.to_internal(trims - np.stack([table.forward, table.reverse], axis=1)))
    if lost.max() > 1e-7:   # internal units: 0.1 nm or 0.1 urad
        raise ChaincompError(f"joint {a.name}: COMP_FILE_TYPE {file_type} loses up to {lost.max():.3g} (internal "
                             f"units) of the trims at positions of this magnitude: use --comp-file-type 1")
    return "\n".join(lines) + "\n"


# LinuxCNC src/emc/motion/control.c compute_screw_comp: a joint with comp entries takes its
# forward/reverse trims from them and [JOINT_n]BACKLASH is applied only to a joint without
BACKLASH_NOTE = ("LinuxCNC ignores [JOINT_n]BACKLASH once a COMP_FILE is loaded (control.c): remove BACKLASH "
                 "and put the reversal into the table with --mean-reversal AXIS=VALUE, ISO 230-2's signed mean "
                 "reversal as 'chaincomp iso230-2' prints it (measured with BACKLASH = b in effect: that value "
                 "minus b)")


def linuxcnc_ini_text(e: Export, file_type: int, files: list[str]) -> str:
    lines = [f"# chaincomp export {e.format}: compensation tables for {e.machine.name}, joints in this order:",
             f"# {', '.join(t.axis.name for t in e.tables)}; values in the axes' units "
             f"({', '.join(f'{t.axis.name} {t.axis.unit.name}' for t in e.tables)}). Paste each block into "
             "the [JOINT_n] section of the INI file.", f"# {BACKLASH_NOTE}."]
    for n, (t, f) in enumerate(zip(e.tables, files)):
        lines += [f"[JOINT_{n}]", f"COMP_FILE = {f}", f"COMP_FILE_TYPE = {file_type}",
                  f"# the table's mean reversal: {t.mean_reversal:.6g} {t.axis.unit.name}; no BACKLASH line"]
    return "\n".join(lines) + "\n"


def matrixkins_text(e: Export) -> str:
    names = "xyz"
    lines = [f"# chaincomp export linuxcnc-matrixkins for {e.machine.name}: joint = C . axis on "
             f"{', '.join(e.linear)} (KINEMATICS = matrixkins: LinuxCNC 2.10, not in 2.9)",
             "# constant offset left to the work offset (G54/G10 L2): "
             + " ".join(f"{v * 1e3:+.3f}" for v in e.offset) + " um"]
    for i in range(3):
        for k in range(3):
            lines.append(f"setp matrixkins.C_{names[i]}{names[k]} {e.matrix[i, k]:.12g}")
    return "\n".join(lines + matrixkins_passthrough(e)) + "\n"


def matrixkins_passthrough(e: Export) -> list[str]:
    """matrixkins hands joints 3.. to the axes A, B, C, U, V, W in that order, whatever the
    machine's letters (matrixkins.comp kinematicsForward/Inverse): say which axis each joint
    after the linear ones becomes, so an XYZAC machine sees its C land on B."""
    others = [a for a in e.joints if a.name not in e.linear]
    if not others:
        return []
    pairs = ", ".join(f"joint {3 + n} ({a.name}) <-> axis {'ABCUVW'[n]}" for n, a in enumerate(others[:6]))
    return [f"# matrixkins passes the joints after X, Y, Z through in the order A, B, C, U, V, W: {pairs}. "
            "Give each of them the program letter it gets, or use matrixkins on a three-axis machine."]


def skew_factors(e: Export) -> dict[str, float]:
    """The Marlin/Klipper factors xy, xz, yz of the fitted matrix: motor x = x - y.xy -
    z.(xz - xy.yz), motor y = y - z.yz (Marlin planner.h skew(), Klipper skew_correction.py)."""
    c = e.matrix
    xy, yz = -c[0, 1], -c[1, 2]
    return {"xy": xy, "xz": -c[0, 2] + xy * yz, "yz": yz}


def to_json(e: Export) -> dict:
    def res(r: Residual | None):
        return None if r is None else {"max_um": r.max * 1e3, "rms_um": r.rms * 1e3}
    doc = {"format": e.format, "machine": e.machine.name, "grid": e.grid, "check_points": e.grid_points,
           "knot_axes": e.knot_axes,
           "before": res(e.before), "after": res(e.after)}
    if e.tables:
        doc["joints"] = [{"axis": t.axis.name, "unit": t.axis.unit.name, "entries": len(t.nominal),
                          "largest_trim": float(np.max(np.abs(t.forward))), "mean_reversal": t.mean_reversal}
                         for t in e.tables]
        doc["backlash"] = BACKLASH_NOTE
    if e.matrix is not None:
        doc["linear_axes"] = e.linear
        doc["matrix"] = e.matrix.tolist()
        doc["offset_um"] = (e.offset * 1e3).tolist()
        doc["after_offset"] = res(e.after_offset)
    if e.without_z is not None:
        doc["without_skew_correction_for_z"] = res(e.without_z)
    if e.uncorrected is not None:
        u = e.uncorrected
        doc["uncorrected"] = {"points": u.points, "of": u.of, "rule": u.rule, "past_limits_um": u.past_limits * 1e3,
                              "left": res(u.left)}
    if e.isg is not None:
        f = e.isg
        doc["isg"] = {"axes": {c: a.name for c, a in f.letters.items()}, "chain": f.chain,
                      "workpiece_axes": f.workpiece_axes, "names": f.names, "left_out": f.left_out,
                      "workpiece_side": f.workpiece_side, "records": f.records, "notes": f.notes,
                      "represented_only": res(f.represented_only)}
    doc["errors"] = [{"name": s.name, "before": res(s.before), "after": res(s.after),
                      "represented": s.represented} for s in e.shares]
    return doc


def to_text(e: Export) -> str:
    def um(r: Residual) -> str:
        return f"max {r.max * 1e3:.3f} um, RMS {r.rms * 1e3:.3f} um"
    between = (", and between every two entries of each joint" if e.tables else
               ", and between every two records of each table" if e.isg is not None and e.isg.records > 1 else "")
    if e.knot_axes:
        between += f", and at the params' table knots along {', '.join(e.knot_axes)}"
    between += ", each point once"
    rule = ("the file as ISG holds it, composed as ISO 230-1 on this model" if e.isg is not None else
            "the controller's own rule")
    lines = [f"export {e.format} for {e.machine.name}: checked on {e.grid_points} points "
             f"({e.grid} per axis over the limits{between})",
             f"  tool-point error without compensation: {um(e.before)}",
             f"  with it ({rule}): {um(e.after)}"]
    if e.tables:
        lines.append("  " + "; ".join(f"{t.axis.name}: {len(t.nominal)} entries, largest trim "
                                       f"{np.max(np.abs(t.forward)):.6g} {t.axis.unit.name}" for t in e.tables))
        if any(t.mean_reversal for t in e.tables):
            lines.append("  mean reversal B̄ in the tables: " + ", ".join(f"{t.axis.name} {t.mean_reversal:.6g} "
                                                                         f"{t.axis.unit.name}" for t in e.tables))
        lines.append(f"  {BACKLASH_NOTE}")
    if e.matrix is not None:
        lines.append(f"  once the constant offset {', '.join(f'{v * 1e3:+.3f}' for v in e.offset)} um "
                     f"(x, y, z) is touched off: {um(e.after_offset)}")
        lines.append("  C (joint = C . axis, " + ", ".join(e.linear) + "): "
                     + "; ".join(" ".join(f"{v:.9f}" for v in row) for row in e.matrix))
        if e.format == "linuxcnc-matrixkins":
            lines += ["  " + line.lstrip("# ") for line in matrixkins_passthrough(e)]
        if e.without_z is not None:
            lines.append(f"  {MARLIN_FOR_Z}: with I alone, once touched off: {um(e.without_z)}")
        if e.uncorrected is not None:
            u, marlin = e.uncorrected, e.format == "marlin"
            past = (f" (the corrected X or Y up to {u.past_limits * 1e3:.3f} um past the limits)"
                    if u.past_limits > 0 else "")
            rest = (f"{u.points} it leaves uncorrected{past}: {um(u.left)} there, once touched off" if marlin else
                    f"{u.points} it refuses{past}") if u.points else "no other"
            lines.append(f"  {u.rule}: the residuals above are over the {u.of - u.points} of {u.of} points it "
                         f"{'corrects' if marlin else 'moves to'}; {rest}")
    if e.isg is not None:
        f = e.isg
        lines.append(f"  axes {', '.join(f'{c}={a.name}' for c, a in f.letters.items())}; chain {f.chain} "
                     f"(workpiece to tool), workpiece_axes {f.workpiece_axes}; {f.records} "
                     f"record{'s' if f.records != 1 else ''}")
        lines += [f"  note: {n}" for n in f.notes]
        lines.append(f"  with the errors it carries alone: {um(f.represented_only)}")
        if f.left_out:
            reasons: dict[str, list[str]] = {}
            for k, why in f.left_out.items():
                reasons.setdefault(why, []).append(k)
            lines.append("  no ISG name for: " + "; ".join(f"{' '.join(ks)} ({why})" for why, ks in reasons.items()))
    if e.shares:
        left = [s for s in e.shares if s.represented != "yes"]
        lines.append("  represented: " + (" ".join(s.name for s in e.shares if s.represented == "yes") or "none"))
        if left:
            lines.append("  left out, each alone (max um without -> with the format):")
            lines += [f"    {s.name:<10} {s.before.max * 1e3:9.3f} -> {s.after.max * 1e3:9.3f}  "
                      f"{'not representable' if s.represented == 'no' else 'partly represented'}" for s in left]
    return "\n".join(lines)


KLIPPER_SIDE = 100.0   # mm: side AD of the calibration square SET_SKEW's lengths describe


def klipper_lengths(factor: float, side: float = KLIPPER_SIDE) -> tuple[float, float, float]:
    """AC, BD, AD of the square (sides ``side``) whose angle at A gives ``factor``: Klipper's
    calc_skew_factor takes factor = cot(angle DAB) (klippy/extras/skew_correction.py)."""
    theta = np.arctan2(1.0, factor)
    return (side * float(np.sqrt(2 * (1 + np.cos(theta)))), side * float(np.sqrt(2 * (1 - np.cos(theta)))), side)


MARLIN_FOR_Z = "M852's J (XZ) and K (YZ) act only in a Marlin built with SKEW_CORRECTION_FOR_Z"


def skew_text(e: Export) -> str:
    """The firmware's commands, with the state they need set first. Marlin M852
    (gcode/calibrate/M852.cpp) and Klipper SET_SKEW (docs/G-Codes.md) take the factors of
    skew_factors(); M852 reads them with value_linear_units(), x25.4 after a G20, so G21
    comes first. RepRapFirmware M556 (Move.cpp AxisTransform: x += tanXY.y + tanXZ.z,
    y += tanYZ.z) adds, with X = S.tanXY, Y = S.tanYZ, Z = S.tanXZ (GCodes2.cpp case 556),
    and keeps an earlier P (P1: the XY term on Y) unless P is given: P0 is written."""
    f = skew_factors(e)
    if e.format == "marlin":
        return "\n".join([f"; {MARLIN_FOR_Z}; without it I alone leaves max {e.without_z.max * 1e3:.3f} um once "
                          "touched off (chaincomp export's report)",
                          "; M852 reads its factors in the current length unit (x25.4 after G20): G21 (mm) first, "
                          "and it stays in force",
                          "G21", f"M852 I{f['xy']:.9f} J{f['xz']:.9f} K{f['yz']:.9f}"])
    if e.format == "klipper":
        planes = {p: ",".join(f"{v:.9f}" for v in klipper_lengths(f[p.lower()])) for p in ("XY", "XZ", "YZ")}
        return "SET_SKEW " + " ".join(f"{p}={v}" for p, v in planes.items())
    c, s = e.matrix, KLIPPER_SIDE
    return "\n".join(["; P0 (the XY term corrects X, RRF's default) replaces an earlier M556 P1, which M556 "
                      "without P keeps",
                      f"M556 S{s:g} X{s * c[0, 1]:.9f} Y{s * c[1, 2]:.9f} Z{s * c[0, 2]:.9f} P0"])
