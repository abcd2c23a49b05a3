"""What ``identify`` reports about a fit: the text for people (``to_text``), the JSON with every
number in internal units (``to_json``) and the params file the fit writes (``params_yaml``)."""

from __future__ import annotations

import math

from ..escape import one_line
from ..model.display import DEFAULT_UNITS, display_unit, plus_minus, quantity
from ..model.units import INTERNAL, UNITS
from ..model.varying import Varying
from ..model.yamlsource import read_text
from ..symbolic.derive import COMPONENTS
from .identify import SHOWN, Fit, Param, Vary
from .table import count


def _shown(fit: Fit, p: Param, units: str) -> tuple[float, str]:
    """A parameter's display unit: its kind's (µm, arcsec, µm/m; or internal), per the axis'
    declared unit (internal: mm, rad) to the power for a polynomial coefficient."""
    vu = display_unit(p.kind, units)
    if not p.power:
        return vu.to_internal, vu.name
    au = fit.machine.symbol(p.axis).unit
    if units != "people":
        au = UNITS[INTERNAL[au.kind]]
    return vu.to_internal / au.to_internal ** p.power, f"{vu.name}/{au.name}" + (f"^{p.power}" if p.power > 1 else "")


def _internal_unit(p: Param, fit: Fit) -> str:
    """The internal unit of a parameter: mm, rad or 1, per mm^k or rad^k for a coefficient."""
    name = INTERNAL[p.kind]
    if not p.power:
        return name
    pos = INTERNAL[fit.machine.symbol(p.axis).unit.kind]
    return f"{name}/{pos}" + (f"^{p.power}" if p.power > 1 else "")


def _varying_json(fit: Fit, e: str, v: Vary) -> dict:
    """A varying error's parameters, internal units (named in ``units``, as in a params file)."""
    m = fit.machine
    a, s = m.symbol(v.axis), m.symbol(e)
    ps = [p for p in fit.params if p.error == e]
    units = [INTERNAL[a.unit.kind], INTERNAL[s.unit.kind]]
    out = {"axis": v.axis, "units": units, "parameters": [p.name for p in ps],
           "uncertainties": [fit.uncertainties.get(p.name) for p in ps], "outside": "hold"}
    vals = [fit.estimates.get(p.name) for p in ps]
    if v.kind == "table":
        return {"kind": "table", **out, "interpolation": "linear", "positions": list(v.knots), "values": vals}
    return {"kind": "polynomial", **out, "degree": v.degree, "coefficients": vals, "range": list(fit.ranges[e])}


def to_json(fit: Fit, source: str) -> dict:
    """Every value in internal units (mm, rad, 1), named beside it; None where not measured or
    not identified."""
    byname = {p.name: p for p in fit.params}
    constant = {n: {"value": v, "uncertainty": fit.uncertainties[n], "unit": _internal_unit(byname[n], fit)}
                for n, v in fit.estimates.items() if byname[n].error not in fit.varying}
    return {
        "machine": fit.machine.name, "measurements": source, "units": "internal (mm, rad, 1)",
        "setups": fit.setups, "observations": fit.observations,
        "measured": fit.measured, "fitted": fit.fitted, "assumed_zero": fit.assumed_zero,
        "estimates": {n: e for n, e in constant.items() if not _registration(fit, n)},
        "registration": {n: e for n, e in constant.items() if _registration(fit, n)},
        "varying": {e: _varying_json(fit, e, v) for e, v in fit.varying.items()},
        "parameters": len(fit.params), "minimal": fit.minimal,
        "redundant": {n: {"reason": why, "carried_by": fit.carried[n]} for n, why in fit.redundant.items()},
        "unidentifiable": fit.unidentifiable,
        "suggested_assume_zero": fit.suggested_zero, "rank": fit.rank,
        "condition_number": fit.condition,
        "correlations": [{"errors": [a, b], "value": c} for a, b, c in fit.correlations],
        "rms_residual": None if math.isnan(fit.rms) else fit.rms, "length_unit": "mm",
        "rms_direction_residual": None if math.isnan(fit.rms_direction) else fit.rms_direction,
        "direction_unit": "rad",
        "rms_orientation_residual": None if math.isnan(fit.rms_orientation) else fit.rms_orientation,
        "sigma": {c: {"value": v, "unit": "mm" if c in COMPONENTS else "rad"} for c, v in fit.sigma.items()},
        "chi2_per_dof": fit.chi2, "misfit": fit.misfit, "smooth": fit.smooth, "notes": fit.notes,
        "degrees_of_freedom": fit.dof, "iterations": fit.iterations, "converged": fit.converged,
        "loss": "squares" if fit.huber is None else {"huber": fit.huber},
        "outliers": [{"line": line, "column": c, "standardized_residual": u, "weight": wt}
                     for line, c, u, wt in fit.outliers],
    }


