"""Measurement protocol for machines whose axes are all linear (three-axis machining centres,
two-slide stages): laser runs per axis and channel, the body diagonals of ISO 230-6, tracker
points in the volume, and which errors each identifies, from the model's first-order gains.

What is identified. An error of a slide (an ISO 230-1 name such as EXX or EBY, or an error in
the block after the slide's translation) is a function of that slide's position; it is split
into its *offset* (the value at the axis' reference position), its *slope* along the travel and
its *shape* (what is left, a quadratic standing for any curvature). Every other error
(squareness, tool offsets) is a constant. Each reading is linear in these parameters to first
order: the gain of the error in that channel at that pose, times 1, t or t², with t the axis
position from its reference over half its travel.

What each measurement reads. A laser run moves one axis over its travel, the others held:
positioning reads the tool's displacement along the travel, straightness across it, angular
channels the tool's rotation (roll about the travel) — all relative to the tool, as ISO 230-1
defines the error motions. The laser reads relative to its start (an unknown zero per run),
and a straightness evaluation removes the best-fit line (an unknown zero and slope: the
optics' alignment). A diagonal (ISO 230-6) moves all axes at once between opposite corners of
the travel and reads the displacement along it, relative to its start. A tracker reads the
tool point at the 3^k grid of the travel (limits and mid-range) in the chain's frame, as
``identify`` takes its coordinates. Ranks are those of the stacked readings with these unknown
zeros and slopes as extra columns, every column scaled to unit norm.
"""

from __future__ import annotations

import dataclasses
import itertools
from dataclasses import dataclass, field

import numpy as np
import sympy as sp

from ..errors import ChaincompError
from ..escape import one_line
from ..model.machine import Machine
from ..symbolic.derive import COMPONENTS
from ..symbolic.numeric import ExactModel
from .calibration import varying_axis
from .identify import pose_points
from .lsq import numeric_rank
from .pose_design import point_jacobian
from .protocol import check_errors, check_measure

RUN_POINTS = 11          # targets per laser run and per diagonal
PARTS = ("offset", "slope", "shape")
STAGES = ("laser runs", "diagonals", "tracker")


def linear_only(machine: Machine) -> bool:
    return bool(machine.axes) and all(s.unit.kind == "length" for s in machine.axes)


def auto_levels(s) -> list[float]:
    """An axis' auto set-up values (internal units): both limits and the middle, or for a rotary
    axis that can make a turn the four quarter turns (each moved by a turn into the limits)."""
    lo, hi = s.to_internal(s.limits[0]), s.to_internal(s.limits[1])
    if s.unit.kind == "angle" and hi - lo >= 2 * np.pi * (1 - 1e-12):
        return [v if v <= hi else v - 2 * np.pi for v in (0.0, 0.5 * np.pi, np.pi, 1.5 * np.pi)]
    return [lo, 0.5 * (lo + hi), hi] if hi > lo else [lo]


def slide_of(machine: Machine, error: str) -> str | None:
    """The linear axis an error varies along (laser-to-params' rule), or None: a constant."""
    axis = varying_axis(machine, error)
    return axis if axis is not None and machine.symbol(axis).unit.kind == "length" else None


@dataclass
class Param:
    error: str
    part: str                # "offset" | "slope" | "shape" | "constant"
    axis: str | None

    @property
    def label(self) -> str:
        return self.error if self.part == "constant" else f"{self.error} {self.part}"


@dataclass
class Reading:
    """One measurement: its poses, what it reads, and the unknowns of its zero."""
    kind: str                      # "laser" | "diagonal" | "tracker"
    name: str
    axes: dict[str, np.ndarray]    # internal units, one value per row
    channel: str                   # "point" | "rotation"
    vector: np.ndarray | None      # unit vector read (None: tracker, every measured coordinate)
    nuisance: int                  # polynomial degree of the unknown zero: -1 none, 0 offset, 1 line
    along: str | None = None       # the axis the reading runs along (laser runs)
    instrument: str = ""
    gains: np.ndarray | None = None                              # (rows, errors)
    measures: dict[str, float] = field(default_factory=dict)   # laser: the run's axis' errors, gain
    slope_from: list[str] = field(default_factory=list)         # other errors it sees as a slope
    rows: np.ndarray | None = None # (rows, params) before scaling


