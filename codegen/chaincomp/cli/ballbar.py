"""``chaincomp ballbar``: the ISO 230-4 circular test — the trace a machine's errors give, its
G and F, a polar plot, and the fit of the errors a measured trace shows."""

from __future__ import annotations

import math
import os
import shlex
import sys

import numpy as np

from ..errors import ChaincompError
from ..escape import one_line
from ..measure import ballbar as bb
from ..measure.calibration import _write_loadable
from ..measure.protocol import check_errors
from ..model.display import fixed, plus_minus
from ..model.expressions import MAX_LITERAL
from ..model.params_merge import merge
from ..model.varying import Varying
from ..symbolic.jets import JetModel
from ..symbolic.numeric import ExactModel
from .common import (add_assume_zero_argument, add_format_argument, add_machine_argument, add_values_arguments,
                     _same_file, check_image, check_output, integer, load, names, number, refuse_empty, to_json,
                     values_for)
from .figures import save, use_agg

UM = bb.UM


def add_parser(sub) -> None:
    p = sub.add_parser("ballbar", help="ISO 230-4 circular test: predict a ballbar trace, or fit errors to one",
                       description="Predict the trace of a circular test (ISO 230-4, a ballbar) from the machine "
                                   "and its error values: the axes move the nominal tool point on a circle in the "
                                   "plane, both directions; the ballbar, its centre pivot fixed on the workpiece "
                                   "side at the nominal centre, measures the actual tool point's distance. Reports "
                                   "the circular deviation G (radial range about the least-squares circle's "
                                   "centre), the radial deviation F (max and min of the deviation from R) and the "
                                   "least-squares circle, per direction and bidirectional. With --fit, reads a "
                                   "measured trace and fits the errors it shows by linear least squares on the "
                                   "model's gains.")
    add_machine_argument(p)
    add_values_arguments(p)
    p.add_argument("--plane", type=str.upper, choices=tuple(bb.PLANES),
                   help="plane of the circle (required without --fit); the angle turns from the first "
                        "coordinate towards the second")
    p.add_argument("--radius", type=number(0, above=True), metavar="R",
                   help="radius of the circle (the ballbar's length) in the machine's length unit "
                        "(required without --fit)")
    p.add_argument("--centre", "--center", metavar="x=..,y=..,z=..",
                   help="the centre pivot in the workpiece frame (machine's length unit), any of x, y, z "
                        "(default: the tool point with the axes at 0 or mid-range, or as --set: '--set Z=-200' "
                        "also places the centre of a circle that Z drives)")
    p.add_argument("--axes", metavar="A,B", help="the two axes that drive the circle, when more than one axis "
                   "moves the tool along a direction of the plane (default: found from the model)")
    p.add_argument("--points", type=integer(bb.MIN_POINTS, bb.MAX_POINTS), default=360, metavar="N",
                   help=f"points per direction, equally spaced in angle ({bb.MIN_POINTS} to {bb.MAX_POINTS}, "
                        "default 360)")
    p.add_argument("--feed", type=number(0, above=True), metavar="F",
                   help="feed in mm/min, recorded in the trace and report (the model is quasi-static: the "
                        "feed changes nothing in the prediction)")
    p.add_argument("--fit", metavar="TRACE.csv", help="a measured trace to fit errors to (the format -o writes); "
                   "--params then gives the start values")
    p.add_argument("--degree", type=integer(0, 2), default=1,
                   help="with --fit: highest power of a plane axis fitted in its slide's positioning and "
                        "straightness errors (0 constants only; 1, default, adds scale errors and straightness "
                        "slopes; 2 the bows too)")
    add_assume_zero_argument(p, "with --fit: errors not fitted (held at their start values)")
    p.add_argument("--prefer", action="append", default=[], metavar="E1,E2",
                   help="with --fit: errors to fit first, in this order, where several move the trace alike "
                        "(by default the centre, then errors outside the slides' error blocks such as "
                        "squareness, then the slides' errors, then their powers of the axes); names separated "
                        "by commas (repeatable)")
    add_format_argument(p, what="report format")
    p.add_argument("--plot", metavar="OUT.png", help="draw the polar plot: deviation magnified, both "
                   "directions, the nominal circle, a scale in µm per division")
    p.add_argument("-o", "--output", metavar="FILE", help="write the predicted trace (TRACE.csv), or with "
                   "--fit the fitted params file (P.yaml)")
    p.set_defaults(run=run)


