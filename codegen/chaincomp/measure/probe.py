"""Sphere probing of the rotary axes (the KinematicsOpt / CYCLE996 kind of calibration): plan
the rotary positions and the probing program, read the probe logs, fit each position's sphere
centre, and identify the rotary axes' location errors with the sphere's position as nuisance
parameters.

The measurement: a calibration sphere (radius R) sits on the table at an unknown place S of the
workpiece frame; at each rotary position the probe (a stylus ball of radius r, the machine file's
tool point at its centre) touches it a few times with G38.2 moves of the linear axes. The
touched linear-axis positions lie on a sphere of radius R + r around the linear-axis position c
at which the tool point would sit at S (the linear axes move the tool rigidly over the sphere's
few millimetres), so each position gives c, and the model says tool_point(c, rotary) = S.

The identification is ``identify`` itself, on the machine with three more errors: the sphere's
offset from its nominal place (``NUISANCE``), a translation appended to the workpiece chain, and
every set-up's "measured" tool point the nominal sphere centre. So its Gauss-Newton on the exact
model, rank analysis and uncertainties are the fit's; its minimal set, with the sphere offsets
taken first, fixes the gauge freedoms: every error outside it is one a sphere cannot see, held
at zero and explained from the combination that carries it (``gauge_explanations``).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace

import numpy as np

from ..errors import ChaincompError, NoAnswer
from ..escape import csv_text, gcode_comment, one_line
from ..model import csvtable
from ..model.machine import Machine, Symbol, Translation
from ..model.numbers import parse_number
from ..model.units import UNITS
from ..model.yamlsource import read_text
from ..symbolic.numeric import ExactModel
from . import lsq
from .identify import Fit, HeldModel, identify, pose_frames, pose_points
from .table import Table

NUISANCE = ("SPHERE_DX", "SPHERE_DY", "SPHERE_DZ")   # the sphere's offset from its nominal place
LETTERS = "XYZABCUVW"            # LinuxCNC's axes, in the order of its probe log's nine numbers
# A fit (or a plan) whose column-scaled Jacobian has a condition number above this is refused:
# the near-singular fit (one gauge freedom left free) had 3.7e5; the nutating table's
# default plan has 15.
MAX_CONDITION = 1e4
# ... or one whose errors would be uncertain by more than this many µm (lengths) or arcsec (angles)
# per µm of the centres: B turned by 1° only leaves B's line uncertain by 55 µm and 170 arcsec per
# µm; the default plans of the tests stay below 3
MAX_NOISE_GAIN = 20.0
DEFAULT_RADIUS_TOLERANCE = 0.005   # mm: a probed radius further from R is a dirty sphere or stylus
DEFAULT_PER_AXIS = 4               # rotary values per axis of the default plan's grid
DEFAULT_CLEARANCE = 3.0            # mm: start beyond the surface, and overtravel below it
# Touches per position (latitude above the sphere's equator across the tool, azimuth; rad):
# three on the equator and three at asin(sqrt(2/3)) = 54.7° between them. With the sphere's
# radius known (the touches of all positions pooled), their centre's uncertainty is the same in
# every direction (the information sum n nᵀ is 2·I), so each centre coordinate weighs alike in
# the fit (a top touch and four on the equator gave z twice the variance of x and y).
TOUCHES = [(0.0, 2 * math.pi * j / 3) for j in range(3)] + \
    [(math.asin(math.sqrt(2 / 3)), 2 * math.pi * j / 3 + math.pi / 3) for j in range(3)]
MAX_POSITIONS = 400
MAX_LOG_LINES = 100_000
SAME_ANGLE = 1e-4                  # deg: two logged rotary values this close are one position


@dataclass(frozen=True)
class Sphere:
    """The calibration sphere, internal units: its nominal centre in the workpiece frame, its
    radius and the stylus ball's (effective, as calibrated) radius."""
    centre: tuple[float, float, float]
    radius: float
    stylus: float

    @property
    def contact(self) -> float:
        """Distance of the stylus centre from the sphere centre at a touch."""
        return self.radius + self.stylus


# ----------------------------------------------------------------------------- axes

@dataclass(frozen=True)
class Axes:
    linear: list[Symbol]           # three, in the order X, Y, Z of their letters
    rotary: list[Symbol]
    letters: dict[str, str]        # axis name -> LinuxCNC letter


def machine_axes(machine: Machine) -> Axes:
    """The machine's three linear axes and its rotary ones, with their LinuxCNC letters: an axis
    named by a letter of XYZABCUVW, else a rotary axis whose name starts with A, B or C."""
    linear = [a for a in machine.axes if a.unit.kind == "length"]
    rotary = [a for a in machine.axes if a.unit.kind == "angle"]
    if len(linear) != 3 or not rotary:
        raise ChaincompError(f"sphere probing needs three linear axes (to move the probe) and at least one rotary "
                             f"axis; {machine.name} has {len(linear)} linear "
                             f"({', '.join(a.name for a in linear) or 'none'}) and {len(rotary)} rotary",
                             machine.file)
    letters = {}
    for a in machine.axes:
        letter = a.name if a.name in LETTERS else a.name[0].upper() if a in rotary and a.name[0].upper() in "ABC" \
            else None
        if letter is None or letter in letters.values():
            raise ChaincompError(f"axis {a.name} of {machine.name} has no LinuxCNC letter of its own (an axis is "
                                 f"named X, Y, Z, A, B, C, U, V or W, or a rotary one starting with A, B or C): "
                                 f"rename it in the machine file", machine.file, a.line)
        letters[a.name] = letter
    linear.sort(key=lambda a: LETTERS.index(letters[a.name]))
    return Axes(linear, rotary, letters)


def with_sphere(machine: Machine) -> Machine:
    """The machine whose workpiece frame is moved by the sphere's offset (NUISANCE, µm): its tool
    point is the tool relative to the actual sphere's nominal place."""
    import sympy as sp
    taken = [n for n in NUISANCE if n in {s.name for s in machine.symbols}]
    if taken:
        raise ChaincompError(f"symbol {taken[0]} of {machine.name} is the name sphere probing gives the sphere's "
                             f"offset: rename it in the machine file", machine.file, machine.symbol(taken[0]).line)
    extra = tuple(Symbol(n, "error", UNITS["um"], f"offset of the sphere from its nominal centre along {c} of the "
                         f"workpiece frame (nuisance)") for n, c in zip(NUISANCE, "xyz"))
    shift = Translation(tuple(sp.Symbol(n, real=True) for n in NUISANCE))
    return replace(machine, symbols=machine.symbols + extra, workpiece_chain=machine.workpiece_chain + (shift,))


