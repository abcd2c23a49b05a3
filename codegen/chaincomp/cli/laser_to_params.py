"""``chaincomp laser-to-params``: one channel of a laser calibration (a CSV of ISO 230-2 runs)
as an error table in a params file, new or merged into an existing one."""

from __future__ import annotations

import shlex
import sys

import numpy as np

from ..errors import ChaincompError
from ..measure import iso230_2 as iso
from ..measure.calibration import _write_loadable, varying_axis
from ..model.machine import ROT_PLANE, Machine, Rotation
from ..escape import one_line
from ..model.params_merge import merge
from ..model.varying import INTERPOLATIONS, MAX_TABLE_KNOTS, OUTSIDE
from ..symbolic.numeric import ExactModel
from .common import add_machine_argument, check_output, load
from .iso230_2 import add_columns_arguments, read

_FIELD = {"mean": ("mean", "mean bidirectional deviations x̄_i"),
          "up": ("mean_up", "mean unidirectional deviations x̄_i↑ (positive approach)"),
          "down": ("mean_down", "mean unidirectional deviations x̄_i↓ (negative approach)")}


def add_parser(sub) -> None:
    p = sub.add_parser("laser-to-params", help="a laser calibration channel (ISO 230-2 runs) as an error table",
                       description="Evaluate a CSV of laser runs as 'chaincomp iso230-2' does and write the mean "
                                   "deviation at each target as a table of ERROR over its axis in a params "
                                   "file (µm or arcsec), new or merged into an existing file without touching "
                                   "its other entries. The deviation is taken as ISO 230-1 measures it, the "
                                   "tool relative to the workpiece; the machine file's sign for ERROR is "
                                   "checked on its exact model and a table of an error written with the "
                                   "opposite sign is negated (with a warning), so that the model reproduces "
                                   "the measurement.")
    add_machine_argument(p, alias=True)
    add_columns_arguments(p)
    p.add_argument("--error", required=True, metavar="NAME", help="the error symbol the runs measure (e.g. EXX)")
    p.add_argument("--axis", metavar="AXIS", help="the axis the error varies along (default: from an ISO 230-1 "
                   "name such as EXX or EBY, else the slide whose error block holds it)")
    p.add_argument("--direction", default="mean", choices=tuple(_FIELD),
                   help="which mean: bidirectional (default), or one direction of approach")
    p.add_argument("-o", "--output", required=True, metavar="P.yaml", help="params file to write")
    p.add_argument("--merge", metavar="P0.yaml", help="copy this params file and put the table into it, "
                   "replacing an entry of the same error; every other line is kept")
    p.add_argument("--interpolation", default="linear", choices=INTERPOLATIONS,
                   help="interpolation written into the table (default linear, as a CNC's pitch error "
                        "compensation)")
    p.add_argument("--outside", default="hold", choices=OUTSIDE, help="beyond the first and last target "
                   "(default hold)")
    p.set_defaults(run=run)


def _axis_for(machine: Machine, error: str, given: str | None) -> str:
    names = [a.name for a in machine.axes]
    if given is not None:
        if given not in names:
            raise ChaincompError(f"--axis: {given!r} is not an axis of {machine.name} (axes: {', '.join(names)})")
        return given
    axis = varying_axis(machine, error)
    if axis is not None:
        return axis
    raise ChaincompError(f"--axis: give the axis {error} varies along (axes: {', '.join(names)})")


def _orientation(machine: Machine, values: dict) -> np.ndarray:
    """The rotation of the chain (leftmost matrix first) at values (internal units)."""
    subs = {s.sym: values[s.name] for s in machine.symbols}
    r = np.eye(3)
    for el in machine.chain:
        if isinstance(el, Rotation):
            i, j = ROT_PLANE[el.axis]
            a = float(el.angle.evalf(subs=subs))
            step = np.eye(3)
            step[i, i], step[i, j], step[j, i], step[j, j] = np.cos(a), -np.sin(a), np.sin(a), np.cos(a)
            r = r @ step
    return r


