"""``chaincomp thermal fit`` and ``chaincomp thermal check``: a thermal model of the machine's
errors from a log of temperatures and measured drift, and how much of a log's drift a model
takes out."""

from __future__ import annotations

import shlex
import sys

import numpy as np

from ..errors import ChaincompError
from ..measure import thermal as T
from ..output import write_file
from .common import (add_controller_arguments, add_format_argument, add_machine_argument, assignments, check_finite,
                     check_output, integer, load, names, number, parse_number, require_controller, to_json)

STREAM_CONTROLLERS = ("siemens", "isg")   # thermal stream's --controller

LOG_HELP = ("a CSV log: 'time [s]', temperature columns 'NAME [degC]' and drift columns named by the errors they "
            "measure, e.g. 'EZZ [um]'")


def add_parser(sub) -> None:
    p = sub.add_parser("thermal", help="thermal models: fit one to logged drift (fit), or check one on a log (check)",
                       description="Thermal errors as functions of measured temperatures and their first-order lags "
                                   "(docs/guide/thermal.md).")
    verbs = p.add_subparsers(dest="thermal_verb", metavar="ACTION", required=True)
    f = verbs.add_parser("fit", help="fit gains and time constants to a log, choosing a few of its sensors",
                         description="For each drift column of the log, choose sensors one at a time by how well they "
                                     "predict held-out stretches of the log (blocked cross-validation over 5 "
                                     "stretches of time; each must improve it by more than its standard error, pass "
                                     "Schwarz's criterion and lower the residual by --min-improvement), fit the "
                                     "offset, gains and time constants (value = offset + sum gain * (lagged "
                                     "temperature - reference)), drop the terms the log cannot support "
                                     "(--max-uncertainty), report their standard uncertainties (white noise on "
                                     "the drift readings assumed), how well each time constant is identified and "
                                     "what log would pin down what is uncertain, and write the model.")
    add_machine_argument(f)
    f.add_argument("log", metavar="LOG.csv", help=LOG_HELP)
    f.add_argument("-o", "--output", required=True, metavar="MODEL.yaml", help="thermal model to write")
    f.add_argument("--errors", metavar="E1,E2", help="drift columns to fit (default all)")
    f.add_argument("--sensors", metavar="S1,S2", help="sensors to choose from (default every temperature column)")
    f.add_argument("--max-sensors", type=integer(1, T.MAX_TERMS), default=3, metavar="N",
                   help=f"at most this many sensors per error (default 3, at most {T.MAX_TERMS})")
    f.add_argument("--min-improvement", type=number(0, 1), default=0.01, metavar="R",
                   help="a sensor is taken only if it lowers the RMS residual by this fraction (default 0.01)")
    f.add_argument("--max-uncertainty", type=number(0, 10, above=True), default=T.MAX_RELATIVE_UNCERTAINTY,
                   metavar="R", help="a term whose gain or time constant has a standard uncertainty above this "
                   f"fraction of its value, or a time constant longer than the log, is not written (default "
                   f"{T.MAX_RELATIVE_UNCERTAINTY:g})")
    f.add_argument("--no-lag", action="store_true", help="no time constants: each term follows its sensor at once")
    f.add_argument("--reference", type=number(*T.TEMPERATURE_RANGE), default=T.REFERENCE_TEMPERATURE, metavar="DEGC",
                   help=f"reference temperature (default {T.REFERENCE_TEMPERATURE:g} degC, ISO 1)")
    f.add_argument("--drift", action="append", default=[], metavar="COLUMN=ERROR",
                   help="a drift column measuring ERROR under another name (repeatable)")
    f.add_argument("--check", metavar="HELD_OUT.csv", help="also report the model on this log (not used in the fit)")
    add_format_argument(f)
    f.set_defaults(run=run_fit)
    c = verbs.add_parser("check", help="the drift of a log before and after a thermal model",
                         description="Evaluate the model on the log's temperatures and report each drift column "
                                     "before and after subtracting it (largest and RMS, the error's unit), both "
                                     "from the log's first row, as a probe reads the drift since it was touched "
                                     "off.")
    add_machine_argument(c)
    c.add_argument("model", metavar="MODEL.yaml", help="thermal model (as thermal fit writes)")
    c.add_argument("log", metavar="LOG.csv", help=LOG_HELP)
    c.add_argument("--drift", action="append", default=[], metavar="COLUMN=ERROR",
                   help="a drift column measuring ERROR under another name (repeatable)")
    add_format_argument(c)
    c.set_defaults(run=run_check)
    s = verbs.add_parser("stream", help="per-axis offset and slope over a log, as Siemens or ISG controllers take them",
                         description="Evaluate the model on the log's temperatures and turn its errors into what a "
                                     "controller's per-axis temperature compensation takes: for each linear axis an "
                                     "offset at a reference position and a slope (the tool's error along the axis' "
                                     "travel over its range, the other axes at their default positions, fitted by a "
                                     "line): the error line itself, as both manuals define it, which the "
                                     "controller takes out (it moves the axis by minus the line). --controller "
                                     "siemens: SD43900 "
                                     "$SA_TEMP_COMP_ABS_VALUE (mm), SD43910 $SA_TEMP_COMP_SLOPE (tan beta) and "
                                     "SD43920 $SA_TEMP_COMP_REF_POSITION (mm), K = SD43900 + SD43910 (P - SD43920); "
                                     "isg: P-AXIS-00273 temp_comp_offset_0 (0.1 um), P-AXIS-00274 "
                                     "temp_comp_coefficient (um/m) and P-AXIS-00272 temp_comp_position_0 (0.1 um), "
                                     "integers. One row per row of the log; the report gives each axis' largest "
                                     "values, their fastest change and what the line leaves (docs/guide/thermal.md).")
    add_machine_argument(s)
    s.add_argument("model", metavar="MODEL.yaml", help="thermal model (as thermal fit writes)")
    s.add_argument("log", metavar="LOG.csv", help="a CSV log of the temperatures ('time [s]', 'NAME [degC]'; drift "
                   "columns are not needed)")
    add_controller_arguments(s, STREAM_CONTROLLERS)
    s.add_argument("-o", "--output", required=True, metavar="OUT.csv", help="the stream to write")
    s.add_argument("--reference-position", action="append", default=[], metavar="AXIS=VALUE",
                   help="the line's reference position of an axis, in its unit (default its lower limit; repeatable)")
    s.set_defaults(run=run_stream)