def inverse_kinematics(machine: Machine, model: ExactModel, axes: Axes, rotary: dict[str, np.ndarray],
                       targets: np.ndarray) -> np.ndarray:
    """(k, 3) linear-axis values (internal) putting the tool point at ``targets`` (k, 3) of the
    workpiece frame at the rotary values ``rotary`` (k each): Newton on the exact model, its
    Jacobian by differences over 1 mm (the linear axes move the tool point almost affinely)."""
    k = len(targets)
    x = np.tile([a.to_internal(a.default_position) for a in axes.linear], (k, 1))

    def point(x):
        vals = {a.name: x[:, i] for i, a in enumerate(axes.linear)}
        vals.update({n: np.broadcast_to(v, (k,)) for n, v in rotary.items()})
        return np.broadcast_to(pose_points(machine, model, vals, {}), (k, 3))

    for _ in range(30):
        p = point(x)
        miss = targets - p
        if np.max(np.abs(miss), initial=0.0) < 1e-10:
            return x
        jac = np.stack([point(x + np.eye(3)[i]) - p for i in range(3)], axis=-1)     # (k, 3, 3)
        if not np.all(np.abs(np.linalg.det(jac)) > 1e-9):
            break
        x = x + np.linalg.solve(jac, miss[..., None])[..., 0]
    raise ChaincompError(f"the linear axes of {machine.name} cannot put the probe on the sphere at some rotary "
                         f"position (the inverse kinematics does not converge)", machine.file)


# ----------------------------------------------------------------------------- plan

@dataclass
class Touch:
    position: int        # index of the rotary position (0-based)
    approach: str        # '+': the rotary axes came from below, '-': from above
    start: dict          # axis name -> value (internal) before the G38.2 move
    target: np.ndarray   # (3,) linear axes the G38.2 move aims at (internal)
    above: np.ndarray    # (3,) linear axes above the start, clear of the sphere


@dataclass
class Plan:
    machine: Machine
    sphere: Sphere
    axes: Axes
    positions: list[dict]            # rotary axis name -> value (internal)
    touches: list[Touch]
    retract: tuple[str, float]       # the linear axis along the tool and where it retracts to (internal)
    valuation: Valuation             # identify's fit of exact centres at these positions, sigma 1 µm
    backlash_step: float = 0.0       # rad; 0: one approach per position
    notes: list[str] = field(default_factory=list)


def default_positions(axes: Axes, per_axis: int, margin: float) -> list[dict]:
    """A grid of ``per_axis`` values per rotary axis: a turning axis (limits 360° apart or more)
    at equal steps of a turn from 0, any other over its limits (less ``margin``, internal)."""
    values = []
    for a in axes.rotary:
        lo, hi = (a.to_internal(v) for v in a.limits)
        if hi - lo >= 2 * math.pi - 1e-9:
            start = 0.0 if lo <= 0.0 <= hi - 2 * math.pi * (per_axis - 1) / per_axis else lo
            values.append([start + 2 * math.pi * i / per_axis for i in range(per_axis)])
        else:
            values.append(list(np.linspace(lo + margin, hi - margin, per_axis)))
    grid = np.meshgrid(*values, indexing="ij")
    return [{a.name: float(g.flat[i]) for a, g in zip(axes.rotary, grid)} for i in range(grid[0].size)]


def parse_positions(machine: Machine, axes: Axes, text: str) -> list[dict]:
    """'B=0,C=0;B=90,C=180': positions separated by ';', each every rotary axis = value in its
    declared unit."""
    out = []
    for item in (t.strip() for t in text.split(";")):
        pos = {}
        for part in (p.strip() for p in item.split(",")):
            name, eq, value = (t.strip() for t in part.partition("="))
            if not eq or name not in {a.name for a in axes.rotary}:
                raise ChaincompError(f"--positions: expected AXIS=VALUE for the rotary axes "
                                     f"{', '.join(a.name for a in axes.rotary)}, got {part!r}")
            if name in pos:
                raise ChaincompError(f"--positions: {name} given twice in {item!r}")
            try:
                v = parse_number(value)
            except ValueError as exc:
                raise ChaincompError(f"--positions: {name}: {exc}") from None
            a = machine.symbol(name)
            if not a.limits[0] <= v <= a.limits[1]:
                raise ChaincompError(f"--positions: {name} = {v:g} {a.unit.name} is outside its limits "
                                     f"[{a.limits[0]:g}, {a.limits[1]:g}]")
            pos[name] = a.to_internal(v)
        missing = [a.name for a in axes.rotary if a.name not in pos]
        if missing:
            raise ChaincompError(f"--positions: {item!r} gives no value for {', '.join(missing)}")
        out.append(pos)
    if len(out) > MAX_POSITIONS:
        raise ChaincompError(f"--positions: at most {MAX_POSITIONS} positions, got {len(out)}")
    return out


def _centre_table(machine: Machine, axes: Axes, sphere: Sphere, positions: list[dict],
                  centres: np.ndarray, lines: list[int], file: str) -> Table:
    """identify's table: per position the rotary values and the linear axes at the sphere centre,
    the "measured" tool point the sphere's nominal centre."""
    vals = {a.name: np.array([p[a.name] for p in positions]) for a in axes.rotary}
    vals.update({a.name: centres[:, i] for i, a in enumerate(axes.linear)})
    return Table(file, vals, np.tile(np.array(sphere.centre, float), (len(positions), 1)), lines,
                 [a.name for a in machine.axes] + ["x", "y", "z"])


def zero_errors(machine: Machine, model: ExactModel, axes: Axes, table: Table, errors) -> dict[str, str]:
    """error -> rotary axis, for each error that moves the tool point at every set-up of ``table``
    exactly as turning that axis does (its zero angle, whatever the machine file names it)."""
    out, h = {}, 1e-7
    for e in errors:
        if machine.symbol(e).unit.kind != "angle":
            continue
        de = np.broadcast_to(pose_points(machine, model, table.axes, {e: h}), table.coords.shape) \
            - np.broadcast_to(pose_points(machine, model, table.axes, {e: -h}), table.coords.shape)
        for a in axes.rotary:
            turn = {**table.axes, a.name: table.axes[a.name] + h}
            back = {**table.axes, a.name: table.axes[a.name] - h}
            da = np.broadcast_to(pose_points(machine, model, turn, {}), de.shape) \
                - np.broadcast_to(pose_points(machine, model, back, {}), de.shape)
            size = np.linalg.norm(da)
            if size > 0 and min(np.linalg.norm(de - da), np.linalg.norm(de + da)) < 1e-6 * size:
                out[e] = a.name
                break
    return out


@dataclass
class Valuation:
    """The set of positions judged before any measurement: identify's fit of exact sphere
    centres (the nominal model's, 1 µm per coordinate) and what it says about the gauge."""
    fit: Fit
    zeros: dict[str, str]          # zero-angle errors -> their axis
    centres: np.ndarray            # (positions, 3) nominal linear axes at the sphere centre

    @property
    def gauge(self) -> list[str]:
        """The errors a sphere cannot see: outside the minimal set, or moving no centre."""
        return [n for n in [*self.fit.redundant, *self.fit.unidentifiable] if n not in NUISANCE]