def _residuals(fit: Fit, units: str) -> str:
    """'rms residual 0.785 µm', or with directions '... 0.785 µm (tool point), 9.8 arcsec (tool
    direction)', with orientations '..., 9.8 arcsec (tool orientation, per component of ω)'."""
    point, direction = not math.isnan(fit.rms), not math.isnan(fit.rms_direction)
    orientation = not math.isnan(fit.rms_orientation)
    parts = ([quantity(fit.rms, "length", units) + (" (tool point)" if direction or orientation else "")]
             if point else []) \
        + ([quantity(fit.rms_direction, "angle", units) + " (tool direction)"] if direction else []) \
        + ([quantity(fit.rms_orientation, "angle", units) + " (tool orientation, per component of ω)"]
           if orientation else [])
    return "rms residual " + ", ".join(parts)


def to_text(fit: Fit, source: str, units: str = DEFAULT_UNITS) -> str:
    m = fit.machine
    what = count(len(fit.fitted), "error") + (f" as {len(fit.params)} parameters"
                                              if len(fit.params) != len(fit.fitted) else "")
    lines = [f"identify {m.name} from {source}: {fit.observations} coordinates "
             f"({', '.join(fit.measured)}) at {fit.setups} set-ups; {what} fitted"
             + (f" (the data see {fit.rank} independent combinations of them)"
                if fit.rank < len(fit.params) else "")
             + (f", assumed zero: {', '.join(fit.assumed_zero)}" if fit.assumed_zero else "")]
    for e, v in fit.varying.items():
        a = m.symbol(v.axis)
        if v.kind == "table":
            lines.append(f"{e} varies along {v.axis}: a table on {len(v.knots)} knots, linear between them, "
                         f"held beyond [{a.from_internal(v.knots[0]):g}, {a.from_internal(v.knots[-1]):g}] "
                         f"{a.unit.name}")
        else:
            lo, hi = fit.ranges[e]
            lines.append(f"{e} varies along {v.axis}: a polynomial of degree {v.degree} in {v.axis} "
                         f"({a.unit.name}) over the measured [{a.from_internal(lo):g}, {a.from_internal(hi):g}] "
                         f"{a.unit.name}, held beyond")
    if fit.smooth:
        lines.append(f"smoothing: {fit.smooth:g} x the squared second differences of the tables' knot values "
                     f"(declared unit) added to the weighted sum of squares")
    if fit.minimal:
        lines.append(f"minimal set: {len(fit.estimates)} of {len(fit.params)} parameters fitted (chosen by QR "
                     f"with column pivoting), {len(fit.redundant) + len(fit.unidentifiable)} held at zero")
    if fit.sigma:
        groups: dict[str, list[str]] = {}
        for c, v in fit.sigma.items():
            u = display_unit("length" if c in COMPONENTS else "angle", units)
            groups.setdefault(f"{v / u.to_internal:.4g} {u.name}", []).append(c)
        given = ", ".join(f"{', '.join(cs)} {v}" for v, cs in groups.items())
        weights = f"; sigma {given}; chi2/dof {fit.chi2:.3g}"
    else:
        weights = ""
    lines.append(f"{'converged' if fit.converged else 'NOT converged'} after {fit.iterations} Gauss-Newton "
                 f"iterations on the exact model; {_residuals(fit, units)}; {fit.dof:.4g} degrees of freedom"
                 + weights)
    width = max([12] + [len(n) for n in fit.estimates])
    lines.append(f"  {'parameter':<{width}}  estimate ± standard uncertainty")
    byname = {p.name: p for p in fit.params}
    registration = [n for n in fit.estimates if _registration(fit, n)]
    for n, v in fit.estimates.items():
        f, unit = _shown(fit, byname[n], units)
        if n not in registration:
            lines.append(f"  {n:<{width}}  {plus_minus(v / f, fit.uncertainties[n] / f)} {unit}")
    if registration:
        lines.append("registration (the base in the measuring instrument's frame: not a machine error, identified "
                     "with the errors, written to the params as zero):")
        for n in registration:
            f, unit = _shown(fit, byname[n], units)
            lines.append(f"  {n:<{width}}  {plus_minus(fit.estimates[n] / f, fit.uncertainties[n] / f)} {unit}")
    lines.append(f"condition number {fit.condition:.4g} (Jacobian columns scaled to unit norm)")
    lines.append("correlations above 0.9: " + (", ".join(f"{a}/{b} {c:+.3f}" for a, b, c in fit.correlations)
                                                 or "none"))
    if fit.redundant:
        lines.append("held at zero, not in the minimal set (each carried by the fitted ones):")
        lines += [f"  {n}: {why}" for n, why in fit.redundant.items()]
    if fit.unidentifiable:
        lines.append("not identifiable from these set-ups ("
                     + ("held at zero):" if fit.minimal else "no value given):"))
        lines += [f"  {n}: {why}" for n, why in fit.unidentifiable.items()]
    if fit.suggested_zero:
        constants = [n for n in fit.suggested_zero if n in fit.fitted and n not in fit.varying]
        lines.append("to give every other parameter a value, fit a minimal set (--minimal)"
                     + (f", or assume these zero as well (one choice of many): --assume-zero "
                        + ",".join(fit.assumed_zero + constants) if len(constants) == len(fit.suggested_zero) else ""))
    if fit.huber is not None:
        lines.append(_outliers(fit))
    lines += [f"note: {note}" for note in fit.notes]
    return "\n".join(lines)