@dataclass
class LinearProtocol:
    machine: Machine
    fixed: dict[str, float]                  # axes held during the laser runs (declared unit)
    measured: list[str]                      # tracker coordinates
    assumed_zero: list[str]
    params: list[Param]
    readings: list[Reading]
    datum: dict[str, str] = field(default_factory=dict)   # param label -> why it is zero by definition
    stages: list[dict] = field(default_factory=list)
    found_by: dict[str, str] = field(default_factory=dict)  # param label -> stage that identified it
    unidentifiable: dict[str, str] = field(default_factory=dict)


def _t(machine: Machine, axis: str, values: np.ndarray) -> np.ndarray:
    s = machine.symbol(axis)
    lo, hi = (s.to_internal(v) for v in s.limits)
    half = 0.5 * (hi - lo) or 1.0
    return (values - s.reference_value) / half


def shifted_models(machine: Machine) -> list[tuple[Machine, ExactModel]]:
    """The machine and its exact model, then the same with the tool point moved by a unit along
    x, y and z of the tool's frame (for the rotation gains)."""
    out = [(machine, ExactModel(machine))]
    for k in range(3):
        shifted = tuple(sp.sympify(v) + (1 if i == k else 0) for i, v in enumerate(machine.tool_point))
        mk = dataclasses.replace(machine, point=shifted)
        out.append((mk, ExactModel(mk)))
    return out


def pose_gains(models: list[tuple[Machine, ExactModel]], axes: dict[str, np.ndarray], errors: list[str]):
    """(point, rotation): each (rows, 3, errors), the first-order change of the tool point and
    of the tool's small rotation vector (workpiece frame) per unit error, internal units.
    The rotation comes from the point gains at the tool point moved by a unit along x, y, z
    of the tool's frame (``shifted_models``): their differences are the rotation applied to
    those unit vectors."""
    machine, model = models[0]
    point = point_jacobian(machine, model, axes, errors)
    rows = point.shape[0]
    base = np.broadcast_to(pose_points(machine, model, axes, {}), (rows, 3))
    cols, units = [], []
    for mk, model_k in models[1:]:
        cols.append(point_jacobian(mk, model_k, axes, errors) - point)
        units.append(np.broadcast_to(pose_points(mk, model_k, axes, {}), (rows, 3)) - base)
    d = np.stack(cols, axis=2)               # (rows, 3 xyz, 3 k, errors): [w]x R0 e_k
    r0 = np.stack(units, axis=2)             # (rows, 3, 3 k): R0 e_k
    w = np.einsum("rikn,rjk->rijn", d, r0)   # [w]x = D R0^T
    rotation = np.stack([w[:, 2, 1], w[:, 0, 2], w[:, 1, 0]], axis=1)
    return point, rotation


def build_linear_protocol(machine: Machine, measure=COMPONENTS, assume_zero=(),
                          fixed: dict[str, float] | None = None) -> LinearProtocol:
    """The laser runs, diagonals and tracker points of ``machine`` and what each identifies."""
    assume_zero = check_errors(machine, assume_zero, "--assume-zero")
    measure = check_measure(measure)
    errors = [s.name for s in machine.errors if s.name not in assume_zero]
    if not errors:
        raise ChaincompError("--assume-zero: every error is assumed zero, nothing is left to identify")
    fixed = dict(fixed or {})
    for name, v in fixed.items():
        s = machine.symbol(name)
        lo, hi = s.limits
        if not lo <= v <= hi:
            raise ChaincompError(f"--set {name}: {v:g} {s.unit.name} is outside the axis' limits [{lo:g}, {hi:g}]")
    held = {s.name: s.to_internal(fixed.get(s.name, s.default_position)) for s in machine.axes}
    slide = {e: slide_of(machine, e) for e in errors}
    models = shifted_models(machine)
    readings = _laser_runs(machine, held) + _diagonals(machine, models[0][1]) + [_tracker(machine, measure)]
    for rd in readings:
        _gains(models, rd, errors, slide, measure)
    proto = LinearProtocol(machine, {k: machine.symbol(k).from_internal(v) for k, v in held.items()},
                           measure, assume_zero, [], readings)
    datum = _datum(machine, readings, errors, slide)
    for e in errors:
        for part in (PARTS if slide[e] else ("constant",)):
            p = Param(e, part, slide[e])
            if p.label in datum:
                proto.datum[p.label] = datum[p.label]
            else:
                proto.params.append(p)
    for rd in readings:
        rd.rows = _rows(proto, rd, errors)
    _identify(proto)
    return proto