def valuation(machine: Machine, axes: Axes, sphere: Sphere, positions: list[dict], held: dict,
              assume_zero=()) -> Valuation:
    """Rank and condition of the fit at these positions, at the nominal geometry: every error
    zero, held ones too (a gauge freedom is exactly one there; a few µm of a held error would
    break it at 1e-4 and leave it near-singular instead). The sphere's offsets are taken into
    the minimal set first, then every error but the zero angles, so a zero angle is what is held
    when it and another error cannot be told apart."""
    k = len(positions)
    rot = {a.name: np.array([p[a.name] for p in positions]) for a in axes.rotary}
    centres = inverse_kinematics(machine, ExactModel(machine), axes, rot,
                                 np.tile(np.array(sphere.centre, float), (k, 1)))
    table = _centre_table(machine, axes, sphere, positions, centres, list(range(1, k + 1)), "the plan")
    aug = with_sphere(machine)
    model = ExactModel(aug)
    free = [s.name for s in machine.errors if s.name not in held and s.name not in assume_zero]
    zeros = zero_errors(aug, model, axes, table, free)
    prefer = list(NUISANCE) + [e for e in free if e not in zeros]
    fit = identify(aug, table, list(assume_zero) + list(held), 0.001, model=model, minimal=True, prefer=prefer)
    return Valuation(fit, zeros, centres)


def make_plan(machine: Machine, sphere: Sphere, positions: list[dict] | None = None,
              per_axis: int = DEFAULT_PER_AXIS, backlash_step: float = 0.0,
              clearance: float = DEFAULT_CLEARANCE, held: dict | None = None, assume_zero=()) -> Plan:
    """The rotary positions with their touches. Of the default grid, a position some touch of
    which would leave an axis' limits is left out (a note says which); given positions must all
    be reachable. Refused (NoAnswer) when the set is near-singular."""
    held = held or {}
    axes = machine_axes(machine)
    model = HeldModel(machine, held)
    given = positions is not None
    if not given:
        positions = default_positions(axes, per_axis, backlash_step)
    k = len(positions)
    rot = {a.name: np.array([p[a.name] for p in positions]) for a in axes.rotary}
    s0 = np.array(sphere.centre, float)
    centres = inverse_kinematics(machine, model, axes, rot, np.tile(s0, (k, 1)))
    # the tool's direction in the workpiece frame (up the spindle), at each position
    vals = {a.name: centres[:, i] for i, a in enumerate(axes.linear)}
    vals.update(rot)
    frames = np.broadcast_to(pose_frames(machine, model, vals, held), (k, 9))
    up = frames[:, 3:6] if machine.direction is not None else np.tile([0.0, 0.0, 1.0], (k, 1))
    # the tool axis' linear axis: the one moving the tool point most along the tool direction
    here = np.broadcast_to(pose_points(machine, model, vals, held), (k, 3))[0]
    along = np.array([(np.broadcast_to(pose_points(machine, model, {**vals, a.name: vals[a.name] + 1.0}, held),
                                       (k, 3))[0] - here) @ up[0] for a in axes.linear])
    j = int(np.argmax(np.abs(along)))
    tool_axis = axes.linear[j]
    retract = (tool_axis.name, tool_axis.to_internal(tool_axis.limits[1] if along[j] > 0 else tool_axis.limits[0]))
    kept, touches, notes = [], [], []
    for i, pos in enumerate(positions):
        these = _touches_at(machine, model, axes, sphere, pos, up[i], clearance, backlash_step, len(kept))
        outside = _outside(machine, axes, these, backlash_step)
        if outside:
            a = machine.symbol(outside[0])
            where = (f"position {i + 1} ({_where(machine, axes, pos)}) would take {a.name} to {outside[1]:g} "
                     f"{a.unit.name}, outside its limits [{a.limits[0]:g}, {a.limits[1]:g}]")
            if given:
                raise ChaincompError(f"--positions: {where}; move the sphere (--sphere) or choose other positions")
            notes.append(f"left out: {where}")
            continue
        kept.append(pos)
        touches += these
    if len(kept) < 2:
        raise ChaincompError(f"{len(kept)} rotary positions within the limits; at least two are needed"
                             + (f" ({notes[0]}{' and more' if len(notes) > 1 else ''})" if notes else "")
                             + ": move the sphere (--sphere) or give positions (--positions)")
    value = valuation(machine, axes, sphere, kept, held, assume_zero)
    plan = Plan(machine, sphere, axes, kept, touches, retract, value, backlash_step, notes)
    _refuse_singular(value.fit, f"these {len(kept)} positions", gain=noise_gain(value.fit))
    return plan


def _touches_at(machine, model, axes: Axes, sphere: Sphere, pos: dict, up: np.ndarray, clearance: float,
                backlash_step: float, index: int) -> list[Touch]:
    """A position's touches (TOUCHES around the tool direction ``up``), each approach's."""
    s0 = np.array(sphere.centre, float)
    h = sphere.contact + clearance
    kz = up / np.linalg.norm(up)
    e1 = np.cross(kz, [1.0, 0, 0] if abs(kz[0]) < 0.9 else [0, 1.0, 0])
    e1 /= np.linalg.norm(e1)
    e2 = np.cross(kz, e1)
    dirs = [math.cos(lat) * (math.cos(az) * e1 + math.sin(az) * e2) + math.sin(lat) * kz for lat, az in TOUCHES]
    # per touch: above the start (clear of the sphere), the start, the target past the surface
    pts = []
    for d in dirs:
        start = s0 + h * d
        pts += [start + h * kz, start, s0 + (sphere.contact - clearance) * d]
    lin = inverse_kinematics(machine, model, axes, pos, np.array(pts))
    out = []
    for approach in ("+", "-") if backlash_step > 0 else ("+",):
        for t in range(len(dirs)):
            start = {a.name: lin[3 * t + 1, j] for j, a in enumerate(axes.linear)}
            start.update(pos)
            out.append(Touch(index, approach, start, lin[3 * t + 2], lin[3 * t]))
    return out


def _outside(machine: Machine, axes: Axes, touches: list[Touch], backlash_step: float):
    """(axis, value in its declared unit) of the first value of these touches (their starts,
    targets and points above, the rotary axes' backlash approach) beyond an axis' limits."""
    for t in touches:
        for a in machine.axes:
            if a in axes.linear:
                at = [t.start[a.name], t.target[axes.linear.index(a)], t.above[axes.linear.index(a)]]
            else:
                at = [t.start[a.name] + s * backlash_step for s in (-1, 0, 1)]
            for x in (a.from_internal(v) for v in at):
                if not a.limits[0] - 1e-9 <= x <= a.limits[1] + 1e-9:
                    return a.name, x
    return None


def noise_gain(fit: Fit) -> dict[str, tuple[float, str]]:
    """Per error (not the sphere's) its standard uncertainty per µm of each centre coordinate, in
    µm for a length and arcsec for an angle, from a fit weighted by 1 µm (the valuation's)."""
    out = {}
    for p in fit.params:
        if p.name in fit.uncertainties and p.name not in NUISANCE:
            unit = "um" if p.kind == "length" else "arcsec"
            out[p.name] = (fit.uncertainties[p.name] / UNITS[unit].to_internal, unit)
    return out


