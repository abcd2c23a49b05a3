"""``chaincomp eval``: tool point, direction and error at one set of axis values."""

from __future__ import annotations

from ..jets import JetModel
from ..numeric import ExactModel
from ..units import UNITS
from ..varying import check_inside, resolve, varying_errors
from .common import add_format_argument, add_machine_argument, add_values_arguments, check_finite, load, to_json, values_for


def add_parser(sub) -> None:
    p = sub.add_parser("eval", help="evaluate the tool point and its error at given axis values",
                       description="Evaluate the nominal tool point (and tool direction) at given axis "
                                   "values and, when error values are given, the tool-point error of "
                                   "the first-order, second-order and exact models. An error given as a "
                                   "table or polynomial over an axis takes its value at the axes given.")
    add_machine_argument(p)
    add_values_arguments(p)
    add_format_argument(p)
    p.set_defaults(run=run)


def evaluate(machine, values: dict, with_errors: bool) -> dict:
    scale = 1.0 / UNITS[machine.length_unit].to_internal
    exact = ExactModel(machine)
    nominal_values = {k: (0.0 if machine.symbol(k).role == "error" else v) for k, v in values.items()}
    point, direction = exact.pose(nominal_values)
    out = {
        "machine": machine.name,
        "units": {"length": machine.length_unit},
        "axes": {s.name: float(f"{s.from_internal(values[s.name]):.15g}") for s in machine.axes},
        "position": [float(v) * scale for v in point],
    }
    if direction is not None:
        out["direction"] = [float(v) for v in direction]
    varying = varying_errors(values)
    if varying:
        # errors that vary along an axis, at these axes, in their declared units
        at = resolve(values)
        out["varying"] = {k: {"value": float(f"{machine.symbol(k).from_internal(at[k]):.15g}"),
                              "unit": machine.symbol(k).unit.name, "axis": v.axis}
                          for k, v in varying.items()}
    if with_errors:
        model = JetModel(machine, 2)   # numerically through the chain: no symbolic expansion
        err, derr = {}, {}
        for name, (dp, dd) in (("first", model.error(values, 1)), ("second", model.error(values, 2)),
                               ("exact", exact.error(values))):
            err[name] = [float(v) * scale for v in dp]
            if dd is not None:
                derr[name] = [float(v) for v in dd]
        out["error"] = err
        if derr:
            out["direction_error"] = derr
    return out


def run(args) -> int:
    machine = load(args.machine)
    values, with_errors = values_for(machine, args.params, args.sets)
    check_inside(values)
    out = evaluate(machine, values, with_errors)
    check_finite(out)   # the table too: a NaN tool point is no answer
    print(to_json(out) if args.format == "json" else _text(out))
    return 0


def _text(out: dict) -> str:
    unit = out["units"]["length"]
    axes = ", ".join(f"{k} = {v:g}" for k, v in out["axes"].items())
    fmt = lambda v: "[" + ", ".join(f"{x:14.9f}" for x in v) + "]"  # noqa: E731
    lines = [f"{out['machine']} at {axes}", f"  tool point       {fmt(out['position'])} {unit}"]
    if "direction" in out:
        lines.append(f"  tool direction   {fmt(out['direction'])}")
    if "varying" in out:
        lines.append("  errors that vary along an axis, here: "
                     + ", ".join(f"{k} = {v['value']:.6g} {v['unit']}" for k, v in out["varying"].items()))
    for key, title, u in (("error", "tool point error", unit), ("direction_error", "direction error", "")):
        if key in out:
            lines.append(f"  {title} ({u or 'unit vector'}):")
            for name, v in out[key].items():
                lines.append(f"    {name:<12} {fmt(v)}")
    return "\n".join(lines)
