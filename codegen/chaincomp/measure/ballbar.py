"""The circular test of ISO 230-4 (a ballbar): the trace the model predicts, its evaluation
(circular deviation G, radial deviation F, the least-squares circle), the trace CSV, and the
fit of the errors a ballbar sees by linear least squares on the model's gains.

Geometry. The axes are commanded so that the *nominal* tool point runs on the circle of
radius R about the centre, in the plane; the centre pivot of the ballbar stands on the table
(the workpiece side), fixed in the workpiece frame at the nominal centre, and the tool ball at
the tool point, so the ballbar measures |actual tool point − centre| − R: the radial
deviation, against the nominal angle. The angle turns right-handed about the plane's normal
(XY: from +x towards +y about +z; YZ: from +y towards +z; ZX: from +z towards +x); ccw is
that sense, cw the other. Internal units: mm and rad.

The trace CSV (written by ``write_trace``, read by ``read_trace``)::

    # chaincomp ballbar trace (ISO 230-4 circular test)
    # machine: vmc_xyz
    # plane: XY
    # axes: X, Y
    # radius: 100 mm
    # centre: 0, 0, 400 mm
    # held: Z=0 mm
    # feed: 1000 mm/min
    angle [deg],direction,deviation [um]
    0,ccw,0.4123
    ...

``# key: value`` lines before the header carry the test's set-up (plane, radius and centre
required; the others optional); other ``#`` lines and blank lines are comments. Columns:
``angle`` (the nominal angle, deg or rad), ``direction`` (ccw/cw), ``deviation`` (the radial
deviation, µm, mm or nm).
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass, field

import numpy as np

from ..errors import ChaincompError
from ..escape import one_line
from ..model import csvtable, units as U
from ..model.expressions import MAX_LITERAL
from ..model.machine import Machine
from ..model.numbers import parse_number
from ..model.params import parse_value
from ..model.varying import Varying
from ..output import write_file
from ..symbolic.jets import JetModel
from ..symbolic.numeric import ExactModel
from . import lsq
from .calibration import find_slides

# plane -> (first in-plane coordinate, second, normal): the angle turns from the first towards the second
PLANES = {"XY": (0, 1, 2), "YZ": (1, 2, 0), "ZX": (2, 0, 1)}
CCW, CW = "ccw", "cw"
_DIRECTIONS = {"ccw": CCW, "counterclockwise": CCW, "anticlockwise": CCW, "cw": CW, "clockwise": CW}
MIN_POINTS, MAX_POINTS = 8, 36_000     # per direction: the model is evaluated at every point
MAX_ROWS = 2 * MAX_POINTS
_TOL = 1e-9                            # mm: the nominal tool point on the circle, and in the plane
UM = 1e-3                              # one µm in mm
SMALL = 0.1                            # a ballbar reading is below this fraction of R


@dataclass
class Setup:
    """Where the test is made: plane, its two axes, radius, centre pivot, the other axes."""
    plane: str
    axes: tuple[str, str] | None          # the axes moving the tool along the plane's two directions
    radius: float                         # mm
    centre: np.ndarray                    # (3,) mm, workpiece frame: the centre pivot
    held: dict[str, float]                # every other axis, internal units
    feed: float | None = None             # mm/min, recorded only (the model is quasi-static)


@dataclass
class Trace:
    setup: Setup
    angle: np.ndarray                     # nominal angle, rad
    direction: np.ndarray                 # CCW or CW per point
    deviation: np.ndarray                 # ballbar length minus R, mm
    file: str = ""
    lines: list[int] = field(default_factory=list)
    where: dict[str, int] = field(default_factory=dict)   # set-up key -> its '# key:' line in the file

    def of(self, direction: str) -> tuple[np.ndarray, np.ndarray]:
        k = self.direction == direction
        return self.angle[k], self.deviation[k]


# ----------------------------------------------------------------------------- geometry

def _refuse(source: Trace | None, key: str, message: str, option: str | None = None):
    """A set-up that cannot be: read from a trace (its file and the line of ``key``), or given
    as options (``option`` names the one at fault)."""
    if source is not None:
        raise ChaincompError(message, source.file, source.where.get(key), key)
    raise ChaincompError(f"{option}: {message}" if option else message)


def _travel(machine: Machine, model: ExactModel, values: dict) -> dict[str, np.ndarray]:
    """Nominal tool-point motion per unit (internal) of each linear axis at ``values``."""
    out = {}
    for a in machine.axes:
        if a.unit.kind != "length":
            continue
        h = 1e-3
        plus, minus = dict(values), dict(values)
        plus[a.name] = values[a.name] + h
        minus[a.name] = values[a.name] - h
        out[a.name] = (np.array(model.pose(plus)[0], float) - np.array(model.pose(minus)[0], float)) / (2 * h)
    return out


def plane_axes(machine: Machine, plane: str, values: dict, given: list[str] | None = None,
               model: ExactModel | None = None, source: Trace | None = None) -> tuple[str, str]:
    """The linear axes that move the tool (relative to the workpiece) along the plane's two
    directions at ``values``, found from the nominal model, not from their names. source: the
    trace whose header gives plane and axes (refusals name its lines), else they are options."""
    model = model or ExactModel(machine)
    travel = _travel(machine, model, nominal(machine, values))
    picked = []
    for i, c in enumerate(PLANES[plane][:2]):
        coord = "xyz"[c]
        along = [a for a, u in travel.items() if np.linalg.norm(u) > 0 and abs(u[c]) > 0.99 * np.linalg.norm(u)]
        if given:
            name = given[i]
            if name not in [s.name for s in machine.axes]:
                _refuse(source, "axes", f"{name!r} is not an axis of {machine.name} "
                        f"(axes: {', '.join(s.name for s in machine.axes)})", "--axes")
            if name not in along:
                _refuse(source, "axes", f"{name} does not move the tool along {coord} here"
                        + (" (it is not a linear axis)" if name not in travel else
                           f" (it moves it by {np.round(travel[name], 6).tolist()} per mm)"), "--axes")
            picked.append(name)
            continue
        if not along:
            rotary = [s.name for s in machine.axes if s.unit.kind == "angle"]
            _refuse(source, "plane", f"no linear axis of {machine.name} moves the tool along {coord} "
                    f"here (linear axes: {', '.join(travel) or 'none'}"
                    + (f"; rotary axes {', '.join(rotary)} may be "
                       + ("held elsewhere in a '# held:' line)" if source else "set with --set)")
                       if rotary and travel else ")"), f"plane {plane}")
        if len(along) > 1:
            _refuse(source, "plane", f"axes {', '.join(along)} all move the tool along {coord}: "
                    + ("name two in a '# axes: A, B' line" if source else "choose with --axes"), f"plane {plane}")
        picked.append(along[0])
    if picked[0] == picked[1]:
        _refuse(source, "axes" if given else "plane",
                f"{picked[0]} cannot drive both directions of the circle", "--axes" if given else f"plane {plane}")
    return picked[0], picked[1]


def nominal(machine: Machine, values: dict) -> dict:
    """``values`` with every error at zero (varying ones too)."""
    out = dict(values)
    for s in machine.errors:
        out[s.name] = 0.0
    return out


def tool_point(model: ExactModel, values: dict) -> np.ndarray:
    """(..., 3) tool points for values that may hold arrays."""
    p = model.pose(values)[0]
    shape = np.broadcast_shapes(*[np.shape(v) for v in p])
    return np.stack([np.broadcast_to(np.asarray(v, float), shape) for v in p], axis=-1)


def circle_points(setup: Setup, angle: np.ndarray) -> np.ndarray:
    i, j, _ = PLANES[setup.plane]
    out = np.tile(setup.centre, (len(angle), 1))
    out[:, i] += setup.radius * np.cos(angle)
    out[:, j] += setup.radius * np.sin(angle)
    return out


def commanded(machine: Machine, model: ExactModel, setup: Setup, values: dict, angle: np.ndarray,
              source: Trace | None = None) -> dict:
    """The axis values (internal) that put the nominal tool point on the circle at ``angle``:
    Newton on the nominal exact model, the two plane axes moving, the others held. source: the
    trace the set-up was read from (refusals name its lines)."""
    i, j, n = PLANES[setup.plane]
    a, b = setup.axes
    base = nominal(machine, values)
    base.update(setup.held)
    travel = _travel(machine, model, base)
    jac = np.array([[travel[a][i], travel[b][i]], [travel[a][j], travel[b][j]]])
    target = circle_points(setup, angle)
    at = tool_point(model, base)
    if abs(at[n] - setup.centre[n]) > _TOL:
        c = "xyz"[n]
        held = ", ".join(f"{k} = {machine.symbol(k).from_internal(v):g} {machine.symbol(k).unit.name}"
                         for k, v in setup.held.items()) or "the other axes where they are"
        _refuse(source, "centre", f"the centre's {c} ({setup.centre[n]:g} mm) is not the tool's {c} with {held} "
                f"({at[n]:g} mm): the circle must lie in the plane the tool moves in (move the other axes, or "
                "the centre)")
    q = {a: np.full(len(angle), base[a]), b: np.full(len(angle), base[b])}
    for _ in range(8):
        p = tool_point(model, {**base, **q})
        res = np.stack([target[:, i] - p[:, i], target[:, j] - p[:, j]])
        step = np.linalg.solve(jac, res)
        q[a], q[b] = q[a] + step[0], q[b] + step[1]
    p = tool_point(model, {**base, **q})
    miss = np.abs(p - target)
    if not np.all(np.isfinite(p)) or miss[:, [i, j]].max() > _TOL:
        raise ChaincompError(f"the nominal tool point does not reach the circle by moving {a} and {b} "
                             f"(missed by {miss[:, [i, j]].max():.3g} mm)")
    if miss[:, n].max() > _TOL:
        raise ChaincompError(f"moving {a} and {b} on the circle takes the tool out of the {setup.plane} plane by "
                             f"{miss[:, n].max():.3g} mm: the axes do not travel in that plane here")
    for name in (a, b):
        s = machine.symbol(name)
        lo, hi = s.limits
        vals = s.from_internal(q[name])
        if vals.min() < lo - 1e-9 or vals.max() > hi + 1e-9:
            _refuse(source, "radius", f"the circle takes {name} from {vals.min():g} to {vals.max():g} "
                    f"{s.unit.name}, beyond its limits [{lo:g}, {hi:g}]: "
                    + ("not a circle this machine can run" if source else "a smaller --radius or another --centre"))
    return {**{k: v for k, v in base.items() if machine.symbol(k).role == "axis"}, **q}


def deviation(machine: Machine, model: ExactModel, setup: Setup, values: dict, axes: dict) -> np.ndarray:
    """Ballbar length minus R at the commanded axes, from the exact model with ``values``."""
    p = tool_point(model, {**values, **axes})
    d = np.linalg.norm(p - setup.centre, axis=1) - setup.radius
    bad = np.flatnonzero(~np.isfinite(d))
    if len(bad):
        k = bad[0]
        at = ", ".join(f"{n} = {machine.symbol(n).from_internal(float(np.broadcast_to(v, d.shape)[k])):g}"
                       for n, v in axes.items() if n in setup.axes)
        raise ChaincompError(f"the exact model is not finite on the circle at {at} (a table that rejects "
                             "positions outside its range, or an expression out of its domain)")
    return d


def angles(points: int) -> np.ndarray:
    return 2 * np.pi * np.arange(points) / points


def predict(machine: Machine, values: dict, setup: Setup, points: int, model: ExactModel | None = None) -> Trace:
    """Both directions of travel: ccw at increasing angles from 0, cw back from 360°. The model
    is quasi-static geometry, so the two coincide point for point."""
    model = model or ExactModel(machine)
    th = angles(points)
    axes = commanded(machine, model, setup, values, th)
    d = deviation(machine, model, setup, values, axes)
    worst = float(np.abs(d).max())
    if not worst < SMALL * setup.radius:   # what read_trace refuses too
        raise ChaincompError(f"the trace reaches {worst / UM:.4g} µm, not small against the radius "
                             f"({_num(setup.radius)} mm): a ballbar of that length would not read it (a larger "
                             "--radius)")
    back = np.r_[0, np.arange(points - 1, 0, -1)]     # cw: 0, 359, 358, ... degrees
    return Trace(setup, np.r_[th, th[back]], np.array([CCW] * points + [CW] * points),
                 np.r_[d, d[back]])


# ----------------------------------------------------------------------------- evaluation

def lsq_circle(angle: np.ndarray, dev: np.ndarray, radius: float) -> tuple[np.ndarray, float, np.ndarray]:
    """The least-squares circle (minimum of the sum of squared radial distances) through the
    trace's points (R + deviation at the nominal angle, about the pivot): centre (2,) and
    radius, by Gauss-Newton from the linearised fit; and each point's distance from that centre."""
    pts = (radius + dev)[:, None] * np.stack([np.cos(angle), np.sin(angle)], axis=1)
    a = np.stack([np.ones_like(angle), np.cos(angle), np.sin(angle)], axis=1)
    r0, cx, cy = lsq.solve(a, dev)

    def linearise(x):          # x: centre x, y and radius; the residual is the distance minus the radius
        v = pts - x[:2]
        dist = np.linalg.norm(v, axis=1)
        return -(dist - x[2]), np.column_stack([-v / dist[:, None], -np.ones_like(dist)])

    x, _, _ = lsq.gauss_newton(linearise, np.array([cx, cy, radius + r0]), 20,
                               lambda step, x, j: np.abs(step).max() < 1e-15 * radius)
    c = x[:2]
    return c, float(x[2]), np.linalg.norm(pts - c, axis=1)