def _refuse_singular(fit: Fit, what: str, source: str | None = None, gain: dict | None = None) -> None:
    """Refuse (NoAnswer) a near-singular fit: its column-scaled condition number above
    MAX_CONDITION (a combination left almost free), or, with ``gain`` (noise_gain of the
    positions' valuation), an error whose uncertainty is above MAX_NOISE_GAIN per µm (an error
    these positions hardly move: the column scaling hides it from the condition number)."""
    gain = gain or {}
    shown = sorted(gain, key=lambda n: -gain[n][0])[:3]
    if fit.condition > MAX_CONDITION or (shown and gain[shown[0]][0] > MAX_NOISE_GAIN):
        raise NoAnswer(f"{what} are near-singular for the errors left after fixing the gauge freedoms: condition "
                       f"number {fit.condition:.3g} (refused above {MAX_CONDITION:g})"
                       + ("; standard uncertainty per µm of the centres: "
                          + ", ".join(f"{n} {gain[n][0]:.3g} {gain[n][1]}" for n in shown)
                          + f" (refused above {MAX_NOISE_GAIN:g})" if shown else "")
                       + "; no values given: probe at positions that turn each rotary axis further (--positions), "
                         "or hold errors known from elsewhere (--hold)", source)


def _where(machine: Machine, axes: Axes, pos: dict) -> str:
    return ", ".join(f"{n} = {machine.symbol(n).from_internal(v):g}" for n, v in pos.items())


def _gcode_value(a: Symbol, value: float) -> str:
    """A value as LinuxCNC takes it in G21: mm, degrees."""
    v = value / (UNITS["mm"].to_internal if a.unit.kind == "length" else UNITS["deg"].to_internal)
    return f"{v:.4f}"


def gcode(plan: Plan, log_name: str, feed: float, command: str) -> str:
    """The probing program for LinuxCNC: G21/G90, zero offsets in G59.3, the probe log opened
    with PROBEOPEN, per position the rotary move (from below, and with a backlash step from above
    too) and per touch: above the start, the start, G38.2 towards the sphere, back."""
    m, axes = plan.machine, plan.axes
    lin = axes.linear
    letter = axes.letters
    zero = " ".join(f"{letter[a.name]}0" for a in m.axes)
    out = [*_comments(f"chaincomp probe plan for {m.name}: {command}"),
           *_comments(f"{len(plan.positions)} rotary positions, {len(plan.touches)} touches; the sphere at "
                      + _sphere_text(plan.sphere)),
           "(the tool is the probe: the machine file's tool point at the stylus ball's centre)",
           "G21 G90 G94 G40 G49 G92.1 G61",   # exact path: no blending near the sphere nor past a limit
           f"G10 L2 P9 {zero} (no work offset: G59.3 zeroed and used by this program only)",
           "G59.3",
           f"F{feed:.1f}",
           f"(PROBEOPEN {gcode_comment(log_name)[:GCODE_LINE - 12]})"]
    retract_axis, retract_to = plan.retract
    ra = m.symbol(retract_axis)
    last = None
    for t in plan.touches:
        key = (t.position, t.approach)
        if key != last:
            pos = plan.positions[t.position]
            out += _comments(f"position {t.position + 1} of {len(plan.positions)}: " + _where(m, axes, pos)
                             + (f", approach {t.approach}" if plan.backlash_step else ""))
            out.append(f"G0 {letter[retract_axis]}{_gcode_value(ra, retract_to)}")
            if plan.backlash_step:
                step = -plan.backlash_step if t.approach == "+" else plan.backlash_step
                out.append("G0 " + " ".join(f"{letter[n]}{_gcode_value(m.symbol(n), v + step)}"
                                            for n, v in pos.items()))
            out.append("G0 " + " ".join(f"{letter[n]}{_gcode_value(m.symbol(n), v)}" for n, v in pos.items()))
            out.append("G0 " + " ".join(f"{letter[a.name]}{_gcode_value(a, t.above[i])}" for i, a in enumerate(lin)
                                        if a.name != retract_axis))
            last = key
        out.append("G0 " + " ".join(f"{letter[a.name]}{_gcode_value(a, t.above[i])}" for i, a in enumerate(lin)))
        out.append("G0 " + " ".join(f"{letter[a.name]}{_gcode_value(a, t.start[a.name])}" for a in lin))
        out.append("G38.2 " + " ".join(f"{letter[a.name]}{_gcode_value(a, t.target[i])}" for i, a in enumerate(lin)))
        out.append("G0 " + " ".join(f"{letter[a.name]}{_gcode_value(a, t.start[a.name])}" for a in lin))
        out.append("G0 " + " ".join(f"{letter[a.name]}{_gcode_value(a, t.above[i])}" for i, a in enumerate(lin)))
    out += [f"G0 {letter[retract_axis]}{_gcode_value(ra, retract_to)}", "(PROBECLOSE)", "M2", ""]
    # a move to where the probe already is (the top touch starts where it is above) is left out
    return "\n".join(line for k, line in enumerate(out) if k == 0 or line != out[k - 1])


# LinuxCNC's reader (rs274ngc read_text: fgets into LINELEN = 255 characters, a read of 254 refused as
# "Command too long", the newline counted) takes at most 252 characters a line; rs274 -g agrees
GCODE_LINE = 252


def _comments(text: str) -> list[str]:
    """``text`` as G-code comment lines, each within GCODE_LINE characters."""
    t = gcode_comment(text)
    width = GCODE_LINE - 2
    return [f"({t[i:i + width]})" for i in range(0, max(len(t), 1), width)]


def _sphere_text(s: Sphere) -> str:
    return (f"({', '.join(f'{v:g}' for v in s.centre)}) mm, radius {s.radius:g} mm, "
            f"stylus ball radius {s.stylus:g} mm")


def plan_csv(plan: Plan, command: str) -> str:
    """Every touch: its position and approach, every axis at the start (declared units) and the
    linear axes the move aims at (to_NAME), for any controller; ``probe fit --plan`` reads it."""
    m, lin = plan.machine, plan.axes.linear
    out = [f"# {one_line(f'chaincomp probe plan for {m.name}: {command}')}",
           f"# {one_line('the sphere at ' + _sphere_text(plan.sphere))}",
           "# approach +: the rotary axes came to their values from below, -: from above",
           ",".join(["position", "approach"] + [csv_text(a.name) for a in m.axes]
                    + [csv_text(f"to_{a.name}") for a in lin])]
    for t in plan.touches:
        out.append(",".join([str(t.position + 1), t.approach]
                            + [f"{a.from_internal(t.start[a.name]):.6f}" for a in m.axes]
                            + [f"{a.from_internal(t.target[i]):.6f}" for i, a in enumerate(lin)]))
    return "\n".join(out) + "\n"


@dataclass
class PlannedTouch:
    line: int
    position: int
    approach: str
    start: dict          # axis -> internal
    target: np.ndarray   # (3,) linear internal


def read_plan(path: str, machine: Machine) -> list[PlannedTouch]:
    """The touches of a plan CSV (plan_csv's format)."""
    axes = machine_axes(machine)
    data = csvtable.read(path, max_rows=MAX_LOG_LINES)
    want = ["position", "approach"] + [a.name for a in machine.axes] + [f"to_{a.name}" for a in axes.linear]
    col = _columns(data, want, path)
    out = []
    for r in data.rows:
        pos = data.number(r, col["position"])
        if not (pos == int(pos) and 1 <= pos <= MAX_POSITIONS):
            data.fail(f"expected a position number 1 to {MAX_POSITIONS}", r.line, "position")
        approach = r.cells[col["approach"]]
        if approach not in ("+", "-"):
            data.fail(f"expected + or -, got {approach!r}", r.line, "approach")
        start = {a.name: a.to_internal(data.number(r, col[a.name])) for a in machine.axes}
        target = np.array([a.to_internal(data.number(r, col[f"to_{a.name}"])) for a in axes.linear])
        out.append(PlannedTouch(r.line, int(pos) - 1, approach, start, target))
    if not out:
        raise ChaincompError("no touches: expected a header row and at least one row", path)
    return out