def _renames(items: list[str]) -> dict[str, str]:
    return assignments(items, "--drift", "COLUMN=ERROR")


def _require_sensors(model: T.ThermalModel, log: T.Log) -> None:
    missing = [s for s in model.sensors if s not in log.temperatures]
    if missing:
        raise ChaincompError(f"the model reads sensor {', '.join(missing)}, not in the log (sensors: "
                             f"{', '.join(log.temperatures)})", log.path)


def _check(model: T.ThermalModel, log: T.Log) -> dict:
    """Each of the model's errors that the log measures: its drift before and after the model."""
    _require_sensors(model, log)
    out = {}
    for name, em in model.errors.items():
        if name not in log.drift:
            continue
        scale = log.drift_units[name].to_internal / em.unit.to_internal   # the log's unit -> the model's
        d = log.drift[name] * scale
        # both from the log's first row: a probe reads the drift since it was touched off
        predicted = em.evaluate(log.t, log.temperatures, model.reference)
        before = d - d[0]
        after = before - (predicted - predicted[0])
        out[name] = {"unit": em.unit.name, "before_max": float(np.max(np.abs(before))),
                     "before_rms": float(np.sqrt(np.mean(before ** 2))),
                     "after_max": float(np.max(np.abs(after))), "after_rms": float(np.sqrt(np.mean(after ** 2)))}
    if not out:
        raise ChaincompError(f"no drift column of the model's errors ({', '.join(model.errors)})", log.path)
    return out


def _check_lines(result: dict, what: str) -> list[str]:
    lines = [f"{what}:"]
    for name, r in result.items():
        share = f"{100 * r['after_max'] / r['before_max']:.0f} % of the largest" if r["before_max"] > 0 else "no drift"
        lines.append(f"  {name}: drift {r['before_max']:.4g} {r['unit']} max, {r['before_rms']:.4g} RMS -> left "
                     f"{r['after_max']:.4g} max, {r['after_rms']:.4g} RMS ({share})")
    return lines