def evaluate(trace: Trace) -> dict:
    """ISO 230-4 figures (mm): per direction G (radial range about the least-squares circle's
    centre), F_max and F_min (largest and smallest deviation from R about the pivot), the
    circle's centre offset and radius; bidirectional G(b) about the circle of both paths, and the
    circular hysteresis H."""
    r = trace.setup.radius
    out = {}
    for d in (CCW, CW):
        th, dev = trace.of(d)
        if len(th) == 0:
            continue
        c, rho, dist = lsq_circle(th, dev, r)
        out[d] = {"G": float(np.ptp(dist)), "F_max": float(dev.max()), "F_min": float(dev.min()),
                  "centre": c.tolist(), "radius": rho, "points": int(len(th))}
    if len(out) == 2:
        c, rho, dist = lsq_circle(trace.angle, trace.deviation, r)
        out["bidirectional"] = {"G": float(np.ptp(dist)), "H": hysteresis(trace), "centre": c.tolist(),
                                "radius": rho, "points": int(len(trace.angle))}
    return out


def largest_gap(angle: np.ndarray) -> float:
    """The largest arc of the circle (rad) with no point of ``angle`` on it."""
    a = np.sort(np.mod(angle, 2 * np.pi))
    return float(np.diff(np.r_[a, a[0] + 2 * np.pi]).max())