def _columns(data, want: list[str], path: str, optional=()) -> dict[str, int]:
    header = data.header
    for c in header:
        if c not in want and c not in optional:
            raise ChaincompError(f"unknown column {c!r} (expected {', '.join(want + list(optional))})", path,
                                 data.line, "header")
    missing = [c for c in want if c not in header]
    if missing:
        raise ChaincompError(f"missing column {missing[0]!r} (expected {', '.join(want)})", path, data.line, "header")
    return {c: header.index(c) for c in header}


# ----------------------------------------------------------------------------- logs

@dataclass
class Group:
    """The touches of one rotary position and approach, as read."""
    file: str
    line: int                 # of its first touch
    rotary: dict              # axis -> value (internal)
    approach: str
    points: list[np.ndarray] = field(default_factory=list)   # (3,) linear axes at each touch, internal
    lines: list[int] = field(default_factory=list)
    radius: float | None = None   # a centres file: the probed sphere radius given (internal)
    key: tuple | None = None      # (position, approach) of the plan, when read with one


def read_linuxcnc_log(path: str, machine: Machine, plan: list[PlannedTouch] | None = None) -> list[Group]:
    """LinuxCNC's probe log (PROBEOPEN): per successful G38 move one line of nine numbers, the
    position X Y Z A B C U V W in program units (mm and degrees under the plan's G21) of the
    coordinate system the move ran in (emccanon.cc GET_EXTERNAL_PROBE_POSITION, "%f" x 9). With
    the plan, line k is its touch k (position and approach); without it, consecutive lines at the
    same rotary values are one position."""
    axes = machine_axes(machine)
    text = read_text(path)
    touches = []
    for lineno, line in enumerate(text.splitlines(), 1):
        if not line.strip():
            continue
        cells = line.split()
        if len(cells) != 9:
            raise ChaincompError(f"expected the nine numbers X Y Z A B C U V W of a LinuxCNC probe log line, got "
                                 f"{len(cells)}", path, lineno)
        try:
            nums = [parse_number(c) for c in cells]
        except ValueError as exc:
            raise ChaincompError(str(exc), path, lineno) from None
        if len(touches) >= MAX_LOG_LINES:
            raise ChaincompError(f"more than {MAX_LOG_LINES} touches", path, lineno)
        vals = {}
        for a in machine.axes:
            unit = UNITS["mm"] if a.unit.kind == "length" else UNITS["deg"]
            vals[a.name] = nums[LETTERS.index(axes.letters[a.name])] * unit.to_internal
        touches.append((lineno, vals))
    if not touches:
        raise ChaincompError("no touches: the probe log is empty (did every G38.2 move fail?)", path)
    return _grouped(path, machine, axes, touches, plan)


def _grouped(path, machine, axes: Axes, touches, plan, approaches=None) -> list[Group]:
    if plan is not None and len(plan) != len(touches):
        raise ChaincompError(f"{len(touches)} touches, but the plan has {len(plan)} (a G38.2 move that found "
                             f"nothing, or another plan's log?)", path)
    groups: list[Group] = []
    for k, (lineno, vals) in enumerate(touches):
        rot = {a.name: vals[a.name] for a in axes.rotary}
        if plan is not None:
            key, approach = (plan[k].position, plan[k].approach), plan[k].approach
            for a in axes.rotary:
                if abs(a.from_internal(rot[a.name]) - a.from_internal(plan[k].start[a.name])) > 1e-3:
                    raise ChaincompError(f"{a.name} = {a.from_internal(rot[a.name]):g} {a.unit.name}, but the plan's "
                                         f"touch {k + 1} is at {a.from_internal(plan[k].start[a.name]):g}: not this "
                                         f"plan's log", path, lineno, a.name)
        else:
            approach = approaches[k] if approaches else "+"
            key = None
        same = groups and groups[-1].approach == approach and (
            key == groups[-1].key if plan is not None else
            all(abs(machine.symbol(n).from_internal(v - groups[-1].rotary[n])) < SAME_ANGLE for n, v in rot.items()))
        if not same:
            groups.append(Group(path, lineno, rot, approach, key=key))
        groups[-1].points.append(np.array([vals[a.name] for a in axes.linear]))
        groups[-1].lines.append(lineno)
    return groups


def read_csv_log(path: str, machine: Machine) -> list[Group]:
    """A CSV of touched points (every axis of the machine in its declared unit, one row per
    touch; optional columns position, a number per rotary position, and approach, + or -) or of
    sphere centres (the same, plus radius: the probed sphere radius in the machine's length unit,
    one row per position)."""
    axes = machine_axes(machine)
    data = csvtable.read(path, max_rows=MAX_LOG_LINES)
    col = _columns(data, [a.name for a in machine.axes], path, optional=("position", "approach", "radius"))
    length = UNITS[machine.length_unit].to_internal
    touches, approaches, positions, radii = [], [], [], []
    for r in data.rows:
        vals = {a.name: a.to_internal(data.number(r, col[a.name])) for a in machine.axes}
        approach = r.cells[col["approach"]] if "approach" in col else "+"
        if approach not in ("+", "-"):
            data.fail(f"expected + or -, got {approach!r}", r.line, "approach")
        touches.append((r.line, vals))
        approaches.append(approach)
        positions.append(data.number(r, col["position"]) if "position" in col else None)
        if "radius" in col:
            radius = data.number(r, col["radius"]) * length
            if not radius > 0:
                data.fail(f"expected a positive radius, got {r.cells[col['radius']]!r}", r.line, "radius")
            radii.append(radius)
    if not touches:
        raise ChaincompError("no rows: expected a header row and at least one row", path)
    if radii:      # a centres file: each row is a position's centre
        groups = []
        for (lineno, vals), approach, radius in zip(touches, approaches, radii):
            g = Group(path, lineno, {a.name: vals[a.name] for a in axes.rotary}, approach,
                      [np.array([vals[a.name] for a in axes.linear])], [lineno], radius)
            groups.append(g)
        return groups
    if positions[0] is not None:
        plan = [PlannedTouch(line, int(p), a, vals, np.zeros(3)) for (line, vals), p, a in
                zip(touches, positions, approaches)]
        return _grouped(path, machine, axes, touches, plan)
    return _grouped(path, machine, axes, touches, None, approaches)


def read_logs(paths: list[str], machine: Machine, plan: list[PlannedTouch] | None = None) -> list[Group]:
    """Every file's groups: a .csv file by read_csv_log, any other as LinuxCNC's probe log."""
    groups = []
    for path in paths:
        groups += read_csv_log(path, machine) if path.lower().endswith(".csv") else \
            read_linuxcnc_log(path, machine, plan)
    return groups


# ----------------------------------------------------------------------------- sphere centres

