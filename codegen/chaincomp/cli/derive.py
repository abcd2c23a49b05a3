"""``chaincomp derive``: nominal pose, error model, error gain matrix and Jacobians."""

from __future__ import annotations

import sympy as sp

from ..escape import one_line
from ..model.machine import Rotation
from ..symbolic.derive import COMPONENTS, EXPANDED_TERMS_LIMIT, Derivation, Progress, derive
from ..symbolic.orientation import ROWS as ORIENTATION_ROWS
from ..symbolic.polyprint import RingPrinter, shown_collected, shown_plain, shown_sympy
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


def _short(d: Derivation) -> bool:
    return sum(d.term_count(s, k) for s in d.point + (d.direction or []) for k in range(1, d.order + 1)) \
        <= EXPANDED_TERMS_LIMIT


def _simplifier(d: Derivation):
    short = _short(d)
    return lambda e: sp.trigsimp(e) if short and sp.count_ops(e) <= TRIGSIMP_MAX_OPS else e


def _ring(d: Derivation):
    for vec in (d.point, d.direction or [], d.reference or [], d.orientation or []):
        for s in vec:
            for c in s.values():
                return c.ring
    return None


def report(d: Derivation, progress: bool = False) -> dict:
    """Every derived formula, keyed like the JSON output: each a polyprint.Shown (its text,
    its LaTeX), printed on demand straight from the derivation's series (chaincomp.polyprint)
    as sympy would print the collected expressions. Machines whose atoms polyprint does not
    take build the sympy expressions instead (_report_sympy). Progress on stderr once it
    takes over a second."""
    ring = _ring(d)
    pr = RingPrinter(ring, d._restore, d.small) if ring is not None else None
    if pr is None or not pr.supported:
        return _report_sympy(d, progress)
    m = d.machine
    prog = Progress(f"derive {m.name}: formulas", progress)
    names = [s.name for s in m.errors]
    short = _short(d)

    def trig_simplified(terms, build):
        """The orientation's formulas as before: trigsimp where the chain is short and the
        formula takes at most TRIGSIMP_MAX_OPS operations (a sum of n terms takes n - 1 at
        least, so the long ones are never built as sympy expressions)."""
        if short and terms and pr.op_lower_bound(terms) <= TRIGSIMP_MAX_OPS:
            e = build()
            if sp.count_ops(e) <= TRIGSIMP_MAX_OPS:
                return sp.trigsimp(e)
        return None

    def jacobian(s: dict) -> dict:
        terms = pr.terms(s[()]) if () in s else []
        out = {}
        for a in m.axes:
            dt = pr.derivative(terms, a.sym)
            out[a.name] = shown_sympy(sp.diff(d.nominal(s), a.sym)) if dt is None else shown_plain(pr, dt)
        return out

    def plain(s: dict):
        return shown_plain(pr, pr.terms(s[()]) if () in s else [])

    out: dict = {"nominal": {}, "direction": {}, "reference": {}, "error": {}, "direction_error": {},
                 "orientation_error": {}, "gain": {}, "jacobian": {}}
    for i, c in enumerate(COMPONENTS):
        prog.step(f"{c} ({i + 1}/{len(COMPONENTS)})")
        out["nominal"][c] = plain(d.point[i])
        for k in range(1, d.order + 1):
            out["error"].setdefault(f"order{k}", {})[f"d{c}"] = shown_collected(pr, pr.series_terms(d.point[i], k))
        out["jacobian"][c] = jacobian(d.point[i])
        if d.direction is not None:
            out["direction"][f"k{c}"] = plain(d.direction[i])
            for k in range(1, d.order + 1):
                out["direction_error"].setdefault(f"order{k}", {})[f"dk{c}"] = shown_collected(
                    pr, pr.series_terms(d.direction[i], k))
        if d.orientation is not None:
            out["reference"][f"x{c}"] = plain(d.reference[i])
            for k in range(1, d.order + 1):
                w, terms = d.orientation[i], pr.series_terms(d.orientation[i], k)
                simple = trig_simplified(terms, lambda: d.degree_part(w, k))
                out["orientation_error"].setdefault(f"order{k}", {})[f"w{c}"] = (
                    shown_collected(pr, terms) if simple is None else shown_sympy(_collect(simple, d.small)))
    prog.step("error gain matrix")
    rows = {f"d{c}": s for c, s in zip(COMPONENTS, d.point)}
    if d.direction is not None:
        rows.update({f"dk{c}": s for c, s in zip(COMPONENTS, d.direction)})
    if d.orientation is not None:
        rows.update(dict(zip(ORIENTATION_ROWS, d.orientation)))
    for comp, s in rows.items():
        row = {}
        for j, name in enumerate(names):
            c = s.get((j,))
            terms = pr.terms(c) if c else []
            simple = trig_simplified(terms, lambda: d.expr(c)) if comp.startswith("w") else None
            row[name] = shown_plain(pr, terms) if simple is None else shown_sympy(simple)
        out["gain"][comp] = row
    prog.done()
    return {k: v for k, v in out.items() if v}


def _report_sympy(d: Derivation, progress: bool = False) -> dict:
    """report() through sympy expressions: collect(expand(...)) of each formula."""
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
    return _walk({k: v for k, v in out.items() if v}, shown_sympy)


def _walk(obj, fn):
    if isinstance(obj, dict):
        return {k: _walk(v, fn) for k, v in obj.items()}
    return fn(obj)


def run(args) -> int:
    machine = load(args.machine)
    prog = Progress(f"derive {machine.name}", True)
    d = derive(machine, args.order, progress=True)
    rep = report(d, progress=True)
    prog.step(f"printing {args.format}")   # the formulas are printed on demand, here
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
    prog.done()
    return 0


_TITLES = {"nominal": "Nominal tool point", "direction": "Nominal tool direction",
           "reference": "Nominal x axis of the tool frame",
           "gain": "Error gain matrix (first order): coefficient of each error in each component",
           "jacobian": "Jacobian of the nominal tool point with respect to the axes"}


_ERROR_TITLES = {"error": "Tool point error", "direction_error": "Tool direction error",
                 "orientation_error": "Tool frame orientation error ω (rad; R_actual = exp([ω]×)·R_nominal, "
                                      "about the base frame's axes)"}


def _text(machine, d: Derivation, rep: dict) -> str:
    lines = [f"Machine {machine.name} ({one_line(machine.file)}): {len(machine.axes)} axes, "
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
                lines += [f"  {comp} / {n}: {e}" for n, e in v.items() if not e.is_zero]
            else:
                lines.append(f"  {comp} = {v}")
        lines.append("")
    return "\n".join(lines).rstrip()


def _latex(machine, rep: dict) -> str:
    out = [f"% chaincomp derive {one_line(machine.file)}", r"\begin{align*}"]
    for key, value in rep.items():
        for comp, v in value.items():
            if isinstance(v, dict):
                for n, e in v.items():
                    if not e.is_zero:
                        out.append(rf"\text{{{key} {comp}}}/{sp.latex(sp.Symbol(n))} &= {e.latex()} \\")
            else:
                out.append(rf"\text{{{key}}}\ {comp} &= {v.latex()} \\")
    out.append(r"\end{align*}")
    return "\n".join(out)