def hysteresis(trace: Trace) -> float:
    """Circular hysteresis H (ISO 230-4): the largest radial difference between the two paths,
    the cw one interpolated (periodically, linearly in angle) at the ccw one's angles."""
    (a, da), (b, db) = trace.of(CCW), trace.of(CW)
    b = np.mod(b, 2 * np.pi)
    order = np.argsort(b)
    at = np.interp(np.mod(a, 2 * np.pi), b[order], db[order], period=2 * np.pi)
    return float(np.abs(da - at).max())


# ----------------------------------------------------------------------------- the trace CSV

def _num(v: float) -> str:
    """A number as short as reads back to the same float (the set-up must reproduce the circle)."""
    text = f"{v:.10g}"
    text = text if float(text) == v else repr(float(v))
    return "0" if text in ("-0", "-0.0") else text


def header_lines(machine: Machine, setup: Setup) -> list[str]:
    lu = machine.length_unit
    k = U.UNITS[lu].to_internal
    held = ", ".join(f"{n}={_num(machine.symbol(n).from_internal(v))} {machine.symbol(n).unit.name}"
                     for n, v in setup.held.items())
    out = ["# chaincomp ballbar trace (ISO 230-4 circular test)",
           f"# machine: {machine.name}",
           f"# plane: {setup.plane}",
           f"# axes: {', '.join(setup.axes)}",
           f"# radius: {_num(setup.radius / k)} {lu}",
           f"# centre: {', '.join(_num(c / k) for c in setup.centre)} {lu}"]
    if held:
        out.append(f"# held: {held}")
    if setup.feed is not None:
        out.append(f"# feed: {_num(setup.feed)} mm/min")
    return out