def fit_sphere(points: np.ndarray, radius: float | None = None) -> tuple[np.ndarray, float, np.ndarray]:
    """Centre, radius and each point's radial residual of the least-squares sphere through
    ``points`` (k >= 4, not coplanar), or of the given ``radius``: the algebraic fit, then
    Gauss-Newton on the distances."""
    a = np.hstack([2 * points, np.ones((len(points), 1))])
    sol = lsq.solve(a, (points ** 2).sum(axis=1))
    free = radius is None                   # the radius fitted too: x is the centre and the radius
    c = sol[:3]
    start = np.append(c, math.sqrt(max(sol[3] + c @ c, 0.0))) if free else c

    def linearise(x):       # the residual is each point's distance from the centre minus the radius
        d = points - x[:3]
        dist = np.linalg.norm(d, axis=1)
        return -(dist - (x[3] if free else radius)), \
            np.hstack([-d / dist[:, None], -np.ones((len(points), 1))])[:, :4 if free else 3]

    x, _, _ = lsq.gauss_newton(linearise, start, 20, lambda step, x, j: np.linalg.norm(step) < 1e-12)
    c, rho = x[:3], (x[3] if free else radius)
    return c, rho, np.linalg.norm(points - c, axis=1) - rho


@dataclass
class Centre:
    group: Group
    centre: np.ndarray       # (3,) linear axes at the sphere centre, internal
    radius: float            # probed sphere radius (stylus removed), internal
    residuals: np.ndarray    # radial residual per touch, internal (empty for a centres file)


def sphere_centres(groups: list[Group], sphere: Sphere, tolerance: float) -> list[Centre]:
    """Each group's sphere centre. Its radius fitted alone first: one further than ``tolerance``
    from the nominal is refused (NoAnswer) with the numbers (a dirty sphere or stylus, a wrong
    stylus radius); then the centres again with the radius all groups share (the same sphere and
    stylus throughout: their mean), which the plan's touches make as certain in every direction."""
    free = []
    for g in groups:
        if g.radius is not None:
            free.append((g, g.points[0], g.radius))
            continue
        pts = np.array(g.points)
        if len(pts) < 4 or np.linalg.matrix_rank(pts[1:] - pts[0], tol=1e-6) < 3:
            raise ChaincompError(f"{len(pts)} touches at this position (lines {', '.join(str(n) for n in g.lines[:6])}"
                                 f"): a sphere needs at least four, not in one plane", g.file, g.line)
        centre, rho, _ = fit_sphere(pts)
        free.append((g, centre, rho - sphere.stylus))
    for g, _, radius in free:
        if not abs(radius - sphere.radius) <= tolerance:
            raise NoAnswer(f"the probed sphere radius is {radius:.4f} mm, the nominal {sphere.radius:.4f} mm: "
                           f"{1000 * (radius - sphere.radius):+.1f} µm, beyond ±{1000 * tolerance:g} µm "
                           f"(--radius-tolerance): a dirty sphere or stylus, a wrong stylus radius (--stylus) or "
                           f"sphere (--radius); no values given", g.file, g.line)
    touched = [(g, r) for g, _, r in free if g.radius is None]
    shared = float(np.average([r for _, r in touched], weights=[len(g.points) for g, _ in touched])) \
        if touched else 0.0
    out = []
    for g, centre, radius in free:
        if g.radius is None:
            centre, _, res = fit_sphere(np.array(g.points), shared + sphere.stylus)
            out.append(Centre(g, centre, radius, res))
        else:
            out.append(Centre(g, centre, radius, np.zeros(0)))
    return out


# ----------------------------------------------------------------------------- the fit

@dataclass
class ProbeFit:
    """Everything ``probe fit`` found, as plain numbers (internal units unless said): the
    calibration report reads it through ``to_json``."""
    machine: Machine
    sphere: Sphere
    fit: Fit                                   # identify's, on with_sphere(machine)
    centres: list[Centre]
    positions: list[dict]                      # rotary values per fitted position (approaches averaged)
    residuals_before: np.ndarray               # (positions, 3) centre misfit with the errors held/zero, mm
    residuals_after: np.ndarray                # (positions, 3) at the estimates, mm
    dispersion: dict[str, tuple[float, float]]  # axis (and "all") -> (before, after), mm
    gauge: dict[str, str]                      # error -> why a sphere cannot see it, in words
    held: dict = field(default_factory=dict)
    sphere_offset: tuple[float, float, float] = (0.0, 0.0, 0.0)   # fitted, mm
    backlash: dict[str, tuple[float, float]] = field(default_factory=dict)   # axis -> (value, sigma), rad
    value: Valuation | None = None             # the positions' valuation, which fixed the gauge


def gauge_explanations(machine: Machine, value: Valuation) -> dict[str, str]:
    """Each error a sphere cannot see, in words: what carries it and what that means for the
    user (a zero angle shows as a rotation of the part frame, set by a work offset)."""
    fit, out = value.fit, {}
    for name in value.gauge:
        meaning = machine.symbol(name).meaning
        what = (f"{name} ({meaning}) is {value.zeros[name]}'s zero angle (it moves the tool as turning "
                f"{value.zeros[name]} does)" if name in value.zeros else f"{name} ({meaning})")
        carriers = fit.carried.get(name)
        if carriers is None:
            out[name] = f"{what} moves no probed centre at these positions; held at 0"
            continue
        others = [n for n in carriers if n not in NUISANCE]
        if not others:
            out[name] = (f"{what}: a sphere cannot see it: it moves every probed centre as a move of the sphere on "
                         f"the table does, so it shows as a shift or rotation of the part frame, absorbed by the "
                         f"sphere's position; held at 0: set it with the work offset when the part is set up")
        else:
            out[name] = (f"{what}: a sphere cannot tell it from {', '.join(others)}: it moves the probed centres "
                         f"as a combination of {', '.join(others)} and the sphere's position does; held at 0, "
                         f"the fitted {', '.join(others)} carr{'ies' if len(others) == 1 else 'y'} it (together "
                         f"right; alone one choice of many)")
    return out


def _residuals(machine: Machine, held: dict, table: Table, errors: dict) -> np.ndarray:
    """(rows, 3) tool point at the measured centres minus the sphere's place (nominal + offset)."""
    aug = with_sphere(machine)
    p = np.broadcast_to(pose_points(aug, HeldModel(aug, held), table.axes, errors), table.coords.shape)
    return p - table.coords


def _dispersion(axes: Axes, positions: list[dict], before: np.ndarray, after: np.ndarray):
    """Per rotary axis the largest distance between two centres of positions that differ in that
    axis alone (how far the sphere seemed to move as it turned), before and after; and over all."""
    out = {}

    def spread(r, idx):
        pts = r[idx]
        return float(np.max(np.linalg.norm(pts[:, None] - pts[None], axis=-1), initial=0.0))

    for a in axes.rotary:
        groups: dict[tuple, list[int]] = {}
        for i, p in enumerate(positions):
            groups.setdefault(tuple(round(v, 9) for n, v in sorted(p.items()) if n != a.name), []).append(i)
        sets = [idx for idx in groups.values() if len(idx) > 1]
        if sets:
            out[a.name] = (max(spread(before, s) for s in sets), max(spread(after, s) for s in sets))
    every = list(range(len(positions)))
    out["all"] = (spread(before, every), spread(after, every))
    return out


