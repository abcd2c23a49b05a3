"""``chaincomp export --format isg-volcomp``: the errors in the ISG kernel's (Beckhoff TwinCAT
CNC's) volumetric compensation, an ISG CSV parameter file and its compensation list.

Written from ISG's kernel manual, *Volumetric compensation* (isg-stuttgart.de/fileadmin/
kernel/kernel-html/en-GB/, the same pages at infosys.beckhoff.com tf5280_volumetric_comp):

- 296386187 Overview: serial kinematics with exactly three linear axes X, Y, Z and up to
  three rotary axes A, B, C; the model is ISO 230-1's, after ISO/TR 16907; only the tool's
  position is compensated (by the axis setpoints), not its orientation.
- 296423819 List of parameters supported: component errors EXX..ECC (ISO 230-1 names, a
  function of the axis), position errors X0X..C0C (ISO 230-1's location errors without the
  leading E: EC0Y is C0Y).
- 296426379 Units of measure: values in mm or rad; arguments in mm (X, Y, Z) or degrees.
- 296429067 ISG CSV format: a header of argument and parameter names, rows below, ``//``
  starts a comment, ``#`` a file break (a new header follows).
- 296390283 General configuration: the compensation list (axis letters to logical axis
  numbers, ``file[j]``, ``file_format[j] ISG_CSV``), ``max_records`` in the start-up list.
- 106014347 (P-VOLC-00008) workpiece_axes: how many axes of the chain lie on the workpiece
  side; 296412555 names a chain by its axes from the workpiece to the tool (``CBYXZ``).
- 1218769547 Updating: an example list with ``interpolation GRID`` (linear between the
  records).

What chaincomp can state and what it cannot. The file carries each error under its ISO 230-1
name, sampled where it varies; how the controller composes them is ISO 230-1's definition
of each error (the tool relative to the workpiece), which is the machine file's own when the
file follows the standard, as the bundled machines do. ISG's pages cite the standard but do
not print its formula, so the residual reported is what the format itself loses: errors it
has no name for, a table between its records (GRID, linear), the numbers as written, and the
controller's one correction step (the deviation at the commanded position taken off the
linear axes), all on the machine's exact model. It is not a check of ISG's arithmetic."""

from __future__ import annotations

import re
from dataclasses import dataclass, field

import numpy as np

from ..errors import ChaincompError
from ..model.machine import Machine, Rotation, Symbol
from ..model.varying import Table, Varying
from . import export as X

FORMAT = "isg-volcomp"
LINEAR, ROTARY = "XYZ", "ABC"
COMPONENT = re.compile(r"E([XYZABC])([XYZABC])$")    # EXX .. ECC: error d of axis a
LOCATION = re.compile(r"E([XYZABC])0([XYZABC])$")    # EX0A .. EC0C: location error d of axis a
MAX_ROWS = 100_000          # records in one file (the controller's max_records bounds it too)
MAX_VALUE = 1e3             # mm or rad: a larger "error" is a mistake, and plain decimals lose digits beyond it
CSV_FILE, LIST_FILE = "volcomp.csv", "volcomp.lis"
DECIMALS = {"length": 9, "angle": 12}   # mm to the pm, rad to the prad: plain decimals, no exponent
ARGUMENT_DECIMALS = 6


@dataclass
class Block:
    """One block of the CSV: an argument (axis letter) or none (constants), its errors."""
    argument: str | None
    names: list[str]          # ISG names, in the header's order
    rows: np.ndarray          # (records, 1 + len(names)) with an argument, (1, len(names)) without


@dataclass
class IsgFile:
    letters: dict[str, Symbol]          # ISO letter -> the machine's axis
    chain: str                          # letters from the workpiece to the tool
    workpiece_axes: int
    names: dict[str, str]               # the machine's error -> ISG name (the represented ones)
    left_out: dict[str, str]            # the machine's error -> why the format cannot carry it
    blocks: list[Block] = field(default_factory=list)
    represented_only: X.Residual | None = None  # the residual with the represented errors alone


# ----------------------------------------------------------------------------- axes and names