def _datum(machine: Machine, readings: list[Reading], errors: list[str], slide: dict) -> dict[str, str]:
    """ISO 230-1's datum: a slide's error motions are zero at its reference position (the
    machine's zero and the tool setting carry the constants), and a straightness is reported
    without its best-fit line (the squareness errors carry the slopes, X the reference
    direction). Without it the constants and slopes trade with each other and with the
    squareness (a constant pitch of X is a squareness of Z to X) and nothing fixes them."""
    positioning = {e for rd in readings if rd.kind == "laser" and rd.name.endswith("positioning")
                   for e in rd.measures}
    out = {}
    for e in errors:
        axis = slide[e]
        if axis is None:
            continue
        ref = machine.symbol(axis)
        out[f"{e} offset"] = f"zero at {axis} = {ref.default_position:g} {ref.unit.name} by definition (ISO 230-1 datum)"
        if machine.symbol(e).unit.kind == "length" and e not in positioning:
            out[f"{e} slope"] = ("a straightness is reported without its best-fit line: the slope is the "
                                 "squareness's (ISO 230-1)")
    return out


def _travel(machine: Machine, axis: str, held: dict) -> np.ndarray:
    """Unit direction the tool moves relative to the workpiece as ``axis`` moves (nominal)."""
    s = machine.symbol(axis)
    a, b = dict(held), dict(held)
    a[axis], b[axis] = s.to_internal(s.limits[0]), s.to_internal(s.limits[1])
    model = ExactModel(machine)
    u = pose_points(machine, model, {k: np.array([b[k]]) for k in b}, {})[0] - \
        pose_points(machine, model, {k: np.array([a[k]]) for k in a}, {})[0]
    n = np.linalg.norm(u)
    if not n > 0:
        raise ChaincompError(f"axis {axis} does not move the tool point: no laser run along it",
                             machine.file, s.line, "symbols")
    return u / n


def _laser_runs(machine: Machine, held: dict) -> list[Reading]:
    out = []
    for s in machine.axes:
        lo, hi = s.limits
        if not hi > lo:
            continue
        axes = {k: np.full(RUN_POINTS, v) for k, v in held.items()}
        axes[s.name] = s.to_internal(np.linspace(lo, hi, RUN_POINTS))
        u = _travel(machine, s.name, held)
        along = int(np.argmax(np.abs(u)))
        eye = np.eye(3)
        channels = [("positioning", "point", u, 0, "linear interferometer")]
        channels += [(f"straightness in {COMPONENTS[c]}", "point", eye[c], 1, "straightness optics")
                     for c in range(3) if c != along]
        channels += [(f"roll (about {COMPONENTS[c]})" if c == along else f"angular about {COMPONENTS[c]}",
                      "rotation", eye[c], 0,
                      "electronic level, or straightness at two offsets" if c == along else "angular interferometer")
                     for c in range(3)]
        for name, kind, vec, nuisance, instrument in channels:
            out.append(Reading("laser", f"{s.name} {name}", axes, kind, vec, nuisance, s.name, instrument))
    return out