def run_fit(args) -> int:
    check_output(args.output, args.machine, args.log, args.check)
    machine = load(args.machine)
    rename = _renames(args.drift)
    log = T.read_log(args.log, machine, rename)
    held = T.read_log(args.check, machine, rename) if args.check else None
    errors = names(args.errors, "--errors") if args.errors else list(log.drift)
    for e in errors:
        if e not in log.drift:
            raise ChaincompError(f"--errors: no drift column of {e} in the log (drift columns: {', '.join(log.drift)})",
                                 args.log)
    sensors = names(args.sensors, "--sensors") if args.sensors else list(log.temperatures)
    for option, given in (("--sensors", sensors), ("--errors", errors)):
        twice = sorted({x for x in given if given.count(x) > 1})
        if twice:
            raise ChaincompError(f"{option}: {', '.join(twice)} given twice")
    for s in sensors:
        if s not in log.temperatures:
            raise ChaincompError(f"--sensors: no temperature column {s} in the log (sensors: "
                                 f"{', '.join(log.temperatures)})", args.log)
    model = T.ThermalModel(machine.name, args.reference)
    fits = {}
    for e in errors:
        if len(log.t) >= 100_000:   # a long fit: say what it is doing
            print(f"thermal fit: {e} from {len(log.t)} rows, {len(sensors)} sensors", file=sys.stderr)
        f = T.fit(log, e, sensors, args.reference, args.max_sensors, args.min_improvement, not args.no_lag,
                  progress=lambda text: print(f"thermal fit: {text}", file=sys.stderr),
                  max_relative=args.max_uncertainty)
        if not f.model.terms:
            why = "".join(f"; {n}" for n in f.notes)
            raise ChaincompError(f"{e}: no sensor explains its drift (RMS {f.rms_before:.4g} "
                                 f"{log.drift_units[e].name}){why}: nothing to write", args.log)
        model.errors[e] = f.model
        fits[e] = f
    command = ["chaincomp", "thermal", "fit", args.machine, args.log, "-o", args.output]
    text = T.model_text(model, [f"Written by: {' '.join(shlex.quote(c) for c in command)}",
                                f"Fitted to {len(log.t)} rows over {log.t[-1] - log.t[0]:g} s; each error's "
                                "value is its params value plus offset + sum gain * (lag - reference)."])
    held_result = None

    def loads(tmp: str) -> None:   # the file written reads back, and the held-out log is checked on it
        nonlocal held_result
        written = T.load_model(tmp, machine)
        if held is not None:
            held_result = _check(written, held)
            check_finite(held_result)

    doc = {"machine": machine.name, "log": args.log, "rows": int(len(log.t)), "reference": args.reference,
           "errors": {e: {"unit": f.model.unit.name, "offset": f.model.offset, "offset_u": f.model.offset_u,
                          "rms_before": f.rms_before, "rms_after": f.rms_after, "max_before": f.max_before,
                          "max_after": f.max_after, "held_out_rms": f.cv_rms, "span": f.span,
                          "terms": [{"sensor": t.sensor, "gain": t.gain, "gain_u": t.gain_u,
                                     "time_constant": t.time_constant, "time_constant_u": t.time_constant_u,
                                     "identifiability": T.identifiability(t, f.span)}
                                    for t in f.model.terms],
                          "notes": f.notes, "advice": T.advice(f)} for e, f in fits.items()}}
    check_finite(doc)
    write_file(args.output, text, loads)
    if held_result is not None:
        doc["check"] = {"log": args.check, "errors": held_result}
    if args.format == "json":
        print(to_json(doc))
        return 0
    lines = [f"thermal model of {machine.name} from {args.log} ({len(log.t)} rows) -> {args.output}"]
    for e, f in fits.items():
        u = f.model.unit.name
        lines.append(f"  {e}: offset {f.model.offset:.4g} ± {f.model.offset_u:.2g} {u}; drift RMS "
                     f"{f.rms_before:.4g} (about its mean) -> {f.rms_after:.4g} {u}, max {f.max_before:.4g} -> {f.max_after:.4g} {u}")
        lines.append(f"    held out (5 stretches of the log in turn): RMS {f.cv_rms:.4g} {u}")
        for t in f.model.terms:
            lines.append(f"    {t.sensor}: gain {t.gain:.5g} ± {t.gain_u:.2g} {u}/K, time constant "
                         f"{t.time_constant:.5g} ± {t.time_constant_u:.2g} s: {T.identifiability(t, f.span)}")
        lines += [f"    note: {n}" for n in f.notes]
        lines.append(f"    to pin it down: {' '.join(T.advice(f))}")
    if held_result is not None:
        lines += _check_lines(held_result, f"on {args.check} (held out)")
    print("\n".join(lines))
    return 0


def run_check(args) -> int:
    machine = load(args.machine)
    model = T.load_model(args.model, machine)
    log = T.read_log(args.log, machine, _renames(args.drift))
    result = _check(model, log)
    doc = {"machine": machine.name, "model": args.model, "log": args.log, "errors": result}
    check_finite(doc)
    if args.format == "json":
        print(to_json(doc))
    else:
        print("\n".join(_check_lines(result, f"{args.model} on {args.log}")))
    return 0


STREAM_COLUMNS = {   # per axis: (parameter, unit, scale from mm or mm/mm, integer)
    "siemens": [("SD43900 $SA_TEMP_COMP_ABS_VALUE", "mm", 1.0, False),
                ("SD43910 $SA_TEMP_COMP_SLOPE", "1", 1.0, False),
                ("SD43920 $SA_TEMP_COMP_REF_POSITION", "mm", 1.0, False)],
    "isg": [("P-AXIS-00273 temp_comp_offset_0", "0.1um", 1e4, True),
            ("P-AXIS-00274 temp_comp_coefficient", "um/m", 1e6, True),
            ("P-AXIS-00272 temp_comp_position_0", "0.1um", 1e4, True)],
}