def _backlash(machine: Machine, axes: Axes, held: dict, centres: list[Centre], values: dict):
    """Per rotary axis the lost motion from pairs of groups at the same rotary values approached
    from below (+) and from above (-): f(c+, θ) - f(c-, θ) = Σ ∂f/∂θ_j b_j (the table stops b/2
    short from either side), least squares over all pairs; (value, standard uncertainty) rad."""
    plus = {tuple(sorted(c.group.rotary.items())): c for c in centres if c.group.approach == "+"}
    pairs = [(plus[k], c) for c in centres if c.group.approach == "-"
             for k in [tuple(sorted(c.group.rotary.items()))] if k in plus]
    if not pairs:
        return {}
    aug = with_sphere(machine)
    model = HeldModel(aug, held)
    rows, rhs = [], []
    for cp, cm in pairs:
        def f(centre, rot):
            vals = {a.name: centre[i] for i, a in enumerate(axes.linear)}
            vals.update(rot)
            return np.broadcast_to(pose_points(aug, model, vals, values), (3,))
        rot = cp.group.rotary
        rhs.append(f(cp.centre, rot) - f(cm.centre, rot))
        h = 1e-6
        rows.append(np.stack([(f(cp.centre, {**rot, n: rot[n] + h}) - f(cp.centre, {**rot, n: rot[n] - h})) / (2 * h)
                              for n in rot], axis=-1))
    j, y = np.vstack(rows), np.concatenate(rhs)
    if len(y) <= j.shape[1]:
        return {}
    b = lsq.solve(j, y)
    # pinv, not inv: pairs that leave a rotary axis still (a singular JᵀJ) give the others theirs
    cov = lsq.residual_variance(y - j @ b, len(y) - len(b)) * np.linalg.pinv(j.T @ j)
    names = list(pairs[0][0].group.rotary)
    return {n: (float(b[i]), float(math.sqrt(max(cov[i, i], 0.0)))) for i, n in enumerate(names)}


def probe_fit(machine: Machine, groups: list[Group], sphere: Sphere, held: dict | None = None, assume_zero=(),
              tolerance: float = DEFAULT_RADIUS_TOLERANCE) -> ProbeFit:
    """Sphere centres, then the location errors (every error not held or assumed zero) with the
    sphere offset as nuisance; refused (NoAnswer) when near-singular or not converged."""
    held = held or {}
    axes = machine_axes(machine)
    centres = sphere_centres(groups, sphere, tolerance)
    # the two approaches of a position are averaged (each is off by half the lost motion)
    byrot: dict[tuple, list[Centre]] = {}
    for c in centres:
        byrot.setdefault(tuple(sorted(c.group.rotary.items())), []).append(c)
    positions = [dict(k) for k in byrot]
    if len(positions) < 2:
        raise ChaincompError(f"{len(positions)} rotary position in the logs: the rotary axes' errors need several",
                             groups[0].file)
    mean = np.array([np.mean([c.centre for c in cs], axis=0) for cs in byrot.values()])
    lines = [cs[0].group.line for cs in byrot.values()]
    source = ", ".join(dict.fromkeys(g.file for g in groups))
    table = _centre_table(machine, axes, sphere, positions, mean, lines, source)
    value = valuation(machine, axes, sphere, positions, held, assume_zero)
    _refuse_singular(value.fit, f"the {len(positions)} rotary positions of the logs", source, noise_gain(value.fit))
    aug = with_sphere(machine)
    fit = identify(aug, table, list(assume_zero) + list(held) + value.gauge, model=HeldModel(aug, held),
                   minimal=True, prefer=NUISANCE)
    if not fit.converged:
        raise NoAnswer(f"the fit did not converge in {fit.iterations} Gauss-Newton iterations (rms residual "
                       f"{1000 * fit.rms:.4g} µm); no values given", source)
    _refuse_singular(fit, f"the {len(positions)} rotary positions of the logs", source)
    before = _residuals(machine, held, table, {})
    before = before - before.mean(axis=0)          # the sphere where it fits best, every error as held/zero
    after = _residuals(machine, held, table, fit.estimates)
    offset = tuple(fit.estimates.get(n, 0.0) for n in NUISANCE)
    values = {n: v for n, v in fit.estimates.items()}
    return ProbeFit(machine, sphere, fit, centres, positions, before, after,
                    _dispersion(axes, positions, before, after), gauge_explanations(machine, value), held, offset,
                    _backlash(machine, axes, held, centres, values), value)


def production_fit(pf: ProbeFit) -> Fit:
    """identify's fit with the production machine and the sphere's parameters stripped, the
    gauge freedoms held at zero with the combination that carries them: what params_yaml
    writes for export and chaincompd."""
    f, gauge = pf.fit, set(pf.value.gauge)
    keep = [p for p in f.params if p.name not in NUISANCE]
    carried = {n: {k: v for k, v in c.items() if k not in NUISANCE} or {"the sphere's position": 1.0}
               for n, c in pf.value.fit.carried.items() if n in gauge}
    return replace(f, machine=pf.machine, params=keep, fitted=[n for n in f.fitted if n not in NUISANCE],
                   estimates={n: v for n, v in f.estimates.items() if n not in NUISANCE},
                   uncertainties={n: v for n, v in f.uncertainties.items() if n not in NUISANCE},
                   redundant={n: pf.gauge[n] for n in gauge}, carried=carried,
                   unidentifiable={n: v for n, v in f.unidentifiable.items() if n not in NUISANCE},
                   assumed_zero=[n for n in f.assumed_zero if n not in pf.held and n not in gauge])


# ----------------------------------------------------------------------------- reports

def _display(machine: Machine, name: str, value: float) -> tuple[float, str]:
    s = machine.symbol(name) if name not in NUISANCE else None
    unit = s.unit if s is not None else UNITS["um"]
    return value / unit.to_internal, unit.name


def to_json(pf: ProbeFit, source: str) -> dict:
    """The fit's numbers for a program (and the calibration report): internal units (mm, rad)."""
    f, m = pf.fit, pf.machine
    names = list(f.estimates)
    return {
        "machine": m.name, "logs": source, "units": "internal (mm, rad)",
        "sphere": {"nominal_centre": list(pf.sphere.centre), "radius": pf.sphere.radius, "stylus": pf.sphere.stylus,
                   "fitted_offset": list(pf.sphere_offset)},
        "centres": [{"file": c.group.file, "line": c.group.line, "approach": c.group.approach,
                     "rotary": c.group.rotary, "linear": list(map(float, c.centre)), "radius": c.radius,
                     "touch_residuals": list(map(float, c.residuals))} for c in pf.centres],
        "positions": [{"rotary": p, "residual_before": list(map(float, b)), "residual_after": list(map(float, a))}
                      for p, b, a in zip(pf.positions, pf.residuals_before, pf.residuals_after)],
        "dispersion": {k: {"before": b, "after": a} for k, (b, a) in pf.dispersion.items()},
        "estimates": {n: {"value": f.estimates[n], "uncertainty": f.uncertainties[n]} for n in names
                      if n not in NUISANCE},
        "correlations": [{"errors": [a, b], "value": c} for a, b, c in f.correlations],
        "correlation_matrix": None if f.correlation is None else {   # of the estimates, the sphere's too
            "names": list(f.estimates), "values": [list(map(float, r)) for r in f.correlation]},
        "unidentifiable": pf.gauge,
        "held": {n: (v if isinstance(v, float) else "varying") for n, v in pf.held.items()},
        "assumed_zero": [n for n in f.assumed_zero if n not in pf.held],
        "backlash": {n: {"value": v, "uncertainty": s} for n, (v, s) in pf.backlash.items()},
        "condition_number": f.condition, "rank": f.rank, "degrees_of_freedom": f.dof,
        "rms_residual": f.rms, "iterations": f.iterations, "converged": f.converged,
    }