def _centre(text: str | None, machine, default: np.ndarray) -> np.ndarray:
    out = default.copy()
    if not text:
        return out
    k = bb.U.UNITS[machine.length_unit].to_internal
    seen = set()
    for item in text.split(","):
        name, sep, value = item.partition("=")
        c = name.strip().lower()
        if not sep or c not in ("x", "y", "z"):
            raise ChaincompError(f"--centre: expected x=VALUE,y=VALUE,z=VALUE (any of them), got {item.strip()!r}")
        if c in seen:
            raise ChaincompError(f"--centre: {c} given twice")
        seen.add(c)
        try:
            v = number()(value)
        except Exception as exc:   # argparse.ArgumentTypeError: its text is the reason
            raise ChaincompError(f"--centre {c}: {exc}") from None
        out["xyz".index(c)] = _to_mm(f"--centre {c}", v, machine)
    return out


def _to_mm(option: str, value: float, machine) -> float:
    """A length option in the machine's length unit, in mm: within the bound of every value (1e308
    in would be inf mm)."""
    unit = bb.U.UNITS[machine.length_unit]
    if not abs(value * unit.to_internal) <= MAX_LITERAL:
        raise ChaincompError(f"{option}: {value:g} {unit.name} is larger than {MAX_LITERAL:g} mm in magnitude")
    return value * unit.to_internal


def _setup(args, machine, model, values) -> bb.Setup:
    axes_given = None
    if args.axes:
        axes_given = [a.strip() for a in args.axes.split(",")]
        if len(axes_given) != 2:
            raise ChaincompError(f"--axes: expected two axes A,B, got {args.axes!r}")
    axes = bb.plane_axes(machine, args.plane, values, axes_given, model)
    centre = _centre(args.centre, machine, bb.tool_point(model, bb.nominal(machine, values)))
    held = {s.name: values[s.name] for s in machine.axes if s.name not in axes}
    return bb.Setup(args.plane, axes, _to_mm("--radius", args.radius, machine), centre, held, args.feed)


def _where(machine, setup: bb.Setup) -> str:
    lu = machine.length_unit
    k = bb.U.UNITS[lu].to_internal
    held = ", ".join(f"{n} = {machine.symbol(n).from_internal(v):g} {machine.symbol(n).unit.name}"
                     for n, v in setup.held.items())
    return (f"plane {setup.plane} (axes {', '.join(setup.axes)}), radius {setup.radius / k:g} {lu}, centre pivot "
            f"at ({', '.join(f'{c / k:g}' for c in setup.centre)}) {lu} on the workpiece side"
            + (f"; {held}" if held else "") + (f"; feed {setup.feed:g} mm/min" if setup.feed else ""))


def _figures(ev: dict, radius: float) -> dict:
    """The figures in µm (centre offset and radius minus R too), for JSON and text."""
    out = {}
    for d, f in ev.items():
        g = {"G": f["G"] / UM, "centre_offset": [c / UM for c in f["centre"]],
             "radius_minus_R": (f["radius"] - radius) / UM, "points": f["points"]}
        if "F_max" in f:
            g.update(F_max=f["F_max"] / UM, F_min=f["F_min"] / UM)
        if "H" in f:
            g["H"] = f["H"] / UM
        out[d] = g
    return out


def _figures_text(fig: dict) -> list[str]:
    out = [f"  {'':22} {'G':>8} {'F_max':>8} {'F_min':>8}   {'LSQ centre offset':>20} {'radius − R':>11}  (µm)"]
    names = {"ccw": "ccw (counterclockwise)", "cw": "cw (clockwise)", "bidirectional": "bidirectional G(b)"}
    for d, f in fig.items():
        fmax = f"{fixed(f['F_max'], 3, 8)} {fixed(f['F_min'], 3, 8)}" if "F_max" in f else f"{'':8} {'':8}"
        cx, cy = f["centre_offset"]
        out.append(f"  {names[d]:22} {f['G']:8.3f} {fmax}   {_z(cx):+9.3f}, {_z(cy):+9.3f} "
                   f"{_z(f['radius_minus_R']):+11.3f}")
    if "H" in fig.get("bidirectional", {}):
        out.append(f"  circular hysteresis H (largest radial difference of the two paths) {fig['bidirectional']['H']:.3f} µm")
    out.append("G: circular deviation, the radial range about the least-squares circle's centre (ISO 230-4); "
               "F: radial deviation, the largest and smallest deviation from R about the pivot")
    return out


def _z(v: float) -> float:
    """v as printed to 3 decimals, without a sign on zero ('-0.000')."""
    return round(v, 3) + 0.0