def write_trace(path: str, machine: Machine, trace: Trace, comments=()) -> None:
    lines = header_lines(machine, trace.setup) + [f"# {one_line(c)}" for c in comments]
    lines.append("angle [deg],direction,deviation [um]")
    lines += [f"{_num(math.degrees(a))},{d},{v / UM:.6f}" for a, d, v in
              zip(trace.angle, trace.direction, trace.deviation)]
    write_file(path, "\n".join(lines) + "\n")


_META = re.compile(r"#\s*(machine|plane|axes|radius|centre|center|held|feed)\s*:\s*(.*?)\s*$", re.IGNORECASE)
_FIELDS = ("angle", "direction", "deviation")


def _number(text: str, fail) -> float:
    try:
        return parse_number(text)
    except ValueError as exc:
        fail(str(exc))


def _length(text: str, machine: Machine, fail) -> float:
    """'100 mm' or '100' (the machine's length unit) -> mm."""
    parts = text.split()
    if len(parts) not in (1, 2):
        fail(f"expected a length such as '100 mm', got {text!r}")
    v = _number(parts[0], fail)
    try:
        u = U.unit(parts[1]) if len(parts) == 2 else U.UNITS[machine.length_unit]
    except KeyError as exc:
        fail(exc.args[0])
    if u.kind != "length":
        fail(f"{u.name} is not a length unit")
    if not abs(v * u.to_internal) <= MAX_LITERAL:
        fail(f"{text!r} is larger than {MAX_LITERAL:g} mm in magnitude")
    return v * u.to_internal