def letters_of(machine: Machine, given: dict[str, str] | None) -> dict[str, Symbol]:
    """ISO letter -> axis: ``given`` (--iso-axes), else each axis named X..C, or a rotary axis
    whose name starts with A, B or C. Every axis must have one: the controller's chain is
    exactly three linear axes X, Y, Z and up to three rotary A, B, C."""
    axes = machine.axes
    hint = "name them with --iso-axes, e.g. --iso-axes X=X1,Y=Y1,Z=Z1,A=Ap"
    out: dict[str, Symbol] = {}
    if given:
        for letter, name in given.items():
            if letter not in LINEAR + ROTARY:
                raise ChaincompError(f"--iso-axes {letter}={name}: {letter} is not an ISO axis letter (X Y Z A B C)")
            if name not in [a.name for a in axes]:
                raise ChaincompError(f"--iso-axes {letter}={name}: not an axis of {machine.name} "
                                     f"({', '.join(a.name for a in axes)})")
            if name in [a.name for a in out.values()]:
                raise ChaincompError(f"--iso-axes: {name} is given two letters")
            out[letter] = machine.symbol(name)
    else:
        for a in axes:
            if a.name in LINEAR + ROTARY:
                letter = a.name
            elif a.unit.kind == "angle" and a.name[0].upper() in ROTARY:
                letter = a.name[0].upper()
            else:
                continue
            if letter in out:
                raise ChaincompError(f"--format {FORMAT}: axes {out[letter].name} and {a.name} of "
                                     f"{machine.name} would both be {letter}: {hint}")
            out[letter] = a
    for letter, a in out.items():
        want = "length" if letter in LINEAR else "angle"
        if a.unit.kind != want:
            raise ChaincompError(f"--format {FORMAT}: {letter} is a {'linear' if want == 'length' else 'rotary'} "
                                 f"axis in ISO 230-1, but {a.name} of {machine.name} is in {a.unit.name}: {hint}")
    missing = [a.name for a in axes if a not in out.values()]
    if missing or not set(LINEAR) <= set(out):
        raise ChaincompError(f"--format {FORMAT} needs three linear axes X, Y, Z and at most three rotary A, B, "
                             f"C, each axis with its letter (ISG: serial kinematics with exactly three linear "
                             f"axes); {machine.name} has " + (f"no letter for {', '.join(missing)}" if missing else
                             f"no {', '.join(sorted(set(LINEAR) - set(out)))}") + f": {hint}")
    return out


def isg_name(machine: Machine, error: Symbol, letters: dict[str, Symbol]) -> tuple[str | None, str]:
    """The ISG name of an error, or None and why the format has none."""
    m = COMPONENT.match(error.name) or LOCATION.match(error.name)
    if not m:
        return None, "not an ISO 230-1 name (EXX..ECC, EX0A..EC0C)"
    direction, axis = m.groups()
    if axis not in letters:
        return None, f"{machine.name} has no {axis} axis"
    want = "length" if direction in LINEAR else "angle"
    if error.unit.kind != want:
        return None, f"ISO 230-1's {error.name} is {'a length' if want == 'length' else 'an angle'}, " \
                     f"this one is in {error.unit.name}"
    return (error.name if m.re is COMPONENT else error.name[1:]), ""


def chain_order(machine: Machine, letters: dict[str, Symbol]) -> tuple[str, int]:
    """The letters in the order the chain meets the axes from the workpiece to the tool, and
    how many of them lie on the workpiece side (P-VOLC-00008)."""
    by_name = {a.name: letter for letter, a in letters.items()}

    def order(elements) -> list[str]:
        seen: list[str] = []
        for e in elements:
            names = e.expr.names if isinstance(e, Rotation) else frozenset().union(*(x.names for x in e.exprs))
            for n in sorted(names):
                if n in by_name and by_name[n] not in seen:
                    seen.append(by_name[n])
        return seen

    both = set(order(machine.workpiece_chain)) & set(order(machine.tool_chain))
    if both:
        raise ChaincompError(f"--format {FORMAT}: {', '.join(letters[c].name for c in sorted(both))} of "
                             f"{machine.name} moves both the tool and the workpiece side: not the serial chain "
                             f"ISG's volumetric compensation describes")
    return "".join(order(machine.chain)), len(order(machine.workpiece_chain))


def check_directions(machine: Machine, values: dict, letters: dict[str, Symbol]) -> None:
    """X, Y and Z must move the tool along x, y and z (ISO 841): at the middle of the limits,
    each one's direction of motion relative to the workpiece lies within 45 degrees of its own
    coordinate axis, or the file's EXX would be another axis' error."""
    exact = X.ExactModel(machine)
    q = {a.name: np.asarray(a.to_internal(sum(a.limits) / 2), float) for a in machine.axes}
    for k, c in enumerate(LINEAR):
        a = letters[c]
        d = X._jacobian_column(exact, values, q, a.name).reshape(3)
        n = float(np.linalg.norm(d))
        if not n or abs(d[k]) < 0.7071 * n:
            raise ChaincompError(f"--format {FORMAT}: {c} must move the tool along {c.lower()} (ISO 841), but "
                                 f"{a.name} of {machine.name} moves it along ({d[0] / n:.3f}, {d[1] / n:.3f}, "
                                 f"{d[2] / n:.3f}) at the middle of its limits" if n else
                                 f"--format {FORMAT}: {a.name} of {machine.name} does not move the tool")