def _outliers(fit: Fit) -> str:
    """'Huber loss (k = 1.345): 3 of 150 coordinates down-weighted: line 14 y -41.2 sigma (weight 0.033), ...'."""
    head = f"Huber loss (k = {fit.huber:g}): {len(fit.outliers)} of {fit.observations} " \
           f"coordinates down-weighted (weight below 1; residuals in standard uncertainties)"
    shown = [f"line {line} {c} {u:+.3g} sigma (weight {wt:.3g})" for line, c, u, wt in fit.outliers[:SHOWN]]
    more = len(fit.outliers) - SHOWN
    return head + (": " + ", ".join(shown) + (f" and {more} more (JSON has them all)" if more > 0 else "")
                   if shown else "")


def _num(v: float) -> str:
    text = f"{v:.12g}"
    return "0" if text == "-0" else text


def _registration(fit: Fit, name: str) -> bool:
    """A parameter of an error marked registration (the base block: the instrument's frame)."""
    return fit.machine.symbol(name).registration if name in fit.fitted else False


def params_yaml(fit: Fit, source: str, held: dict | None = None) -> str:
    """A params file (machine + values as 'VALUE UNIT', tables and polynomials in the params
    format) that load_params and chaincompd read; ``held``: the values the fit held (--hold, by
    name, internal units or a table along an axis), written as they were given."""
    m = fit.machine
    held = held or {}
    out = [f"# Error values identified by chaincomp identify from {one_line(source)}:",
           f"# {fit.observations} coordinates at {fit.setups} set-ups, {_residuals(fit, 'internal')}, "
           f"condition number {fit.condition:.4g}."]
    if fit.huber is not None:
        out.append(f"# Huber loss (k = {fit.huber:g}): {len(fit.outliers)} of {fit.observations} coordinates "
                   "down-weighted (identify's report lists them).")
    if fit.minimal:
        out.append(f"# Minimal identifiable set: {len(fit.estimates)} of {len(fit.params)} parameters fitted; "
                   f"every other one is written as zero (held at zero in the fit).")
    elif fit.unidentifiable:
        out.append(f"# Not identifiable, no value given: {', '.join(fit.unidentifiable)}.")
    out += [f"machine: {m.name}", "values:"]
    params = {p.name: p for p in fit.params}

    def note(name):
        if name in fit.estimates:
            return f"standard uncertainty {fit.uncertainties[name] / params[name].to_internal:.3g} " \
                   f"{params[name].unit}"
        if name in fit.redundant:
            return "held at zero: redundant, carried by " + ", ".join(fit.carried[name])
        return "held at zero: moves no measured coordinate"

    for s in m.errors:
        if s.name in held:
            out += _held_entry(s, held[s.name])
        elif s.name in fit.varying:
            v = fit.varying[s.name]
            ps = [p for p in fit.params if p.error == s.name]
            if not fit.minimal and any(p.name in fit.unidentifiable for p in ps):
                out.append(f"  # {s.name}: not written, not identifiable: "
                           + ", ".join(p.name for p in ps if p.name in fit.unidentifiable))
                continue
            a = m.symbol(v.axis)
            val = [fit.estimates.get(p.name, 0.0) / p.to_internal for p in ps]
            out += [f"  {s.name}:   # identified as a {'table' if v.kind == 'table' else 'polynomial'} along {v.axis}",
                    f"    axis: {v.axis}", f"    units: [{a.unit.name}, {s.unit.name}]"]
            if v.kind == "table":
                out += ["    interpolation: linear", "    outside: hold", "    table:"]
                out += [f"      - [{_num(a.from_internal(k))}, {_num(x)}]   # {note(p.name)}"
                        for k, x, p in zip(v.knots, val, ps)]
            else:
                lo, hi = fit.ranges[s.name]
                out.append(f"    polynomial: [{', '.join(_num(x) for x in val)}]")
                out += [f"    # {p.name}: {note(p.name)}" for p in ps]
                out += [f"    range: [{_num(a.from_internal(lo))}, {_num(a.from_internal(hi))}]", "    outside: hold"]
        elif s.name in fit.estimates and s.registration:   # the instrument's frame: never compensated
            out.append(f'  {s.name}: "0 {s.unit.name}"   # registration, not a machine error: identified '
                       f'{_num(s.from_internal(fit.estimates[s.name]))} {s.unit.name}, {note(s.name)}')
        elif s.name in fit.estimates:
            out.append(f'  {s.name}: "{_num(s.from_internal(fit.estimates[s.name]))} {s.unit.name}"   # {note(s.name)}')
        elif s.name in fit.assumed_zero:
            out.append(f'  {s.name}: "0 {s.unit.name}"   # assumed zero')
        elif fit.minimal:
            out.append(f'  {s.name}: "0 {s.unit.name}"   # {note(s.name)}')
    return "\n".join(out) + "\n"


def _held_entry(s, value) -> list[str]:
    """A held error's lines: a number as 'VALUE UNIT', a table or polynomial as the lines of its
    entry in the params file it was read from."""
    if not isinstance(value, Varying):
        return [f'  {s.name}: "{_num(s.from_internal(value))} {s.unit.name}"   # held at a given value (--hold)']
    lines = read_text(value.file).splitlines()
    first = lines[value.line - 1]
    indent = len(first) - len(first.lstrip())
    block = [first]
    for line in lines[value.line:]:
        if line.strip() and not line.lstrip().startswith("#") and len(line) - len(line.lstrip()) <= indent:
            break
        block.append(line)
    return [f"  # {s.name}: held as given in {one_line(value.file)} (--hold)"] + \
        ["  " + line[indent:] for line in block if line.strip()]