def _division(span_um: float) -> float:
    """µm per division: 1, 2 or 5 times a power of ten, so that the trace spans about 4 divisions."""
    raw = max(span_um, 1e-6) / 4
    p = 10 ** math.floor(math.log10(raw))
    return next(m * p for m in (1, 2, 5, 10) if m * p >= raw)


def plot(trace: bb.Trace, ev: dict, fig_um: dict, title: str, output: str) -> None:
    """Polar plot as ballbar software draws it: the nominal circle at the middle ring, the
    deviation magnified (rings one division apart), both directions."""
    use_agg()
    import matplotlib.pyplot as plt
    # the scale spans the trace and the nominal circle (0): a few divisions, whatever the values
    lo, hi = min(float(trace.deviation.min()) / UM, 0.0), max(float(trace.deviation.max()) / UM, 0.0)
    div = _division(hi - lo)
    rings = max(4, math.ceil(-lo / div) + 2)    # divisions from the plot's centre to the nominal circle
    fig = plt.figure(figsize=(7, 7.8))
    ax = fig.add_subplot(projection="polar")
    for d, colour, style in ((bb.CCW, "tab:blue", "-"), (bb.CW, "tab:red", "--")):
        th, dev = trace.of(d)
        if len(th) == 0:
            continue
        order = np.argsort(np.mod(th, 2 * np.pi))
        t, r = np.mod(th, 2 * np.pi)[order], rings * div + dev[order] / UM
        ax.plot(np.r_[t, t[:1]], np.r_[r, r[:1]], color=colour, lw=1.2, ls=style,
                label=f"{d}: G = {fig_um[d]['G']:.2f} µm")
    full = np.linspace(0, 2 * np.pi, 721)
    ax.plot(full, np.full_like(full, rings * div), color="k", lw=1.0, ls=":", label="nominal circle (R)")
    ax.set_ylim(0, (rings + max(2, math.ceil(hi / div) + 1)) * div)
    ticks = np.arange(0, ax.get_ylim()[1] + div / 2, div)
    ax.set_yticks(ticks)
    ax.set_yticklabels([f"{t - rings * div:+g}" if abs(t - rings * div) > 1e-12 else "0" for t in ticks],
                       fontsize=7)
    ax.set_rlabel_position(100)
    ax.grid(True, alpha=0.4)
    bi = fig_um.get("bidirectional")
    fs = [f for d, f in fig_um.items() if "F_max" in f]
    head = (f"G(b) = {bi['G']:.2f} µm" if bi else f"G = {fs[0]['G']:.2f} µm") + \
        f"   F = {max(f['F_max'] for f in fs):+.2f} / {min(f['F_min'] for f in fs):+.2f} µm"
    ax.set_title(f"{title}\n{head}   scale {div:g} µm/div\n(radial deviation from R in µm, magnified)",
                 fontsize=9, pad=18)
    ax.legend(loc="lower left", bbox_to_anchor=(-0.12, -0.12), fontsize=8)
    fig.subplots_adjust(top=0.8, bottom=0.1)
    save(fig, output, dpi=110)
    plt.close(fig)


def _combination(machine, fit: bb.Fit, t: bb.Term) -> list[tuple[str, float]]:
    """The terms t's estimate stands for too, each with its factor in display units."""
    size = t.unit(machine)[1]
    return [(o.name, f * o.unit(machine)[1] / size) for o, f in fit.combinations[t.name]]


def fit_doc(machine, fit: bb.Fit, axes) -> dict:
    out = []
    for t, v, s in zip(fit.terms, fit.estimates, fit.uncertainties):
        unit, size = t.unit(machine)
        out.append({"term": t.name, "error": t.error, "axis": t.axis, "power": t.power, "value": v / size,
                    "uncertainty": s / size, "unit": unit,
                    "stands_for": [{"term": o, "factor": f} for o, f in _combination(machine, fit, t)]})
    sm = fit.scale_mismatch(axes)
    return {"terms": out, "scale_mismatch": None if sm is None else
            {"axes": list(axes), "value": sm[0] / (UM / 1000), "uncertainty": sm[1] / (UM / 1000), "unit": "um/m"},
            "not_seen": fit.unseen, "assumed_zero": fit.assumed_zero, "not_fitted": fit.not_fitted,
            "rms_residual_um": fit.rms / UM, "rms_before_um": fit.rms_before / UM, "points": fit.points,
            "degrees_of_freedom": fit.dof}