def gain(machine: Machine, error: str) -> tuple[np.ndarray, np.ndarray]:
    """At the reference pose (axes at 0 or mid-range, errors 0): what a unit of ``error`` (internal
    units) does to the tool relative to the workpiece, as a displacement (length errors) or a
    rotation vector (angle errors), and the direction of travel of the axes (rows, unit)."""
    values = {s.name: 0.0 for s in machine.errors}
    values.update({s.name: s.to_internal(s.nominal) for s in machine.constants})
    values.update({s.name: s.to_internal(s.default_position) for s in machine.axes})
    h = 1e-6   # central differences: exact for a translation, 1e-12 relative for a small rotation
    plus, minus = dict(values), dict(values)
    plus[error], minus[error] = h, -h
    sym = machine.symbol(error)
    if sym.unit.kind == "angle":
        r0 = _orientation(machine, values)
        dr = (_orientation(machine, plus) - _orientation(machine, minus)) / (2 * h) @ r0.T
        g = np.array([dr[2, 1], dr[0, 2], dr[1, 0]])
    else:
        model = ExactModel(machine)
        g = (np.array(model.pose(plus)[0], float) - np.array(model.pose(minus)[0], float)) / (2 * h)
    model = ExactModel(machine)
    travel = []
    for a in machine.axes:
        p1, m1 = dict(values), dict(values)
        p1[a.name] += 1e-3 * a.unit.to_internal
        m1[a.name] -= 1e-3 * a.unit.to_internal
        u = np.array(model.pose(p1)[0], float) - np.array(model.pose(m1)[0], float)
        travel.append(u / (np.linalg.norm(u) or 1.0))
    return g, np.array(travel)


def channel(machine: Machine, error: str, axis: str) -> tuple[float, str]:
    """The sign of ``error`` in the machine file (+1: ISO 230-1's, the tool relative to the
    workpiece along or about +x, +y or +z) and what the laser measures of it on ``axis``."""
    g, travel = gain(machine, error)
    c = int(np.argmax(np.abs(g)))
    if not (abs(abs(g[c]) - 1) < 1e-6 and np.sum(np.abs(g)) - abs(g[c]) < 1e-6):
        raise ChaincompError(f"--error {error}: at the reference pose it moves the tool relative to the "
                             f"workpiece by {np.round(g, 6).tolist()} per unit, not along (or about) one of "
                             "x, y, z: no single laser channel measures it")
    a = machine.symbol(axis)
    u = travel[[s.name for s in machine.axes].index(axis)]
    along = a.unit.kind == "length" and abs(u[c]) > 0.99
    kind = machine.symbol(error).unit.kind
    what = {("length", True): "positioning", ("length", False): "straightness",
            ("angle", True): "roll", ("angle", False): "pitch/yaw"}.get((kind, along), kind)
    if a.unit.kind != "length":
        what = f"{kind} error over a rotary axis"
    return float(np.sign(g[c])), f"{what}, {'about' if kind == 'angle' else 'along'} {'xyz'[c]}"


def _num(v: float) -> str:
    text = f"{v:.10g}"
    return "0" if text == "-0" else text


def entry_lines(machine: Machine, error: str, axis: str, targets, values, unit: str, interpolation: str,
                outside: str, indent: str, comment: str) -> list[str]:
    sym = machine.symbol(error)
    return [f"{indent}# {one_line(comment)}",
            f"{indent}{error}:   # {one_line(sym.meaning)}" if sym.meaning else f"{indent}{error}:",
            f"{indent}  axis: {axis}",
            f"{indent}  units: [{machine.symbol(axis).unit.name}, {unit}]",
            f"{indent}  interpolation: {interpolation}",
            f"{indent}  outside: {outside}",
            f"{indent}  table:"] + [f"{indent}    - [{_num(p)}, {v:.4f}]" for p, v in zip(targets, values)]