def read_trace(path: str, machine: Machine) -> Trace:
    """A trace CSV (see the module's docstring); every fault names the file, line and field."""
    table = csvtable.read(path, max_rows=MAX_ROWS, example="angle [deg],direction,deviation [um]")
    meta: dict[str, tuple[str, int]] = {}
    for lineno, raw in table.comments:
        m = _META.fullmatch(raw.strip())
        if m and lineno < table.line:
            key = m.group(1).lower().replace("center", "centre")
            if key in meta:
                raise ChaincompError(f"{key} given twice (first on line {meta[key][1]})", path, lineno, key)
            meta[key] = (m.group(2), lineno)
    header = (table.line, table.header)

    def need(key: str) -> tuple[str, int]:
        if key not in meta:
            raise ChaincompError(f"no '# {key}: ...' line above the header (the test's {key})", path, header[0], key)
        return meta[key]

    def failer(line: int, key: str):
        def fail(msg):
            raise ChaincompError(msg, path, line, key)
        return fail

    if "machine" in meta and meta["machine"][0] != machine.name:
        raise ChaincompError(f"the trace is of machine {meta['machine'][0]!r}, not {machine.name!r}", path,
                             meta["machine"][1], "machine")
    plane_text, line = need("plane")
    plane = plane_text.upper()
    if plane not in PLANES:
        raise ChaincompError(f"expected one of {', '.join(PLANES)}, got {plane_text!r}", path, line, "plane")
    radius_text, line = need("radius")
    radius = _length(radius_text, machine, failer(line, "radius"))
    if not radius > 0:
        raise ChaincompError(f"the radius must be positive, got {radius_text!r}", path, line, "radius")
    centre_text, line = need("centre")
    fail = failer(line, "centre")
    parts = centre_text.split()
    unit = parts.pop() if parts and not re.match(r"[-+.\d]", parts[-1]) else None
    coords = [c.strip() for c in " ".join(parts).split(",")]
    if len(coords) != 3:
        fail(f"expected x, y, z and a unit such as '0, 0, 400 mm', got {centre_text!r}")
    centre = np.array([_length(c + (f" {unit}" if unit else ""), machine, fail) for c in coords])
    held: dict[str, float] = {}
    if "held" in meta:
        held_text, line = meta["held"]
        fail = failer(line, "held")
        for item in (t.strip() for t in held_text.split(",") if t.strip()):
            name, sep, value = item.partition("=")
            name = name.strip()
            try:
                sym = machine.symbol(name)
            except KeyError:
                sym = None
            if not sep or sym is None or sym.role != "axis":
                fail(f"expected AXIS=VALUE items of the axes of {machine.name} "
                     f"({', '.join(s.name for s in machine.axes)}), got {item!r}")
            if name in held:
                fail(f"{name} given twice")
            try:
                held[name] = parse_value(sym, value.strip())
            except ValueError as exc:
                fail(f"{name}: {exc}")
    axes_given = None
    if "axes" in meta:
        axes_given = [a.strip() for a in meta["axes"][0].split(",")]
        if len(axes_given) != 2:
            raise ChaincompError(f"expected the two plane axes, e.g. 'X, Y', got {meta['axes'][0]!r}", path,
                                 meta["axes"][1], "axes")
    feed = None
    if "feed" in meta:
        feed_text, line = meta["feed"]
        feed = _number(feed_text.removesuffix("mm/min").strip(), failer(line, "feed"))
        if not feed > 0:
            raise ChaincompError(f"the feed must be above 0 mm/min, got {feed_text!r}", path, line, "feed")

    # the columns
    hline, cells = header
    col, col_unit = {}, {}
    for k, cell in enumerate(cells):
        name, unit = csvtable.split_unit(cell)
        if name.lower() in _FIELDS:
            if name.lower() in col:
                raise ChaincompError(f"two columns named {name.lower()!r}", path, hline, name.lower())
            col[name.lower()] = k
            col_unit[name.lower()] = unit
    for f in _FIELDS:
        if f not in col:
            raise ChaincompError(f"no column {f!r} (header: {', '.join(cells)}; expected "
                                 "'angle [deg],direction,deviation [um]')", path, hline, f)
    units = {}
    for f, kind in (("angle", "angle"), ("deviation", "length")):
        written = col_unit[f]
        if written is None:
            raise ChaincompError(f"no unit for column {f!r}: write it in the header ('{f} "
                                 f"[{'deg' if kind == 'angle' else 'um'}]')", path, hline, f)
        try:
            u = U.unit(written)
        except KeyError as exc:
            raise ChaincompError(exc.args[0], path, hline, f) from None
        if u.kind != kind:
            raise ChaincompError(f"{u.name} is not {'an angle' if kind == 'angle' else 'a length'} unit", path,
                                 hline, f)
        units[f] = u
    ang, dirs, devs, lines = [], [], [], []
    seen: dict[tuple[str, float], int] = {}
    for r in table.rows:
        lineno, row = r.line, r.cells

        def cell(f: str) -> str:
            if not row[col[f]]:
                raise ChaincompError("missing value", path, lineno, f)
            return row[col[f]]
        a = table.number(r, col["angle"], "angle") * units["angle"].to_internal
        if not abs(a) <= 100 * math.pi:
            raise ChaincompError(f"an angle of {cell('angle').strip()} is beyond ±50 turns", path, lineno, "angle")
        d = _DIRECTIONS.get(cell("direction").strip().lower())
        if d is None:
            raise ChaincompError(f"expected ccw or cw, got {cell('direction').strip()!r}", path, lineno,
                                 "direction")
        v = table.number(r, col["deviation"], "deviation") * units["deviation"].to_internal
        if not abs(v) < SMALL * radius:
            raise ChaincompError(f"a deviation of {cell('deviation').strip()} {units['deviation'].name} is not "
                                 f"small against the radius ({_num(radius)} mm): not a ballbar reading", path,
                                 lineno, "deviation")
        first = seen.setdefault((d, round(a, 9)), lineno)
        if first != lineno:
            raise ChaincompError(f"the {d} point at {cell('angle').strip()} {units['angle'].name} is given twice "
                                 f"(first on line {first})", path, lineno, "angle")
        ang.append(a)
        dirs.append(d)
        devs.append(v)
        lines.append(lineno)
    if not lines:
        raise ChaincompError("no readings below the header", path, hline)
    dirs_arr = np.array(dirs)
    for d in (CCW, CW):
        k = int((dirs_arr == d).sum())
        if 0 < k < MIN_POINTS:
            raise ChaincompError(f"only {k} {d} point{'s' if k > 1 else ''}: a direction needs at least "
                                 f"{MIN_POINTS} around the circle", path, lines[dirs.index(d)], "direction")
    # the plane axes, when the header names them, are checked against the machine by the caller
    setup = Setup(plane, tuple(axes_given) if axes_given else None, radius, centre, held, feed)
    return Trace(setup, np.array(ang), dirs_arr, np.array(devs), path, lines,
                 {key: line for key, (_, line) in meta.items()})


