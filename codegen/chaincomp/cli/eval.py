"""``chaincomp eval``: tool point, direction and error at one set of axis values."""

from __future__ import annotations

import numpy as np

from ..errors import ChaincompError
from ..model.display import add_units_argument, convert, display_unit, fixed
from ..model.expressions import MAX_LITERAL
from ..model.units import UNITS
from ..model.varying import check_inside, resolve, varying_errors
from ..symbolic.jets import JetModel
from ..symbolic.numeric import ExactModel
from ..symbolic.orientation import angle_between
from .common import (add_format_argument, add_machine_argument, add_values_arguments, check_finite, load, to_json,
                     values_for)


def add_parser(sub) -> None:
    p = sub.add_parser("eval", help="evaluate the tool point and its error at given axis values",
                       description="Evaluate the nominal tool point (and tool direction) at given axis "
                                   "values and, when error values are given, the tool-point error of "
                                   "the first-order, second-order and exact models. An error given as a "
                                   "table or polynomial over an axis takes its value at the axes given. "
                                   "Text shows the errors in µm and arcsec (--units internal: mm and "
                                   "rad); the direction error as the tilt of the tool axis towards x, y "
                                   "and z and the angle between the actual and nominal axes; with a tool "
                                   "frame its orientation error as a rotation vector about the base "
                                   "frame's axes (R_actual = exp([w]x)·R_nominal). JSON is in "
                                   "the machine's length unit and rad, named under 'units'.")
    add_machine_argument(p)
    add_values_arguments(p)
    add_format_argument(p)
    add_units_argument(p)
    p.set_defaults(run=run)


def evaluate(machine, values: dict, with_errors: bool) -> dict:
    scale = 1.0 / UNITS[machine.length_unit].to_internal
    exact = ExactModel(machine)
    nominal_values = {k: (0.0 if machine.symbol(k).role == "error" else v) for k, v in values.items()}
    point, direction, reference = exact.frame(nominal_values)
    out = {
        "machine": machine.name,
        # direction: unit vectors and their differences (small ones are tilts in rad)
        "units": {"length": machine.length_unit, "direction": "1", "angle": "rad"},
        "axes": {s.name: float(f"{s.from_internal(values[s.name]):.15g}") for s in machine.axes},
        "position": [float(v) * scale for v in point],
    }
    if direction is not None:
        out["direction"] = [float(v) for v in direction]
    if reference is not None:
        out["frame_x"] = [float(v) for v in reference]   # the tool frame's x axis
    varying = varying_errors(values)
    if varying:
        # errors that vary along an axis, at these axes, in their declared units
        at = resolve(values)
        out["varying"] = {k: {"value": float(f"{machine.symbol(k).from_internal(at[k]):.15g}"),
                              "unit": machine.symbol(k).unit.name, "axis": v.axis}
                          for k, v in varying.items()}
    if with_errors:
        # numerically through the chain, no symbolic expansion; one pass for both orders
        truncated = JetModel(machine, 2).errors_by_order(values, (1, 2))
        err, derr = {}, {}
        for name, (dp, dd) in (("first", truncated[1][:2]), ("second", truncated[2][:2]),
                               ("exact", exact.error(values))):
            err[name] = [float(v) * scale for v in dp]
            if dd is not None:
                derr[name] = [float(v) for v in dd]
        out["error"] = err
        if derr:
            out["direction_error"] = derr
            n = np.asarray(direction, float)
            out["direction_angle"] = {name: float(angle_between(n, n + np.asarray(d, float)))
                                      for name, d in derr.items()}
        if reference is not None:
            # the rotation vector ω (rad): R_actual = exp([ω]×)·R_nominal, about the base frame's axes
            out["orientation_error"] = {name: [float(v) for v in w] for name, w in (
                ("first", truncated[1][2]), ("second", truncated[2][2]), ("exact", exact.orientation_error(values)))}
    return out


def check_varying_bound(machine, values: dict) -> None:
    """An error given as a table or polynomial, at these axes, within the bound of every value
    (1e15 mm or rad): a polynomial's coefficients may each be in bounds and its value not."""
    at = resolve(values)
    for name, v in varying_errors(values).items():
        if not abs(float(at[name])) <= MAX_LITERAL:
            s, axis = machine.symbol(name), machine.symbol(v.axis)
            raise ChaincompError(f"{name} = {s.from_internal(float(at[name])):.6g} {s.unit.name} at {v.axis} = "
                                 f"{axis.from_internal(values[v.axis]):g} {axis.unit.name}: beyond "
                                 f"{MAX_LITERAL:g} (mm, rad) in magnitude", v.file, v.line, v.key)


def run(args) -> int:
    if args.params is not None and not args.params.strip():
        raise ChaincompError("--params: an empty value (leave the option out for no error values)")
    machine = load(args.machine)
    values, with_errors = values_for(machine, args.params, args.sets)
    check_inside(values)
    check_varying_bound(machine, values)
    out = evaluate(machine, values, with_errors)
    check_finite(out)   # the table too: a NaN tool point is no answer
    print(to_json(out) if args.format == "json" else _text(out, args.units))
    return 0


def _text(out: dict, units: str = "people") -> str:
    """The errors in µm and arcsec (units "people") or mm and rad with 9 decimals ("internal")."""
    unit = out["units"]["length"]
    to_mm = UNITS[unit].to_internal
    axes = ", ".join(f"{k} = {v:g}" for k, v in out["axes"].items())
    vec = lambda v, w, d: "[" + ", ".join(fixed(x, d, w) for x in v) + "]"  # noqa: E731
    lines = [f"{out['machine']} at {axes}", f"  tool point       {vec(out['position'], 14, 9)} {unit}"]
    if "direction" in out:
        lines.append(f"  tool direction   {vec(out['direction'], 14, 9)}")
    if "frame_x" in out:
        lines.append(f"  tool frame x     {vec(out['frame_x'], 14, 9)}")
    if "varying" in out:
        lines.append("  errors that vary along an axis, here: "
                     + ", ".join(f"{k} = {v['value']:.6g} {v['unit']}" for k, v in out["varying"].items()))
    width, digits = (14, 9) if units == "internal" else (10, 3)
    if "error" in out:
        lines.append(f"  tool point error ({display_unit('length', units).name}): dx, dy, dz")
        for name, v in out["error"].items():
            lines.append(f"    {name:<12} {vec(convert(np.asarray(v) * to_mm, 'length', units)[0], width, digits)}")
    if "direction_error" in out:
        lines.append(f"  tool direction error ({display_unit('angle', units).name}): tilt towards x, y, z; "
                     "angle between actual and nominal axis")
        for name, v in out["direction_error"].items():
            tilt = convert(np.asarray(v), "angle", units)[0]
            angle = convert(out["direction_angle"][name], "angle", units)[0]
            lines.append(f"    {name:<12} {vec(tilt, width, digits)}   angle {fixed(angle, digits, width)}")
    if "orientation_error" in out:
        lines.append(f"  tool frame orientation error ({display_unit('angle', units).name}): rotation vector "
                     "wx, wy, wz about the base frame's axes; its angle")
        for name, v in out["orientation_error"].items():
            w = convert(np.asarray(v), "angle", units)[0]
            angle = convert(float(np.linalg.norm(v)), "angle", units)[0]
            lines.append(f"    {name:<12} {vec(w, width, digits)}   angle {fixed(angle, digits, width)}")
    return "\n".join(lines)