def run(args) -> int:
    check_output(args.output, args.runs, args.machine, args.merge)
    machine = load(args.machine)
    try:
        sym = machine.symbol(args.error)
    except KeyError:
        raise ChaincompError(f"--error: {args.error!r} is not a symbol of {machine.name} (errors: "
                             f"{', '.join(s.name for s in machine.errors)})") from None
    if sym.role != "error":
        raise ChaincompError(f"--error: {args.error!r} is {'an' if sym.role == 'axis' else 'a'} {sym.role} of {machine.name}, not an error")
    axis = _axis_for(machine, args.error, args.axis)
    runs = read(args)
    a = machine.symbol(axis)
    if runs.position_unit.kind != a.unit.kind:
        raise ChaincompError(f"targets are in {runs.position_unit.name} but axis {axis} is declared in "
                             f"{a.unit.name}", args.runs)
    if runs.unit.kind != sym.unit.kind:
        raise ChaincompError(f"the deviations are in {runs.unit.name} ({runs.unit.kind}s) but {args.error} is "
                             f"declared in {sym.unit.name} ({'an' if sym.unit.kind == 'angle' else 'a'} {sym.unit.kind})", args.runs)
    if len(runs.targets) > MAX_TABLE_KNOTS:
        raise ChaincompError(f"{len(runs.targets)} targets: a table holds at most {MAX_TABLE_KNOTS} points",
                             args.runs)
    sign, what = channel(machine, args.error, axis)
    if sign < 0:
        print(f"chaincomp laser-to-params: warning: {machine.file}: {args.error} is written with the opposite "
              "sign of ISO 230-1 (a positive value moves the tool relative to the workpiece towards -x, -y or "
              "-z, or turns it negatively): the table holds the measured deviations negated, so that the model "
              "reproduces them", file=sys.stderr)
    ev = iso.evaluate(runs)
    field, described = _FIELD[args.direction]
    values = np.asarray(getattr(ev, field)) / sign
    targets = runs.targets * runs.position_unit.to_internal / a.unit.to_internal
    for k in range(1, len(targets)):   # the table's knots are written with _num's 10 digits
        if _num(targets[k]) == _num(targets[k - 1]):
            raise ChaincompError(f"target {float(runs.targets[k])!r} and {float(runs.targets[k - 1])!r} are one table position "
                                 f"({_num(targets[k])} {a.unit.name}) at 10 significant digits", args.runs,
                                 int(runs.lines[k]), "target")
    lo, hi = a.limits
    if targets[0] < lo or targets[-1] > hi:
        print(f"chaincomp laser-to-params: warning: targets [{targets[0]:g}, {targets[-1]:g}] {a.unit.name} reach "
              f"beyond axis {axis}'s limits [{lo:g}, {hi:g}]", file=sys.stderr)
    comment = (f"{args.error}: ISO 230-2 {described} of {len(runs.runs)} runs at {len(runs.targets)} targets from "
               f"{args.runs} ({what}; chaincomp laser-to-params)")

    def make_entry(indent: str) -> list[str]:
        return entry_lines(machine, args.error, axis, targets, values, runs.unit.name, args.interpolation,
                           args.outside, indent, comment)

    if args.merge:
        text = merge(args.merge, machine, args.error, make_entry)
    else:
        command = ["chaincomp", "laser-to-params", args.runs, "--machine", args.machine, "--error", args.error,
                   "--axis", axis, "--direction", args.direction, "-o", args.output]
        text = "\n".join([f"# Written by: {one_line(' '.join(shlex.quote(c) for c in command))}",
                          f"machine: {machine.name}",
                          f"description: laser calibration of {args.error} (chaincomp laser-to-params)",
                          "values:"] + make_entry("  ")) + "\n"
    _write_loadable(args.output, text, machine)
    print(f"laser-to-params: {args.error} over {axis}: {len(targets)} points ({what}, {runs.unit.name}) -> "
          f"{args.output}" + (f" (merged into a copy of {args.merge})" if args.merge else ""), file=sys.stderr)
    return 0