def fit_text(machine, fit: bb.Fit, axes) -> list[str]:
    out = [f"fit: {fit.points} points, {len(fit.terms)} unknowns, {fit.dof} degrees of freedom; rms of the trace "
           f"against the start values {fit.rms_before / UM:.4g} µm, residual after the fit {fit.rms / UM:.4g} µm",
           f"  {'term':<14} {'estimate ± standard uncertainty':>34}   stands also for"]
    for t, v, s in zip(fit.terms, fit.estimates, fit.uncertainties):
        unit, size = t.unit(machine)
        value = f"{plus_minus(v / size, s / size)} {_shown(unit)}"
        out.append(f"  {t.name:<14} {value:>34}   "
                   f"{' '.join(f'{f:+.4g}·{o}' for o, f in _combination(machine, fit, t)) or '-'}")
    sm = fit.scale_mismatch(axes)
    if sm:
        out.append(f"scale mismatch {axes[0]} − {axes[1]} (the difference of their scale errors): "
                   f"{plus_minus(sm[0] / (UM / 1000), sm[1] / (UM / 1000))} µm/m")
    out.append("'stands also for': terms that move the trace only as fitted ones do; each estimate is its "
               "term plus the factors times those (assume some zero with --assume-zero to choose others)")
    if fit.unseen:
        out.append(f"not seen by this trace (move no point of it): {', '.join(fit.unseen)}")
    if fit.not_fitted:   # one reason today: a table or polynomial in the start values
        out.append(f"not fitted, given as tables or polynomials in the start values: {', '.join(fit.not_fitted)}")
    return out


def _shown(unit: str) -> str:
    """A unit as printed for people: 'um' and 'um/m' as µm and µm/m (files and JSON keep ASCII)."""
    return "µ" + unit[1:] if unit.startswith("um") else unit


def params_text(machine, fit: bb.Fit, start: dict, source: str, merge_from: str | None, command: str) -> str:
    """The fitted errors as a params file: constants 'VALUE UNIT', an error with fitted powers of
    an axis as a polynomial over it; start values (--params) added, the rest of that file kept."""
    entries: dict[str, dict] = {}
    for t, v, s in zip(fit.terms, fit.estimates, fit.uncertainties):
        if t.error is None:
            continue
        e = entries.setdefault(t.error, {"axis": None, "coeffs": {}, "sigma": {}})
        if t.power:
            e["axis"] = t.axis
        e["coeffs"][t.power] = v
        e["sigma"][t.power] = s
    comment = f"fitted by chaincomp ballbar from {source}" + (" (the start values plus the fit)" if merge_from else "")

    def lines_for(name: str, indent: str) -> list[str]:
        e = entries[name]
        s = machine.symbol(name)
        base = start.get(name, 0.0)
        coeffs = dict(e["coeffs"])
        coeffs[0] = coeffs.get(0, 0.0) + (base if not isinstance(base, Varying) else 0.0)
        note = "; ".join(("constant" if k == 0 else f"{e['axis']}^{k}") + ": standard uncertainty "
                         + _sigma_text(machine, name, e["axis"], k, sd) for k, sd in sorted(e["sigma"].items()))
        head = [f"{indent}# {name}: {one_line(comment)}; {note}"]
        if e["axis"] is None:
            return head + [f'{indent}{name}: "{_fmt(s.from_internal(coeffs[0]))} {s.unit.name}"']
        a = machine.symbol(e["axis"])
        poly = [coeffs.get(k, 0.0) / s.unit.to_internal * a.unit.to_internal ** k for k in range(max(coeffs) + 1)]
        return head + [f"{indent}{name}:   # {one_line(s.meaning)}" if s.meaning else f"{indent}{name}:",
                       f"{indent}  axis: {e['axis']}",
                       f"{indent}  units: [{a.unit.name}, {s.unit.name}]",
                       f"{indent}  polynomial: [{', '.join(_fmt(c) for c in poly)}]"]

    if merge_from:
        import tempfile
        text = None
        for name in entries:
            src = merge_from
            if text is not None:
                fd, src = tempfile.mkstemp(suffix=".yaml")
                with os.fdopen(fd, "w", encoding="utf-8") as f:
                    f.write(text)
            try:
                text = merge(src, machine, name, lambda indent, n=name: lines_for(n, indent))
            finally:
                if src != merge_from:
                    os.remove(src)
        if text is None:
            from ..model.yamlsource import read_text
            text = read_text(merge_from)
        return text
    body = [f"# Written by: {one_line(command)}",
            f"# rms residual {fit.rms / UM:.4g} µm over {fit.points} points; each value stands also for the terms",
            "# that move the trace as it does (see the report)",
            f"machine: {machine.name}", f"description: errors fitted to a ballbar trace (chaincomp ballbar)",
            "values:"]
    if not entries:
        body.append("  {}")
    for name in entries:
        body += lines_for(name, "  ")
    text = "\n".join(body) + "\n"
    return text.replace("values:\n  {}\n", "values: {}\n")