def to_text(pf: ProbeFit, source: str) -> str:
    f, m = pf.fit, pf.machine
    um = 1000.0
    lines = [f"probe fit {m.name} from {source}: {len(pf.centres)} sphere centres at {len(pf.positions)} rotary "
             f"positions; {len([n for n in f.fitted if n not in NUISANCE])} errors and the sphere's position fitted",
             f"probed sphere radius: {min(c.radius for c in pf.centres):.4f} to "
             f"{max(c.radius for c in pf.centres):.4f} mm (nominal {pf.sphere.radius:.4f})"]
    touch = np.concatenate([c.residuals for c in pf.centres])
    if touch.size:
        lines.append(f"touches: rms {um * math.sqrt(float(np.mean(touch ** 2))):.3g} µm from their position's sphere")
    lines.append(f"{'converged' if f.converged else 'NOT converged'} after {f.iterations} Gauss-Newton iterations; "
                 f"rms centre residual {um * f.rms:.3g} µm; condition number {f.condition:.3g}; "
                 f"{f.dof:.4g} degrees of freedom")
    lines.append("dispersion of the sphere centre (largest distance between two centres as the axis turns alone): "
                 "before -> after")
    for k, (b, a) in pf.dispersion.items():
        lines.append(f"  {k:<6} {um * b:10.3f} µm -> {um * a:8.3f} µm")
    width = max([10] + [len(n) for n in f.estimates])
    lines.append(f"  {'error':<{width}}  estimate ± standard uncertainty")
    for n, v in f.estimates.items():
        x, unit = _display(m, n, v)
        u, _ = _display(m, n, f.uncertainties[n])
        lines.append(f"  {n:<{width}}  {x:+.4g} ± {u:.2g} {unit}" + ("   (the sphere, not written)"
                                                                      if n in NUISANCE else ""))
    lines.append("correlations above 0.9: " + (", ".join(f"{a}/{b} {c:+.3f}" for a, b, c in f.correlations) or "none"))
    if pf.backlash:
        lines.append("rotary backlash (two approach directions): " + ", ".join(
            f"{n} {v / UNITS['arcsec'].to_internal:+.3g} ± {s / UNITS['arcsec'].to_internal:.2g} arcsec"
            for n, (v, s) in pf.backlash.items()))
    if pf.gauge:
        lines.append("not identifiable by probing a sphere (gauge freedoms, fixed):")
        lines += [f"  {why}" for why in pf.gauge.values()]
    if pf.held:
        lines.append(f"held at given values (--hold): {', '.join(pf.held)}")
    return "\n".join(lines)


def plan_text(plan: Plan, outputs: list[str]) -> str:
    f, m = plan.valuation.fit, plan.machine
    lines = [f"probe plan {m.name}: {len(plan.positions)} rotary positions, {len(plan.touches)} touches; the sphere "
             f"at {_sphere_text(plan.sphere)}",
             "positions: " + "; ".join(_where(m, plan.axes, p) for p in plan.positions),
             f"valuation: condition number {f.condition:.3g} (refused above {MAX_CONDITION:g}); {f.rank} combinations "
             f"of {len(f.params)} parameters seen; standard uncertainties per µm of each centre coordinate "
             f"(refused above {MAX_NOISE_GAIN:g}):"]
    lines += [f"  {n}: ± {g:.2g} {unit}" for n, (g, unit) in noise_gain(f).items()]
    gauge = gauge_explanations(m, plan.valuation)
    if gauge:
        lines.append("not identifiable by probing a sphere (gauge freedoms, fixed at 0 by the fit):")
        lines += [f"  {why}" for why in gauge.values()]
    lines += [f"note: {n}" for n in plan.notes]
    lines += [f"wrote {o}" for o in outputs]
    return "\n".join(lines)


# ----------------------------------------------------------------------------- simulation

def simulate_log(machine: Machine, touches: list[PlannedTouch], values: dict, sphere_centre, sphere: Sphere,
                 noise: float, rng: np.random.Generator, backlash: dict | None = None) -> str:
    """A LinuxCNC probe log of ``touches`` run on the true machine (errors ``values``, internal
    units) with the sphere at ``sphere_centre`` (workpiece frame): each G38.2 move stops where
    the stylus ball first touches the sphere (bisection along the move), the rotary axes short of
    their command by half their ``backlash`` in the direction they came from; Gaussian noise of
    ``noise`` (mm) on each logged linear coordinate; "%f" x 9 as emccanon.cc writes them."""
    axes = machine_axes(machine)
    model = ExactModel(machine)
    backlash = backlash or {}
    s = np.array(sphere_centre, float)
    k = len(touches)
    start = np.array([[t.start[a.name] for a in axes.linear] for t in touches])
    target = np.array([t.target for t in touches])
    rot = {a.name: np.array([t.start[a.name] - (1 if t.approach == "+" else -1) * backlash.get(a.name, 0.0) / 2
                             for t in touches]) for a in axes.rotary}

    def gap(lam):      # (k,) distance of the stylus centre from the sphere centre minus the contact distance
        x = start + lam[:, None] * (target - start)
        vals = {a.name: x[:, i] for i, a in enumerate(axes.linear)}
        vals.update(rot)
        p = np.broadcast_to(pose_points(machine, model, vals, values), (k, 3))
        return np.linalg.norm(p - s, axis=1) - sphere.contact

    lo, hi = np.zeros(k), np.ones(k)
    if np.any(gap(lo) <= 0) or np.any(gap(hi) > 0):
        raise ChaincompError("a simulated G38.2 move starts inside the sphere or never reaches it (the true sphere "
                             "is too far from the plan's)")
    for _ in range(60):
        mid = (lo + hi) / 2
        inside = gap(mid) <= 0
        hi, lo = np.where(inside, mid, hi), np.where(inside, lo, mid)
    x = start + hi[:, None] * (target - start) + noise * rng.standard_normal((k, 3))
    out = []
    for i, t in enumerate(touches):
        nums = [0.0] * 9
        for j, a in enumerate(axes.linear):
            nums[LETTERS.index(axes.letters[a.name])] = x[i, j] / UNITS["mm"].to_internal
        for a in axes.rotary:
            nums[LETTERS.index(axes.letters[a.name])] = t.start[a.name] / UNITS["deg"].to_internal
        out.append(" ".join(f"{v:f}" for v in nums))
    return "\n".join(out) + "\n"


def plan_touches(plan: Plan) -> list[PlannedTouch]:
    """The plan's touches as read_plan gives them from its CSV."""
    return [PlannedTouch(0, t.position, t.approach, t.start, t.target) for t in plan.touches]