def _diagonals(machine: Machine, model: ExactModel) -> list[Reading]:
    """ISO 230-6: from one corner of the travel to the opposite one, every axis at once."""
    axes = [s for s in machine.axes if s.limits[1] > s.limits[0]]
    if len(axes) < 2:
        return []
    out = []
    for signs in itertools.product((1, -1), repeat=len(axes) - 1):
        signs = (1,) + signs
        t = np.linspace(-1.0, 1.0, RUN_POINTS)
        values = {}
        for s, sg in zip(axes, signs):
            lo, hi = (s.to_internal(v) for v in s.limits)
            values[s.name] = 0.5 * (lo + hi) + sg * t * 0.5 * (hi - lo)
        for s in machine.axes:
            values.setdefault(s.name, np.full(RUN_POINTS, s.reference_value))
        p = pose_points(machine, model, values, {})
        u = p[-1] - p[0]
        ends = " to ".join("(" + ", ".join(f"{machine.symbol(k).from_internal(values[k][i]):g}" for k in values) + ")"
                           for i in (0, -1))
        out.append(Reading("diagonal", f"diagonal {ends}", values, "point", u / np.linalg.norm(u), 0,
                           instrument="linear interferometer along the diagonal (ISO 230-6)"))
    return out


def _tracker(machine: Machine, measure: list[str]) -> Reading:
    levels = {s.name: auto_levels(s) for s in machine.axes}
    rows = list(itertools.product(*levels.values()))
    axes = {name: np.array([r[i] for r in rows]) for i, name in enumerate(levels)}
    return Reading("tracker", f"tracker at {len(rows)} points ({', '.join(measure)})", axes, "point", None, -1,
                   instrument="laser tracker (or a CMM probe) in the chain's frame")