# ----------------------------------------------------------------------------- the file

def written_argument(axis: Symbol) -> float:
    """Internal units (mm, rad) to the file's arguments: mm, or degrees (296426379)."""
    return 1.0 if axis.unit.kind == "length" else 180.0 / np.pi


def _records(machine: Machine, axis: Symbol, entries: int, varying: dict[str, Varying]) -> np.ndarray:
    """The arguments of a block as written (mm or deg, rounded to 1e-6): ``entries`` equally
    spaced over the axis' limits, and the knots of its tables inside them (GRID is then exact
    on a linear table; a monotone cubic gets its own knots and the points between). Knots the
    rounding would merge are refused: the file could not tell them apart."""
    k = written_argument(axis)
    unit = "mm" if axis.unit.kind == "length" else "deg"
    lo, hi = sorted(axis.to_internal(v) * k for v in axis.limits)
    pts = [np.linspace(lo, hi, entries)]
    for name, v in varying.items():
        if isinstance(v, Table):
            knots = np.asarray(v.x, float) * k
            knots = knots[(knots > lo) & (knots < hi)]
            if len(np.unique(np.round(knots, ARGUMENT_DECIMALS))) < len(knots):
                raise ChaincompError(f"{name}: knots of its table closer than 1e-{ARGUMENT_DECIMALS} {unit} cannot "
                                     f"be told apart in an ISG CSV file (arguments to 1e-{ARGUMENT_DECIMALS} {unit})",
                                     v.file, v.line, v.key)
            pts.append(knots)
    out = np.unique(np.round(np.concatenate(pts), ARGUMENT_DECIMALS))
    if len(out) < min(entries, 2):
        raise ChaincompError(f"axis {axis.name}: its limits [{axis.limits[0]:g}, {axis.limits[1]:g}] "
                             f"{axis.unit.name} are too close for {entries} records 1e-{ARGUMENT_DECIMALS} {unit} "
                             f"apart: nothing written")
    return out + 0.0


def build(machine: Machine, values: dict, letters: dict[str, Symbol], entries: int) -> IsgFile:
    chain, work = chain_order(machine, letters)
    names, left = {}, {}
    for e in machine.errors:
        v = values.get(e.name, 0.0)
        if not X._nonzero(v):
            continue
        name, why = isg_name(machine, e, letters)
        if name is None:
            left[e.name] = why
        else:
            names[e.name] = name
    f = IsgFile(letters, chain, work, names, left)
    constants = [e for e in names if not isinstance(values[e], Varying)]
    if constants:
        f.blocks.append(Block(None, [names[e] for e in constants], np.array([[values[e] for e in constants]])))
    letter_of = {a.name: letter for letter, a in letters.items()}
    by_axis: dict[str, list[str]] = {}
    for e in names:
        if isinstance(values[e], Varying):
            by_axis.setdefault(values[e].axis, []).append(e)
    for axis_name in [letters[c].name for c in LINEAR + ROTARY if c in letters]:
        errs = by_axis.get(axis_name, [])
        if not errs:
            continue
        axis = machine.symbol(axis_name)
        args = _records(machine, axis, entries, {e: values[e] for e in errs})
        t = args / written_argument(axis)          # the errors at the arguments as written
        cols = [np.broadcast_to(np.asarray(values[e](t), float), t.shape) for e in errs]
        f.blocks.append(Block(letter_of[axis_name], [names[e] for e in errs], np.column_stack([args] + cols)))
    for b in f.blocks:
        for k, n in enumerate(b.names):
            col = b.rows[:, k + (b.argument is not None)]
            e = next(e for e, m in names.items() if m == n)
            big = np.abs(col) >= MAX_VALUE
            if big.any() or not np.all(np.isfinite(col)):
                raise ChaincompError(f"{e}: {float(col[np.argmax(big | ~np.isfinite(col))]):g} "
                                     f"{'mm' if machine.symbol(e).unit.kind == 'length' else 'rad'} somewhere on its "
                                     f"axis: an ISG CSV file carries errors below {MAX_VALUE:g} (plain decimals to "
                                     f"1e-9 mm): nothing written")
    rows = sum(len(b.rows) for b in f.blocks)
    if rows > MAX_ROWS:
        raise ChaincompError(f"--entries {entries}: the file would hold {rows} records (at most {MAX_ROWS}): "
                             f"lower --entries")
    return f