def _fmt(v: float) -> str:
    text = f"{v:.10g}"
    return "0" if text == "-0" else text


def _sigma_text(machine, error, axis, k, sd) -> str:
    s = machine.symbol(error)
    if k == 0:
        return f"{s.from_internal(sd):.3g} {s.unit.name}"
    a = machine.symbol(axis)
    return f"{sd / s.unit.to_internal * a.unit.to_internal ** k:.3g} {s.unit.name}/{a.unit.name}" + \
        (f"^{k}" if k > 1 else "")


def run(args) -> int:
    # an empty option value is a typo, not a request for the default (as protocol --angles '')
    refuse_empty(("--params", args.params), ("--centre", args.centre), ("--axes", args.axes), ("--fit", args.fit),
                 ("--plot", args.plot), ("-o", args.output), *(("--prefer", v) for v in args.prefer),
                 *(("--assume-zero", v) for v in args.assume_zero))
    if args.fit:
        return run_fit(args)
    for opt, v in (("--plane", args.plane), ("--radius", args.radius)):
        if v is None:
            raise ChaincompError(f"{opt} is needed to predict a trace (or give --fit TRACE.csv)")
    for opt, v in (("--degree", args.degree != 1), ("--assume-zero", args.assume_zero), ("--prefer", args.prefer)):
        if v:
            raise ChaincompError(f"{opt} applies to --fit only")
    check_output(args.output, args.machine, args.params)
    _two_outputs(args)
    check_image(args.plot, args.machine, args.params, option="--plot")
    machine = load(args.machine)
    values, has_errors = values_for(machine, args.params, args.sets)
    model = ExactModel(machine)
    setup = _setup(args, machine, model, values)
    if not has_errors:
        print("chaincomp ballbar: warning: no error values given (--params or --set): the trace is a perfect "
              "circle", file=sys.stderr)
    trace = bb.predict(machine, values, setup, args.points, model)
    ev = bb.evaluate(trace)
    fig = _figures(ev, setup.radius)
    where = _where(machine, setup)
    if args.format == "json":
        k = bb.U.UNITS[machine.length_unit].to_internal
        doc = {"machine": machine.name, "params": args.params, "standard": "ISO 230-4",
               "plane": setup.plane, "axes": list(setup.axes), "radius": setup.radius / k,
               "centre": [c / k for c in setup.centre], "length_unit": machine.length_unit,
               "held": {n: machine.symbol(n).from_internal(v) for n, v in setup.held.items()},
               "feed": setup.feed, "units": {"figures": "um", "angle": "deg", "deviation": "um"},
               "G_centre": "least squares", "figures": fig,
               "trace": [{"direction": d, "angle": np.degrees(trace.of(d)[0]).tolist(),
                          "deviation": (trace.of(d)[1] / UM).tolist()} for d in (bb.CCW, bb.CW)]}
        print(to_json(doc))
    else:
        print("\n".join([f"ballbar {machine.name} ({machine.file})" + (f" with {args.params}" if args.params else "")
                         + f": ISO 230-4 circular test predicted by the exact model, {args.points} points each way",
                         where] + _figures_text(fig)))
    if args.output:
        bb.write_trace(args.output, machine, trace,
                       [one_line(f"predicted by chaincomp ballbar from {args.params or 'no params'}")])
        print(f"ballbar: trace -> {args.output}", file=sys.stderr)
    if args.plot:
        plot(trace, ev, fig, f"ISO 230-4 circular test predicted for {machine.name}"
             + (f" with {os.path.basename(args.params)}" if args.params else "") + "\n" + where.replace("; ", "\n"),
             args.plot)
        print(f"ballbar: plot -> {args.plot}", file=sys.stderr)
    return 0


def _two_outputs(args) -> None:
    if args.plot and args.output and _same_file(args.plot, args.output):
        raise ChaincompError(f"--plot {args.plot}: is also the -o output; give the plot a name of its own")


