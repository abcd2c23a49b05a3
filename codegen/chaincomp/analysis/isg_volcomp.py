"""``chaincomp export --controller isg-volcomp``: the errors in the ISG kernel's (Beckhoff TwinCAT
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
from ..model.machine import ROT_PLANE, Machine, Rotation, Symbol
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
    notes: list[str] = field(default_factory=list)   # what the user must set in the controller
    represented_only: X.Residual | None = None  # the residual with the represented errors alone
    workpiece_side: int = 0             # axes the machine file's loop puts on the workpiece side

    @property
    def records(self) -> int:
        return sum(len(b.rows) for b in self.blocks)


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
                raise ChaincompError(f"--controller {FORMAT}: axes {out[letter].name} and {a.name} of "
                                     f"{machine.name} would both be {letter}: {hint}")
            out[letter] = a
    for letter, a in out.items():
        want = "length" if letter in LINEAR else "angle"
        if a.unit.kind != want:
            raise ChaincompError(f"--controller {FORMAT}: {letter} is a {'linear' if want == 'length' else 'rotary'} "
                                 f"axis in ISO 230-1, but {a.name} of {machine.name} is in {a.unit.name}: {hint}")
    missing = [a.name for a in axes if a not in out.values()]
    if missing or not set(LINEAR) <= set(out):
        raise ChaincompError(f"--controller {FORMAT} needs three linear axes X, Y, Z and at most three rotary A, B, "
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
        raise ChaincompError(f"--controller {FORMAT}: {', '.join(letters[c].name for c in sorted(both))} of "
                             f"{machine.name} moves both the tool and the workpiece side: not the serial chain "
                             f"ISG's volumetric compensation describes")
    return "".join(order(machine.chain)), len(order(machine.workpiece_chain))


def _home(machine: Machine) -> dict:
    """The pose ISO 841 names the axes at: linear axes mid-travel, rotary axes at 0 (kept
    inside their limits), every constant nominal and every error zero."""
    q = machine.nominal_values()
    for a in machine.axes:
        lo, hi = sorted(a.to_internal(v) for v in a.limits)
        q[a.name] = float(np.clip(0.0, lo, hi)) if a.unit.kind == "angle" else (lo + hi) / 2
    return q


def check_directions(machine: Machine, letters: dict[str, Symbol], f: IsgFile) -> None:
    """X, Y and Z must move the tool along +x, +y and +z relative to the workpiece (within 45
    degrees at _home), and A, B, C whose errors are in the file turn about x, y and z (ISO 841):
    else the file's EXX would be another axis' error, or its sign the opposite. A rotary axis the
    file names no error of (an inclined one: inclined_axes) only gets a note: ISG describes it by
    VXA.. (296423819); one along another coordinate axis is refused (a letter to change)."""
    used = {n[-1] for n in f.names.values()} | {b.argument for b in f.blocks if b.argument}
    q = _home(machine)
    exact = X.ExactModel(machine)
    for k, c in enumerate(LINEAR):
        a = letters[c]
        d = X._jacobian_column(exact, q, {n: np.asarray(v, float) for n, v in q.items() if machine.symbol(n).role ==
                                           "axis"}, a.name).reshape(3)
        n = float(np.linalg.norm(d))
        if not n or d[k] < 0.7071 * n:
            raise ChaincompError(f"--controller {FORMAT}: {c} must move the tool along +{c.lower()} relative to the "
                                 f"workpiece (ISO 841), but {a.name} of {machine.name} moves it along "
                                 f"({d[0] / n:+.3f}, {d[1] / n:+.3f}, {d[2] / n:+.3f})" if n else
                                 f"--controller {FORMAT}: {a.name} of {machine.name} does not move the tool")
    for c, a in letters.items():
        if c in ROTARY:
            w = rotation_axis(machine, a.name, q)
            c_axis = "xyz"[ROTARY.index(c)]
            if abs(w["xyz".index(c_axis)]) >= np.cos(ALONG):
                continue
            if c not in used:   # inclined (its errors left out by inclined_axes), or without errors
                f.notes.append(f"{a.name} turns about ({w[0]:+.3f}, {w[1]:+.3f}, {w[2]:+.3f}), not about {c_axis}: "
                               f"no error of it is in the file; ISG describes such an axis by V{'XYZ'[0]}{c}, "
                               f"V{'XYZ'[1]}{c}, V{'XYZ'[2]}{c} (its modified orientation, 296423819)")
                continue
            raise ChaincompError(f"--controller {FORMAT}: {c} must turn about {c_axis} (ISO 841), but {a.name} of "
                                 f"{machine.name} turns about ({w[0]:+.3f}, {w[1]:+.3f}, {w[2]:+.3f}): name "
                                 f"the rotary axes with --iso-axes")


ALONG = 1e-9   # rad: a rotary axis within this of x, y or z turns about that axis


def inclined_axes(machine: Machine, letters: dict[str, Symbol]) -> dict[str, str]:
    """The rotary letters whose axis is inclined (a nutating table's B at 45 degrees), each with
    why its errors stay out of the file: ISO 230-1 names the location errors (EX0B ..) of an axis
    along x, y or z, and an ISG file holds no others. One rule at every angle: along its letter's
    axis the errors go in, inclined they are left out (and reported with what they leave)."""
    q = _home(machine)
    out = {}
    for c, a in letters.items():
        if c not in ROTARY:
            continue
        w = rotation_axis(machine, a.name, q)
        k = "xyz".index("xyz"[ROTARY.index(c)])
        off = float(np.arccos(min(1.0, abs(w[k]))))
        if off > ALONG and max(abs(w)) < np.cos(ALONG):
            out[c] = (f"{a.name} turns about ({w[0]:+.4f}, {w[1]:+.4f}, {w[2]:+.4f}), {np.degrees(off):.3f} degrees "
                      f"from {'xyz'[k]}: ISO 230-1's location errors are those of an axis along x, y or z, and "
                      "the ISG file has no others (an inclined axis is V" + c + " in ISG's terms, 296423819)")
    return out


def rotation_axis(machine: Machine, axis: str, q: dict) -> np.ndarray:
    """The unit direction a rotary axis turns about, in the workpiece frame at ``q``: the first
    rotation of the chain (workpiece to tool) whose angle uses the axis, its coordinate axis
    carried through the rotations before it."""
    r = np.eye(3)
    for e in machine.chain:
        if not isinstance(e, Rotation):
            continue
        if axis in e.expr.names:
            return r[:, "xyz".index(e.axis)]
        angle = e.expr.value(q)
        c, s_ = np.cos(angle), np.sin(angle)
        i, j = ROT_PLANE[e.axis]     # the plane it turns, in its positive sense (as the models do)
        step = np.eye(3)
        step[i, i], step[i, j], step[j, i], step[j, j] = c, -s_, s_, c
        r = r @ step
    raise ChaincompError(f"--controller {FORMAT}: rotary axis {axis} of {machine.name} turns no rotation of the chain")


# ----------------------------------------------------------------------------- the file

def argument_scale(axis: Symbol) -> float:
    """The factor from internal units (mm, rad) to the file's arguments: mm, or degrees (296426379)."""
    return 1.0 if axis.unit.kind == "length" else 180.0 / np.pi


def _records(axis: Symbol, entries: int, varying: dict[str, Varying]) -> np.ndarray:
    """The arguments of a block as written (mm or deg, rounded to 1e-6): ``entries`` equally
    spaced over the axis' limits, and the knots of its tables inside them (GRID is then exact
    on a linear table; a monotone cubic gets its own knots and the points between). Knots the
    rounding would merge are refused: the file could not tell them apart."""
    k = argument_scale(axis)
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
    if len(np.unique(np.round(pts[0], ARGUMENT_DECIMALS))) < entries:
        raise ChaincompError(f"axis {axis.name}: its limits [{axis.limits[0]:g}, {axis.limits[1]:g}] "
                             f"{axis.unit.name} are too close for {entries} records 1e-{ARGUMENT_DECIMALS} {unit} "
                             f"apart: nothing written")
    return out + 0.0


def build(machine: Machine, values: dict, letters: dict[str, Symbol], entries: int, workpiece_axes: int = 0) -> IsgFile:
    chain, work = chain_order(machine, letters)
    if not 0 <= workpiece_axes < len(chain):
        raise ChaincompError(f"--workpiece-axes {workpiece_axes}: expected 0 to {len(chain) - 1} (P-VOLC-00008: "
                             f"fewer than the {len(chain)} axes of the chain)")
    names, left = {}, {}
    inclined = inclined_axes(machine, letters)
    for e in machine.errors:
        v = values.get(e.name, 0.0)
        if not X._nonzero(v):
            continue
        name, why = isg_name(machine, e, letters)
        axis = name[-1] if name else ""
        if name is not None and axis in inclined:
            name, why = None, inclined[axis]
        if name is None:
            left[e.name] = why
        else:
            names[e.name] = name
    f = IsgFile(letters, chain, workpiece_axes, names, left, workpiece_side=work)
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
        args = _records(axis, entries, {e: values[e] for e in errs})
        t = args / argument_scale(axis)          # the errors at the arguments as written
        cols = [np.broadcast_to(np.asarray(values[e](t), float), t.shape) for e in errs]
        f.blocks.append(Block(letter_of[axis_name], [names[e] for e in errs], np.column_stack([args] + cols)))
    by_isg = {n: e for e, n in names.items()}
    for b in f.blocks:
        for k, n in enumerate(b.names):
            col = b.rows[:, k + (b.argument is not None)]
            e = by_isg[n]
            big = np.abs(col) >= MAX_VALUE
            if big.any() or not np.all(np.isfinite(col)):
                raise ChaincompError(f"{e}: {float(col[np.argmax(big | ~np.isfinite(col))]):g} "
                                     f"{'mm' if machine.symbol(e).unit.kind == 'length' else 'rad'} somewhere on its "
                                     f"axis: an ISG CSV file carries errors below {MAX_VALUE:g} (plain decimals to "
                                     f"1e-9 mm): nothing written")
    if f.records > MAX_ROWS:
        raise ChaincompError(f"the file would hold {f.records} records (--entries {entries} per varying error, and "
                             f"its table's knots; at most {MAX_ROWS}): lower --entries or thin the tables")
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
    number = {a.name: n + 1 for n, a in enumerate(joints)}
    lines = [f"# chaincomp export {FORMAT} for {machine.name}: the compensation list of ISG's volumetric",
             "# compensation, to check before use: the logical axis numbers below are the joint order",
             "# (--joints), not read from your channel's configuration; file[0] is relative, put the",
             "# controller's path there. In the start-up list (hochlauf.lis):",
             f"#   vol_comp[0].max_records  {max(f.records, 1)}"]
    lines += [f"{c} {number[a.name]}" for c, a in f.letters.items()]
    lines += ["# the axes from the workpiece to the tool (as the machine file's chain meets them)", f"chain {f.chain}",
              "# how many of them lie on the workpiece side for the measurement (P-VOLC-00008): the errors are",
              "# ISO 230-1's, the tool's relative to the workpiece, so 0 unless your measurement treated table",
              f"# axes otherwise (296411019); the machine file's loop puts {f.workpiece_side} on the workpiece side",
              f"workpiece_axes {f.workpiece_axes}",
              "interpolation GRID", f"file[0] {CSV_FILE}", "file_format[0] ISG_CSV"]
    lines += [f"# {n}" for n in f.notes]
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
    for header, rows in read_csv(text):
        if header[0] in f.letters:
            axis = f.letters[header[0]]
            t = rows[:, 0] / argument_scale(axis)
            for k, n in enumerate(header[1:]):
                e = by_isg[n]
                out[e] = _linear_table(machine.symbol(e), axis, t, rows[:, k + 1])
        else:
            for k, n in enumerate(header):
                out[by_isg[n]] = float(rows[0, k])
    return out


def _linear_table(error: Symbol, axis: Symbol, x: np.ndarray, y: np.ndarray) -> Table:
    slope = np.diff(y) / np.diff(x)
    d = np.concatenate([slope[:1], (slope[1:] + slope[:-1]) / 2, slope[-1:]])
    zero = np.zeros_like(slope)
    return Table(error.name, axis.name, (axis.unit, error.unit), "hold", float(x[0]), float(x[-1]),
                 interpolation="linear", x=x, y=y, d=d, b=slope, c=zero, e=zero)


# ----------------------------------------------------------------------------- the check

def corrected(exact, held: dict, q: dict, linear: list[Symbol]) -> dict:
    """The setpoints the controller is taken to drive to: the deviation its values predict at
    the commanded position, taken off the linear axes through the nominal model's derivative,
    once (ISG's pages do not say how it solves; one step leaves a second-order remainder, which
    is in the residual, where an iteration would not)."""
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
    their limits and middle: between records is where GRID's straight line departs from the
    error (the largest departure of a parabola's chord is at the midpoint; of other curves near
    it), and the limits hold the longest lever arms."""
    sets = []
    for b in f.blocks:
        if b.argument is None:
            continue
        j = [a.name for a in axes].index(f.letters[b.argument].name)
        pos = axes[j].from_internal(b.rows[:, 0] / argument_scale(axes[j]))
        sets.append(X._mesh(axes, [(pos[1:] + pos[:-1]) / 2 if k == j else
                                   (grid[k] if len(grid[k]) <= 3 else np.linspace(grid[k][0], grid[k][-1], 3))
                                   for k in range(len(axes))]))
    return sets


def export(machine: Machine, values: dict, joints: list[str] | None, points: int, entries: int,
           iso_axes: dict[str, str] | None = None, workpiece_axes: int = 0, shares: bool = True,
           progress=None) -> tuple[X.Export, str, str]:
    """The file and its list for ``values`` (internal units), and what they leave on the exact
    model over the check grid and between every two records of each table."""
    axes = X.axes_of(machine, joints)
    letters = letters_of(machine, iso_axes)
    values = X._held_at_the_ends(machine, values)
    grid = X.check_grid(machine, axes, points)
    f = build(machine, values, letters, entries, workpiece_axes)
    if not f.names:
        raise ChaincompError(f"--controller {FORMAT} represents none of the errors given for {machine.name} (none has "
                             f"an ISO 230-1 name of its axes: " + ", ".join(f"{e}: {w}" for e, w in
                                                                             list(f.left_out.items())[:3]) +
                             "): nothing written")
    check_directions(machine, letters, f)
    text = csv_text(machine, f)
    held = controller_values(machine, f, text, values)
    exact = X.ExactModel(machine)
    linear = [letters[c] for c in LINEAR]
    sets = [X._mesh(axes, grid)] + between_records(axes, grid, f)
    n_points = sum(int(np.prod(X._shape(q))) for q in sets)
    if n_points > X.MAX_POINTS:
        raise ChaincompError(f"the check would take {n_points} points (the grid, and between every two of the "
                             f"{f.records} records; at most {X.MAX_POINTS}): lower "
                             f"--grid or --entries")
    names = [s.name for s in machine.errors if X._nonzero(values.get(s.name, 0.0))]
    if shares and len(names) * n_points > X.MAX_BREAKDOWN // 4:
        raise ChaincompError(f"the breakdown would check each of {len(names)} errors alone on {n_points} points "
                             f"(at most {X.MAX_BREAKDOWN // 4} in all): lower --grid or add --no-breakdown")

    def uncompensated(true: dict) -> list:
        return [X.tool_error(exact, true, q, q) for q in sets]

    def compensated(true: dict, belief: dict) -> list:
        return [X.tool_error(exact, true, q, corrected(exact, belief, q, linear)) for q in sets]

    before, after = uncompensated(values), compensated(values, held)
    for b, a, q in zip(before, after, sets):
        X._check_finite(machine, b, q, "the tool point with the errors given")
        X._check_finite(machine, a, q, f"the tool point with {FORMAT}'s correction")
    out = X.Export(FORMAT, machine, points, n_points, X.Residual.of(before), X.Residual.of(after))
    out.isg = f
    keep = set(f.names)
    f.represented_only = X.Residual.of(compensated(X._errors_only(machine, values, keep),
                                                   X._errors_only(machine, held, keep)))
    if shares:
        if progress:
            progress(f"{FORMAT} checked on {n_points} points; now each of the {len(names)} errors alone")
        for name in names:
            alone = X._errors_only(machine, values, {name})
            belief = X._errors_only(machine, held, {name} & keep)
            out.shares.append(X.ErrorShare(name, X.Residual.of(uncompensated(alone)),
                                           X.Residual.of(compensated(alone, belief)), carried=name in keep))
    return out, text, list_text(machine, f, axes)
