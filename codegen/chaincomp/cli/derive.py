"""``chaincomp derive``: nominal pose, error model, error gain matrix and Jacobians."""

from __future__ import annotations

import sympy as sp

from ..derive import COMPONENTS, EXPANDED_TERMS_LIMIT, Derivation, Progress, derive
from ..machine import Rotation
from .common import add_format_argument, add_machine_argument, add_order_argument, load, to_json


def add_parser(sub) -> None:
    p = sub.add_parser("derive", help="derive the nominal pose and the order-k error model",
                       description="Derive, by multiplying truncated series in the error symbols, the "
                                   "nominal tool point and direction, the error model to the given order, "
                                   "the first-order error gain matrix and the Jacobian of the tool point "
                                   "with respect to the axes. With a tool frame also its orientation "
                                   "error as a rotation vector (wx, wy, wz: rad about the base frame's "
                                   "axes, R_actual = exp([w]x)·R_nominal) and its rows of the gain matrix.")
    add_machine_argument(p)
    add_order_argument(p, 1)
    add_format_argument(p, ("text", "latex", "json"))
    p.set_defaults(run=run)


def chain_text(machine) -> str:
    parts = []
    for el in machine.chain:
        if isinstance(el, Rotation):
            parts.append(f"R{el.axis}({el.angle})")
        else:
            parts.append("T(" + ", ".join(str(v) for v in el.vector) + ")")
    return " · ".join(parts)


def _collect(expr: sp.Expr, small: list[sp.Symbol]) -> sp.Expr:
    return sp.collect(sp.expand(expr), small) if small else expr


# The rotation vector's terms carry cos² + sin² from R·R₀ᵀ: trigsimp removes them on a short
# chain (the expansion limit of generate), in terms of at most this many operations; on an arm
# it takes seconds per term (a UR5: minutes in all), and they are printed as derived.
TRIGSIMP_MAX_OPS = 150


def _simplifier(d: Derivation):
    short = sum(d.term_count(s, k) for s in d.point + (d.direction or []) for k in range(1, d.order + 1)) \
        <= EXPANDED_TERMS_LIMIT
    return lambda e: sp.trigsimp(e) if short and sp.count_ops(e) <= TRIGSIMP_MAX_OPS else e


def report(d: Derivation, progress: bool = False) -> dict:
    """Every derived formula, as sympy expressions, keyed like the JSON output. Collecting the
    terms takes most of a high order's time (30 s at order 4 on five_axis_ac): progress on
    stderr once it takes over a second."""
    m = d.machine
    prog = Progress(f"derive {m.name}: formulas", progress)
    names = [s.name for s in m.errors]
    _trig_simplified = _simplifier(d)
    out: dict = {"nominal": {}, "direction": {}, "reference": {}, "error": {}, "direction_error": {},
                 "orientation_error": {}, "gain": {}, "jacobian": {}}
    for i, c in enumerate(COMPONENTS):
        prog.step(f"{c} ({i + 1}/{len(COMPONENTS)})")
        out["nominal"][c] = d.nominal(d.point[i])
        for k in range(1, d.order + 1):
            out["error"].setdefault(f"order{k}", {})[f"d{c}"] = _collect(d.degree_part(d.point[i], k), d.small)
        out["jacobian"][c] = {a.name: sp.diff(out["nominal"][c], a.sym) for a in m.axes}
        if d.direction is not None:
            out["direction"][f"k{c}"] = d.nominal(d.direction[i])
            for k in range(1, d.order + 1):
                out["direction_error"].setdefault(f"order{k}", {})[f"dk{c}"] = _collect(
                    d.degree_part(d.direction[i], k), d.small)
        if d.orientation is not None:
            out["reference"][f"x{c}"] = d.nominal(d.reference[i])
            for k in range(1, d.order + 1):
                out["orientation_error"].setdefault(f"order{k}", {})[f"w{c}"] = _collect(
                    _trig_simplified(d.degree_part(d.orientation[i], k)), d.small)
    prog.step("error gain matrix")
    for comp, row in d.gain_matrix().items():
        if comp.startswith("w"):
            row = [_trig_simplified(e) for e in row]
        out["gain"][comp] = dict(zip(names, row))
    prog.done()
    return {k: v for k, v in out.items() if v}


def _walk(obj, fn):
    if isinstance(obj, dict):
        return {k: _walk(v, fn) for k, v in obj.items()}
    return fn(obj)


def run(args) -> int:
    machine = load(args.machine)
    d = derive(machine, args.order, progress=True)
    rep = report(d, progress=True)
    if args.format == "json":
        doc = {"machine": machine.name, "file": machine.file, "order": d.order,
               "symbols": [{"name": s.name, "role": s.role, "unit": s.unit.name, "meaning": s.meaning}
                           for s in machine.symbols],
               "chain": chain_text(machine),
               "units": {"internal": "mm and rad: every symbol enters the formulas in internal units"}}
        doc.update(_walk(rep, str))
        print(to_json(doc))
    elif args.format == "latex":
        print(_latex(machine, rep))
    else:
        print(_text(machine, d, rep))
    return 0


_TITLES = {"nominal": "Nominal tool point", "direction": "Nominal tool direction",
           "reference": "Nominal x axis of the tool frame",
           "gain": "Error gain matrix (first order): coefficient of each error in each component",
           "jacobian": "Jacobian of the nominal tool point with respect to the axes"}


_ERROR_TITLES = {"error": "Tool point error", "direction_error": "Tool direction error",
                 "orientation_error": "Tool frame orientation error ω (rad; R_actual = exp([ω]×)·R_nominal, "
                                      "about the base frame's axes)"}


def _text(machine, d: Derivation, rep: dict) -> str:
    lines = [f"Machine {machine.name} ({machine.file}): {len(machine.axes)} axes, "
             f"{len(machine.constants)} constants, {len(machine.errors)} errors; order {d.order}",
             "Formulas take every symbol in internal units (mm, rad).", "",
             "Chain (rotations right-handed, senses applied):", "  X = " + chain_text(machine) + " · X0", ""]
    for key, value in rep.items():
        if key in _ERROR_TITLES:
            for order, comps in value.items():
                lines.append(f"{_ERROR_TITLES[key]}, terms of degree {order[5:]} in the errors")
                lines += [f"  {c} = {e}" for c, e in comps.items()] + [""]
            continue
        lines.append(_TITLES[key])
        for comp, v in value.items():
            if isinstance(v, dict):
                lines += [f"  {comp} / {n}: {e}" for n, e in v.items() if e != 0]
            else:
                lines.append(f"  {comp} = {v}")
        lines.append("")
    return "\n".join(lines).rstrip()


def _latex(machine, rep: dict) -> str:
    out = [f"% chaincomp derive {machine.file}", r"\begin{align*}"]
    for key, value in rep.items():
        for comp, v in value.items():
            if isinstance(v, dict):
                for n, e in v.items():
                    if e != 0:
                        out.append(rf"\text{{{key} {comp}}}/{sp.latex(sp.Symbol(n))} &= {sp.latex(e)} \\")
            else:
                out.append(rf"\text{{{key}}}\ {comp} &= {sp.latex(v)} \\")
    out.append(r"\end{align*}")
    return "\n".join(out)