# ----------------------------------------------------------------------------- the fit

@dataclass
class Term:
    """One unknown of the fit: the centre offset along a plane direction, an error (constant),
    or the coefficient of an error's power of a plane axis (a polynomial term)."""
    name: str                  # e.g. 'centre x', 'EC0Y', 'EXX·X'
    error: str | None = None
    axis: str | None = None
    power: int = 0
    column: np.ndarray = field(default=None, repr=False)   # radial gain at every trace point
    kind: str = ""             # of a slide's error: positioning or straightness

    def unit(self, machine: Machine) -> tuple[str, float]:
        """Display unit and its size in internal units (mm/mm^k ...)."""
        if self.error is None:
            return "um", UM
        s = machine.symbol(self.error)
        if self.power == 0:
            return s.unit.name, s.unit.to_internal
        return ("um/m" if self.power == 1 else "um/m^2"), UM / 1000.0 ** self.power


@dataclass
class Fit:
    terms: list[Term]                       # fitted, in order
    estimates: np.ndarray                   # internal units
    uncertainties: np.ndarray
    combinations: dict[str, list[tuple[Term, float]]]  # fitted term -> [(term it stands for too, factor)]
    unseen: list[str]                       # errors that move no trace point
    assumed_zero: list[str]
    not_fitted: dict[str, str]              # error -> why (a table in P0, ...)
    rms: float                              # mm
    rms_before: float                       # mm, the trace against the start values
    points: int
    dof: int
    residual: np.ndarray                    # mm, per trace point
    covariance: np.ndarray = field(default=None, repr=False)

    def scale_mismatch(self, axes: tuple[str, str]) -> tuple[float, float] | None:
        """The difference of the two plane axes' scale errors (the slopes of their positioning
        errors, mm/mm) and its standard uncertainty, where both are fitted."""
        k = [next((i for i, t in enumerate(self.terms) if t.kind == "positioning" and t.power == 1 and t.axis == a),
                  None) for a in axes]
        if None in k:
            return None
        a, b = k
        c = self.covariance
        return float(self.estimates[a] - self.estimates[b]), math.sqrt(max(c[a, a] + c[b, b] - 2 * c[a, b], 0.0))