def _gains(models, rd: Reading, errors: list[str], slide: dict, measure: list[str]) -> None:
    """The reading's gains in the errors per row, and (laser runs) what the run measures."""
    point, rotation = pose_gains(models, rd.axes, errors)
    if rd.vector is None:
        idx = [COMPONENTS.index(c) for c in measure]
        rd.gains = point[:, idx, :].reshape(-1, len(errors))     # set-up major, coordinate minor
    else:
        rd.gains = np.einsum("c,rcn->rn", rd.vector, point if rd.channel == "point" else rotation)
    if rd.kind != "laser":
        return
    g = rd.gains
    scale = np.abs(g).max(initial=0.0) or 1.0
    for j, e in enumerate(errors):
        if np.abs(g[:, j]).max() <= 1e-9 * scale:
            continue
        if slide[e] == rd.along:
            rd.measures[e] = float(g[RUN_POINTS // 2, j])
        elif np.ptp(g[:, j]) > 1e-9 * scale:
            rd.slope_from.append(e)


def _rows(proto: LinearProtocol, rd: Reading, errors: list[str]) -> np.ndarray:
    power = {"constant": 0, "offset": 0, "slope": 1, "shape": 2}
    per = len(rd.gains) // len(next(iter(rd.axes.values())))     # rows per set-up (tracker: coordinates)
    cols = []
    for p in proto.params:
        g = rd.gains[:, errors.index(p.error)]
        cols.append(g * _t(proto.machine, p.axis, np.repeat(rd.axes[p.axis], per)) ** power[p.part] if p.axis else g)
    return np.stack(cols, axis=1) if cols else np.zeros((len(rd.gains), 0))


def _nuisance(machine: Machine, rd: Reading) -> np.ndarray:
    n = len(rd.rows)
    if rd.nuisance < 0:
        return np.zeros((n, 0))
    t = _t(machine, rd.along, rd.axes[rd.along]) if rd.nuisance > 0 else np.zeros(n)
    return np.stack([t ** k for k in range(rd.nuisance + 1)], axis=1)


def design_matrix(proto: LinearProtocol, readings: list[Reading]) -> np.ndarray:
    """Rows of ``readings`` in the parameters, then each reading's unknown zero (and slope)."""
    blocks = [_nuisance(proto.machine, rd) for rd in readings]
    width = sum(b.shape[1] for b in blocks)
    out, at = [], 0
    for rd, b in zip(readings, blocks):
        extra = np.zeros((len(rd.rows), width))
        extra[:, at:at + b.shape[1]] = b
        at += b.shape[1]
        out.append(np.hstack([rd.rows, extra]))
    return np.vstack(out)


def identified(a: np.ndarray, n_params: int) -> tuple[int, np.ndarray, np.ndarray]:
    """(rank, which of the first n_params columns the rows determine, null-space projector)."""
    norm = np.linalg.norm(a, axis=0)
    visible = norm > 1e-12 * max(norm.max(initial=0.0), 1e-300)
    scaled = a[:, visible] / norm[visible]
    _, s, vt = np.linalg.svd(scaled, full_matrices=True)
    rank = numeric_rank(s)
    null = vt[rank:]
    proj = np.zeros((a.shape[1], a.shape[1]))
    proj[np.ix_(visible, visible)] = null.T @ null
    ok = visible & (np.diag(proj) <= 1e-10)
    return rank, ok[:n_params], proj


def _identify(proto: LinearProtocol) -> None:
    """Cumulatively, stage by stage, which parameters the readings determine; and each stage alone."""
    n = len(proto.params)
    labels = [p.label for p in proto.params]
    so_far: list[Reading] = []
    proj = None
    for stage, kind in zip(STAGES, ("laser", "diagonal", "tracker")):
        alone = [rd for rd in proto.readings if rd.kind == kind]
        if not alone:
            continue
        so_far += alone
        rank, ok, proj = identified(design_matrix(proto, so_far), n)
        rank_alone, ok_alone, _ = identified(design_matrix(proto, alone), n)
        new = [labels[i] for i in np.flatnonzero(ok) if labels[i] not in proto.found_by]
        for lb in new:
            proto.found_by[lb] = stage
        proto.stages.append({"name": stage, "rank": rank, "parameters": n, "identified": new,
                             "total": len(proto.found_by), "rank_alone": rank_alone,
                             "alone": [labels[i] for i in np.flatnonzero(ok_alone)]})
    a = design_matrix(proto, proto.readings)
    seen = np.linalg.norm(a[:, :n], axis=0) > 0
    for i, p in enumerate(proto.params):
        if p.label in proto.found_by:
            continue
        if not seen[i]:
            proto.unidentifiable[p.label] = _invisible(proto, p)
            continue
        partners = [labels[k] for k in range(n) if k != i and abs(proj[i, k]) > 1e-6 * proj[i, i]]
        nuis = any(abs(proj[i, k]) > 1e-6 * proj[i, i] for k in range(n, len(proj)))
        why = []
        if partners:
            why.append(f"seen only together with {', '.join(partners)}")
        if nuis:
            why.append("a laser reading's unknown zero or alignment takes it up")
        proto.unidentifiable[p.label] = "; ".join(why) or "seen only in combinations these readings cannot split"


def _invisible(proto: LinearProtocol, p: Param) -> str:
    s = proto.machine.symbol(p.error)
    if s.unobservable:
        return "moves no reading (the machine file marks it unobservable: it moves neither the tool point nor its axis)"
    if p.part == "constant":
        return "moves no reading of these measurements (to first order)"
    return f"its {p.part} moves no reading of these measurements (to first order)"


# ----------------------------------------------------------------------------- reports

def _combination(rd: Reading) -> str:
    terms = []
    for e, g in rd.measures.items():
        c = f"{abs(g):.6g}*" if abs(abs(g) - 1) > 1e-9 else ""
        terms.append(("- " if g < 0 else "+ ") + c + e)
    text = " ".join(terms)
    return text[2:] if text.startswith("+ ") else "-" + text[2:]


def _grouped(labels: list[str]) -> str:
    """'EXX shape', 'EYX shape', 'EXX slope', 'EC0Y' -> 'shape of EXX, EYX; slope of EXX; EC0Y'."""
    parts: dict[str, list[str]] = {}
    for lb in labels:
        error, _, part = lb.partition(" ")
        parts.setdefault(part, []).append(error)
    return "; ".join((f"{part} of " if part else "") + ", ".join(errs) for part, errs in parts.items())


def to_json(proto: LinearProtocol) -> dict:
    m = proto.machine
    def declared(axes, i):
        return {k: m.symbol(k).from_internal(float(v[i])) for k, v in axes.items()}
    laser, diagonals = [], []
    for rd in proto.readings:
        common = {"name": rd.name, "instrument": rd.instrument, "channel": rd.channel,
                  "vector": None if rd.vector is None else rd.vector.tolist(),
                  "unknown_zero": {-1: "none", 0: "offset", 1: "offset and slope"}[rd.nuisance],
                  "setups": [declared(rd.axes, i) for i in range(len(next(iter(rd.axes.values()))))]}
        if rd.kind == "laser":
            laser.append({**common, "axis": rd.along, "measures": rd.measures,
                          "combination": _combination(rd) if rd.measures else None,
                          "slope_from": rd.slope_from})
        elif rd.kind == "diagonal":
            diagonals.append(common)
        else:
            tracker = {**common, "measured": proto.measured}
    return {
        "machine": m.name, "file": m.file, "kind": "linear axes", "order": 1,
        "held": proto.fixed, "assumed_zero": proto.assumed_zero,
        "units": {"internal": "mm and rad: gains and combinations are in internal units",
                  "setups": {s.name: s.unit.name for s in m.axes}},
        "parameters": [{"label": p.label, "error": p.error, "part": p.part, "axis": p.axis,
                        "identified_by": proto.found_by.get(p.label)} for p in proto.params],
        "laser_runs": laser, "diagonals": diagonals, "tracker": tracker,
        "datum": proto.datum, "stages": proto.stages, "unidentifiable": proto.unidentifiable,
    }


def to_text(proto: LinearProtocol) -> str:
    m = proto.machine
    lines = [f"PROTOCOL for {m.name} ({one_line(m.file)}): {len(m.axes)} linear axes, first order",
             "Errors of a slide are functions of its position (offset, slope along the travel, shape); "
             "the others constants.",
             "Laser runs hold the other axes at " + ", ".join(f"{k} = {v:g} {m.symbol(k).unit.name}"
                                                             for k, v in proto.fixed.items()),
             f"Parameters assumed zero: {' '.join(proto.assumed_zero) or '(none)'}",
             "", "1. Laser runs (each axis over its travel, the tool relative to the workpiece; "
             f"{RUN_POINTS} targets):"]
    for rd in (r for r in proto.readings if r.kind == "laser"):
        what = (f"measures {_combination(rd)}" if rd.measures else "measures none of the axis' errors")
        if rd.slope_from:
            what += f"; sees {', '.join(rd.slope_from)} as a slope"
        lines.append(f"   {rd.name:<28} {what}   [{rd.instrument}]")
    lines += ["   Positioning and angular runs read relative to their start, straightness runs up to a line:",
              "   the offsets and the straightness slopes are left to the tests below."]
    diag = [r for r in proto.readings if r.kind == "diagonal"]
    if diag:
        lines += ["", f"2. Diagonals (ISO 230-6, displacement along each, all axes at once; {RUN_POINTS} targets):"]
        lines += [f"   {rd.name}" for rd in diag]
    tracker = next(r for r in proto.readings if r.kind == "tracker")
    lines += ["", f"3. Tracker points: {tracker.name}, every axis at its limits and mid-range",
              "   (simulate-measurements --setups auto writes them)"]
    lines += ["", "Zero by definition (ISO 230-1 datum): the offsets of the slides' errors at the reference position,",
              "and the slopes of the straightness errors (the squareness errors carry them)"]
    lines += ["", "Identified, cumulatively (rank of the stacked readings, their unknown zeros included):"]
    for st in proto.stages:
        lines.append(f"   + {st['name']:<11} rank {st['rank']}, {st['total']} of {st['parameters']} parameters"
                     + (f": {_grouped(st['identified'])}" if st["identified"] else ": nothing new"))
        if st["name"] != STAGES[0]:
            lines.append(f"     ({st['name']} alone: rank {st['rank_alone']}"
                         + (f", identify {_grouped(st['alone'])})" if st["alone"] else ", identify nothing)"))
    quiet = [s.name for s in m.errors if s.unobservable and s.name not in proto.assumed_zero]
    if quiet:
        lines += ["", f"Marked unobservable in the machine file (they move neither the tool point nor its axis, "
                      f"so need no compensation): {', '.join(quiet)}"]
    if proto.unidentifiable:
        lines += ["", "Not identifiable:"]
        lines += [f"   {lb}: {why}" for lb, why in proto.unidentifiable.items()]
    return "\n".join(lines)