def run_fit(args) -> int:
    for opt, v in (("--plane", args.plane), ("--radius", args.radius), ("--centre", args.centre),
                   ("--set", args.sets), ("--feed", args.feed), ("--axes", args.axes)):
        if v:
            raise ChaincompError(f"{opt}: with --fit the test's set-up comes from the trace's header")
    check_output(args.output, args.machine, args.params, args.fit)
    _two_outputs(args)
    check_image(args.plot, args.machine, args.params, args.fit, option="--plot")
    machine = load(args.machine)
    assume = check_errors(machine, names(",".join(args.assume_zero), "--assume-zero"), "--assume-zero")
    prefer = check_errors(machine, names(",".join(args.prefer), "--prefer"), "--prefer")
    both = [e for e in prefer if e in assume]
    if both:
        raise ChaincompError(f"--prefer {both[0]}: it is also in --assume-zero (held at its start value, not fitted)")
    trace = bb.read_trace(args.fit, machine)
    for d in (bb.CCW, bb.CW):
        th = trace.of(d)[0]
        if len(th) and bb.largest_gap(th) > math.radians(45):
            print(f"chaincomp ballbar: warning: {args.fit}: the {d} points leave {math.degrees(bb.largest_gap(th)):.0f}° "
                  "of the circle without a point: G, F and the fit see only part of it", file=sys.stderr)
    values, _ = values_for(machine, args.params, [])
    setup = trace.setup
    values.update(setup.held)
    for n, v in setup.held.items():   # as --set warns in a prediction
        s, (lo, hi) = machine.symbol(n), machine.symbol(n).limits
        if not lo <= s.from_internal(v) <= hi:
            print(f"chaincomp ballbar: warning: {args.fit}:{trace.where['held']}: held: {n} = {s.from_internal(v):g} "
                  f"{s.unit.name} is outside its limits [{lo:g}, {hi:g}]", file=sys.stderr)
    model = ExactModel(machine)
    setup.axes = bb.plane_axes(machine, setup.plane, values, list(setup.axes) if setup.axes else None, model,
                               source=trace)
    for n in setup.held:
        if n in setup.axes:
            raise ChaincompError(f"{n} drives the circle; it cannot be held", args.fit, trace.where["held"], "held")
    axes = bb.commanded(machine, model, setup, values, trace.angle, source=trace)
    start = bb.deviation(machine, model, setup, values, axes)
    fit = bb.fit(machine, trace, values, axes, start, assume, args.degree, JetModel(machine, 1), prefer)
    ev = bb.evaluate(trace)
    fig = _figures(ev, setup.radius)
    where = _where(machine, setup)
    if args.format == "json":
        print(to_json({"machine": machine.name, "trace": args.fit, "start_params": args.params,
                       "standard": "ISO 230-4", "plane": setup.plane, "axes": list(setup.axes),
                       "units": {"figures": "um"}, "figures": fig, "fit": fit_doc(machine, fit, setup.axes)}))
    else:
        print("\n".join([f"ballbar fit of {machine.name} ({machine.file}) to {args.fit}"
                         + (f", start values {args.params}" if args.params else ""), where]
                        + _figures_text(fig) + fit_text(machine, fit, setup.axes)))
    if args.output:
        command = " ".join(shlex.quote(c) for c in ["chaincomp", "ballbar", args.machine, "--fit", args.fit]
                           + (["--params", args.params] if args.params else [])
                           + ([f"--degree={args.degree}"] if args.degree != 1 else [])
                           + ([f"--assume-zero={','.join(assume)}"] if assume else [])
                           + ([f"--prefer={','.join(prefer)}"] if prefer else []) + ["-o", args.output])
        start_vals = {}
        if args.params:
            from ..model.params import load_params
            start_vals = load_params(args.params, machine)
        text = params_text(machine, fit, start_vals, args.fit, args.params, command)
        _write_loadable(args.output, text, machine)
        if not any(t.error for t in fit.terms):
            print("chaincomp ballbar: warning: no error of the machine was fitted (the trace shows only the centre "
                  f"offset): {args.output} holds " + ("the start values unchanged" if args.params else "no values"),
                  file=sys.stderr)
        print(f"ballbar: fitted values -> {args.output}", file=sys.stderr)
    if args.plot:
        plot(trace, ev, fig, f"ISO 230-4 circular test of {machine.name}: {os.path.basename(args.fit)}\n"
             + where.replace("; ", "\n"),
             args.plot)
        print(f"ballbar: plot -> {args.plot}", file=sys.stderr)
    return 0