def _slide_terms(machine: Machine, axes: tuple[str, str]) -> list[tuple[str, str, str]]:
    """(error, axis, kind): the positioning and straightness errors of the slides of the plane axes."""
    out = []
    for slide in find_slides(machine):
        if slide.axis in axes:
            out += [(c.error, slide.axis, c.kind) for c in slide.components
                    if c.kind in ("positioning", "straightness")]
    return out


def fit(machine: Machine, trace: Trace, values: dict, axes: dict, start: np.ndarray, assume_zero=(),
        degree: int = 1, model: JetModel | None = None, prefer=()) -> Fit:
    """Linear least squares of the trace's deviation from ``start`` (the deviation the start
    values predict) on the radial gains: the centre offset, every error of the machine that
    moves the trace (constants), and for degree >= 1 the powers 1..degree of the plane axes in
    their slides' positioning and straightness errors. Terms that move the trace only as others
    do are left out and their combination reported on the term that stands for it; the terms of
    the errors in ``prefer`` are taken first (after the centre), in that order."""
    model = model or JetModel(machine, 1)
    setup = trace.setup
    i, j, _ = PLANES[setup.plane]
    n = np.zeros((len(trace.angle), 3))
    n[:, i], n[:, j] = np.cos(trace.angle), np.sin(trace.angle)
    gains = model.gains({**values, **axes})
    m = len(trace.angle)

    def radial(k: int) -> np.ndarray:
        return sum(n[:, c] * np.broadcast_to(np.asarray(gains[f"d{'xyz'[c]}"][k], float), (m,)) for c in range(3))

    free = [s.name for s in machine.errors if s.name not in assume_zero]
    not_fitted = {e: "given as a table or polynomial in the start values" for e in free
                  if isinstance(values.get(e), Varying)}
    index = {s.name: k for k, s in enumerate(machine.errors)}
    centre = [Term(f"centre {'xyz'[c]}", column=n[:, c].copy()) for c in (i, j)]
    location, slide_consts, powers = [], [], []
    in_slides = {c.error for s in find_slides(machine) for c in s.components}
    for e in free:
        if e in not_fitted:
            continue
        t = Term(e, e, column=radial(index[e]))
        (slide_consts if e in in_slides else location).append(t)
    for e, a, kind in _slide_terms(machine, setup.axes):
        if e in free and e not in not_fitted:
            for p in range(1, degree + 1):
                powers.append(Term(f"{e}·{a}" + (f"^{p}" if p > 1 else ""), e, a, p,
                                   radial(index[e]) * np.asarray(axes[a], float) ** p, kind))
    rest = location + slide_consts + powers
    first = [t for e in prefer for t in rest if t.error == e]
    candidates = centre + first + [t for t in rest if t not in first]
    norms = np.array([np.linalg.norm(t.column) for t in candidates])
    moves = lsq.seen(norms)
    unseen = [t.name for t, v in zip(candidates, moves) if t.error and t.power == 0 and not v]
    # the first term, in the order above, that adds a direction of its own is fitted; the others
    # are combinations of fitted ones (centre first: it is always there)
    shown = np.flatnonzero(moves)
    units = np.column_stack([candidates[k].column / norms[k] for k in shown])
    picked = [int(shown[i]) for i in lsq.spanning(units, first=range(len(shown)))]
    terms = [candidates[k] for k in picked]
    jac = np.column_stack([t.column for t in terms])
    if m <= len(terms):
        raise ChaincompError(f"{m} trace points for {len(terms)} unknowns: nothing left to estimate the "
                             "uncertainty from; record more points", trace.file)
    y = trace.deviation - start
    f = lsq.linear_fit(jac, y)
    combos: dict[str, list[tuple[Term, float]]] = {t.name: [] for t in terms}
    for k in shown:
        if k in picked:
            continue
        t = candidates[k]
        for c, tf in zip(lsq.solve(jac, t.column), terms):
            if abs(c) * np.linalg.norm(tf.column) > 1e-6 * norms[k]:
                combos[tf.name].append((t, float(c)))
    return Fit(terms, f.estimates, np.sqrt(np.diag(f.covariance)), combos, unseen, list(assume_zero), not_fitted,
               math.sqrt(float(f.residual @ f.residual) / m), math.sqrt(float(y @ y) / m), m, f.dof, f.residual,
               f.covariance)