def run_stream(args) -> int:
    require_controller(args, STREAM_CONTROLLERS)
    check_output(args.output, args.machine, args.model, args.log)
    machine = load(args.machine)
    model = T.load_model(args.model, machine)
    refs = {}
    axes = {a.name: a for a in machine.axes if a.unit.kind == "length"}
    for name, raw in assignments(args.reference_position, "--reference-position",
                                 f"AXIS=VALUE with a linear axis of {machine.name} ({', '.join(axes)})").items():
        if name not in axes:
            raise ChaincompError(f"--reference-position: expected AXIS=VALUE with a linear axis of {machine.name} "
                                 f"({', '.join(axes)}), got {name}={raw}")
        try:
            refs[name] = axes[name].to_internal(float(parse_number(raw)))
        except ValueError as exc:
            raise ChaincompError(f"--reference-position {name}={raw}: {exc}") from None
    log = T.read_log(args.log, machine, require_drift=False)
    _require_sensors(model, log)
    lines = T.axis_lines(machine, list(model.errors), refs)
    if not lines:
        raise ChaincompError(f"{machine.name} has no linear axis: nothing for a per-axis compensation", machine.file)
    values = {e: em.evaluate(log.t, log.temperatures, model.reference) * em.unit.to_internal
              for e, em in model.errors.items()}   # internal units, per row
    cols = STREAM_COLUMNS[args.target]
    header = ["time [s]"] + [f"{ln.axis} {name} [{unit}]" for ln in lines for name, unit, _, _ in cols]
    table = [log.t]
    report = {}
    for ln in lines:
        # The error line, not negated: SINUMERIK K3 (SD43900/SD43910) defines "the gradient of
        # the approximated error line", Delta K = K0 + tan(beta) (P - P0), which the controller
        # compensates (a positive value moves the axis negative); ISG's temperature offset is "the
        # deviation". A negated line would double the drift (docs/guide/thermal.md, The sign).
        offset = sum(values[e] * ln.offset[e] for e in values)       # the error along the axis, mm at P0
        slope = sum(values[e] * ln.slope[e] for e in values)         # mm/mm
        departure = sum(np.abs(values[e]) * ln.departure[e] for e in values)
        for (_, _, scale, whole), series in zip(cols, (offset, slope, np.full(len(log.t), ln.reference))):
            table.append(np.rint(series * scale) if whole else series * scale)
        rate = np.abs(np.diff(offset)) / np.diff(log.t) if len(log.t) > 1 else np.zeros(1)
        lo, hi = (machine.symbol(ln.axis).to_internal(v) for v in machine.symbol(ln.axis).limits)
        report[ln.axis] = {"reference_mm": ln.reference, "offset_max_um": float(np.max(np.abs(offset)) * 1e3),
                           "slope_max_um_per_m": float(np.max(np.abs(slope)) * 1e6),
                           "offset_rate_max_um_per_s": float(np.max(rate) * 1e3),
                           "line_departure_max_um": float(np.max(departure) * 1e3)}
        if args.target == "isg":   # what the integers' steps round away, at the far end of the axis
            report[ln.axis]["rounding_max_um"] = 0.05 + 0.5e-6 * max(abs(hi - ln.reference), abs(lo - ln.reference)) * 1e3
    doc = {"machine": machine.name, "model": args.model, "log": args.log, "format": args.target, "rows": len(log.t),
           "axes": report}
    check_finite(doc)
    text_rows = [",".join(header)]
    for k in range(len(log.t)):
        text_rows.append(",".join(f"{c[k] + 0.0:.0f}" if cols[(i - 1) % 3][3] and i else f"{c[k] + 0.0:.10g}"
                                  for i, c in enumerate(table)))   # (+ 0.0: never -0)
    write_file(args.output, "\n".join(text_rows) + "\n")
    if args.format == "json":
        print(to_json(doc))
        return 0
    out = [f"{args.target} temperature compensation of {machine.name} from {args.model} over {args.log} "
           f"({len(log.t)} rows) -> {args.output}"]
    for axis, r in report.items():
        out.append(f"  {axis}: reference {r['reference_mm']:g} mm; offset up to {r['offset_max_um']:.3g} um, slope up "
                   f"to {r['slope_max_um_per_m']:.3g} um/m; fastest change {r['offset_rate_max_um_per_s']:.3g} um/s; "
                   f"the line leaves up to {r['line_departure_max_um']:.3g} um"
                   + (f"; the integers round by up to {r['rounding_max_um']:.3g} um" if "rounding_max_um" in r else ""))
    print("\n".join(out))
    return 0