def csv_text(machine: Machine, f: IsgFile) -> str:
    kind = {}
    for e, n in f.names.items():
        kind[n] = machine.symbol(e).unit.kind
    lines = [f"// chaincomp export {FORMAT} for {machine.name}: ISG CSV, values in mm and rad, arguments in "
             f"mm and degrees",
             f"// axes {', '.join(f'{c}={a.name}' for c, a in f.letters.items())}; chain {f.chain} "
             f"(workpiece to tool), workpiece_axes {f.workpiece_axes}"]
    for k, b in enumerate(f.blocks):
        if k:
            lines.append("#")
        header = ([b.argument] if b.argument else []) + b.names
        lines.append("// " + ("constant errors" if b.argument is None else f"errors along {b.argument}"))
        lines.append(" ".join(header))
        for row in b.rows:
            cells = []
            if b.argument:
                cells.append(f"{row[0]:.{ARGUMENT_DECIMALS}f}")
                row = row[1:]
            cells += [f"{round(v, DECIMALS[kind[n]]) + 0.0:.{DECIMALS[kind[n]]}f}" for n, v in zip(b.names, row)]
            lines.append(" ".join(cells))
    return "\n".join(lines) + "\n"


def list_text(machine: Machine, f: IsgFile, joints: list[Symbol]) -> str:
    rows = sum(len(b.rows) for b in f.blocks)
    number = {a.name: n + 1 for n, a in enumerate(joints)}
    lines = [f"# chaincomp export {FORMAT} for {machine.name}: the compensation list of ISG's volumetric",
             "# compensation. Logical axis numbers in the joint order (--joints); check them against the",
             f"# channel's. In the start-up list (hochlauf.lis): vol_comp[0].max_records  {max(rows, 1)}"]
    lines += [f"{c} {number[a.name]}" for c, a in f.letters.items()]
    lines += ["# the axes from the workpiece to the tool, and how many lie on the workpiece side",
              f"chain {f.chain}", f"workpiece_axes {f.workpiece_axes}",
              "interpolation GRID", f"file[0] {CSV_FILE}", "file_format[0] ISG_CSV"]
    return "\n".join(lines) + "\n"


def read_csv(text: str) -> list[tuple[list[str], np.ndarray]]:
    """The blocks of an ISG CSV file as the controller splits them (296429067): ``//`` comments,
    ``#`` file breaks, a header then rows of numbers. Only what the exporter writes is read."""
    blocks: list[tuple[list[str], list[list[float]]]] = []
    header = None
    for raw in text.splitlines():
        line = raw.split("//", 1)[0].strip()
        if not line:
            continue
        if line.startswith("#"):
            header = None
            continue
        if header is None:
            header = line.split()
            blocks.append((header, []))
        else:
            blocks[-1][1].append([float(v) for v in line.split()])
    return [(h, np.array(r, float)) for h, r in blocks]


def controller_values(machine: Machine, f: IsgFile, text: str, values: dict) -> dict:
    """The errors as the controller holds them after reading ``text``: constants, and tables
    linear between records, held beyond them (GRID); errors it has no name for are zero."""
    out = {k: v for k, v in values.items() if machine.symbol(k).role != "error"}
    by_isg = {n: e for e, n in f.names.items()}
    arg_letters = {c: a for c, a in f.letters.items()}
    for header, rows in read_csv(text):
        if header[0] in arg_letters:
            axis = arg_letters[header[0]]
            t = rows[:, 0] / written_argument(axis)
            for k, n in enumerate(header[1:]):
                e = by_isg[n]
                out[e] = _linear_table(e, axis, t, rows[:, k + 1])
        else:
            for k, n in enumerate(header):
                out[by_isg[n]] = float(rows[0, k])
    return out


def _linear_table(error: str, axis: Symbol, x: np.ndarray, y: np.ndarray) -> Table:
    slope = np.diff(y) / np.diff(x)
    d = np.concatenate([slope[:1], (slope[1:] + slope[:-1]) / 2, slope[-1:]])
    zero = np.zeros_like(slope)
    return Table(error, axis.name, (axis.unit, axis.unit), "hold", float(x[0]), float(x[-1]),
                 interpolation="linear", x=x, y=y, d=d, b=slope, c=zero, e=zero)


# ----------------------------------------------------------------------------- the check

def corrected(exact, held: dict, q: dict, linear: list[Symbol]) -> dict:
    """The setpoints the controller drives to: the deviation its values predict at the
    commanded position, taken off the linear axes through the nominal model's derivative
    (one step, as a controller does per cycle; the second-order remainder is in the residual)."""
    d = X.tool_error(exact, held, q, q)
    jac = np.stack([X._jacobian_column(exact, held, q, a.name) for a in linear], axis=1)   # (3, 3, ...)
    shape = d.shape[1:]
    j = np.moveaxis(jac.reshape(3, 3, -1), -1, 0)
    step = np.linalg.solve(j, np.moveaxis(d.reshape(3, -1), -1, 0)[..., None])[..., 0]
    out = dict(q)
    for k, a in enumerate(linear):
        out[a.name] = q[a.name] - step[:, k].reshape(shape)
    return out


def between_records(axes: list[Symbol], grid: list[np.ndarray], f: IsgFile) -> list[dict]:
    """Per block with an argument, its records' midpoints along that axis x the other axes at
    their limits and middle: where GRID's straight line is furthest from the error (a chord's
    error moves the tool most at the ends of the lever arms, which the limits hold)."""
    sets = []
    for b in f.blocks:
        if b.argument is None:
            continue
        j = [a.name for a in axes].index(f.letters[b.argument].name)
        pos = axes[j].from_internal(b.rows[:, 0] / written_argument(axes[j]))
        sets.append(X._mesh(axes, [(pos[1:] + pos[:-1]) / 2 if k == j else
                                   (grid[k] if len(grid[k]) <= 3 else np.linspace(grid[k][0], grid[k][-1], 3))
                                   for k in range(len(axes))]))
    return sets


def export(machine: Machine, values: dict, joints: list[str] | None, points: int, entries: int,
           iso_axes: dict[str, str] | None = None, shares: bool = True, progress=None) -> tuple[X.Export, str, str]:
    """The file and its list for ``values`` (internal units), and what they leave on the exact
    model over the check grid and between every two records of each table."""
    axes = X.axes_of(machine, joints)
    letters = letters_of(machine, iso_axes)
    values = X._held_at_the_ends(machine, values)
    grid = X.check_grid(machine, axes, points)
    check_directions(machine, values, letters)
    f = build(machine, values, letters, entries)
    if not f.names:
        raise ChaincompError(f"--format {FORMAT} represents none of the errors given for {machine.name} (none has "
                             f"an ISO 230-1 name of its axes: " + ", ".join(f"{e}: {w}" for e, w in
                                                                             list(f.left_out.items())[:3]) +
                             "): nothing written")
    text = csv_text(machine, f)
    held = controller_values(machine, f, text, values)
    exact = X.ExactModel(machine)
    linear = [letters[c] for c in LINEAR]
    sets = [X._mesh(axes, grid)] + between_records(axes, grid, f)
    n_points = sum(int(np.prod(X._shape(q))) for q in sets)
    if n_points > X.MAX_POINTS:
        raise ChaincompError(f"the check would take {n_points} points (the grid, and between every two of the "
                             f"{sum(len(b.rows) for b in f.blocks)} records; at most {X.MAX_POINTS}): lower "
                             f"--grid or --entries")
    names = [s.name for s in machine.errors if X._nonzero(values.get(s.name, 0.0))]
    if shares and len(names) * n_points > X.MAX_BREAKDOWN // 4:
        raise ChaincompError(f"the breakdown would check each of {len(names)} errors alone on {n_points} points "
                             f"(at most {X.MAX_BREAKDOWN // 4} in all): lower --grid or add --no-breakdown")

    def residuals(true: dict, belief: dict) -> tuple[list, list]:
        before = [X.tool_error(exact, true, q, q) for q in sets]
        after = [X.tool_error(exact, true, q, corrected(exact, belief, q, linear)) for q in sets]
        return before, after

    before, after = residuals(values, held)
    for b, a, q in zip(before, after, sets):
        X._check_finite(machine, b, q, "the tool point with the errors given")
        X._check_finite(machine, a, q, f"the tool point with {FORMAT}'s correction")
    out = X.Export(FORMAT, machine, points, n_points, X.Residual.of(before), X.Residual.of(after))
    out.isg = f
    keep = set(f.names)
    _, only = residuals(X._errors_only(machine, values, keep), X._errors_only(machine, held, keep))
    f.represented_only = X.Residual.of(only)
    if shares:
        if progress:
            progress(f"{FORMAT} checked on {n_points} points; now each of the {len(names)} errors alone")
        for name in names:
            alone = X._errors_only(machine, values, {name})
            belief = X._errors_only(machine, held, {name} & keep)
            b, a = residuals(alone, belief)
            out.shares.append(X.ErrorShare(name, X.Residual.of(b), X.Residual.of(a), carried=name in keep))
    return out, text, list_text(machine, f, axes)
