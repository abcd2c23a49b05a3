"""``chaincomp identify``: error values from measured tool-tip coordinates (least squares)."""

from __future__ import annotations

import math
import re
import sys

from ..analysis.calibration_report import write_report
from ..errors import ChaincompError, NoAnswer, OutsideLimit
from ..measure.calibration import _write_loadable, slide_axis
from ..measure.identify import MAX_SMOOTH, HeldModel, Vary, held_values, identify
from ..measure.identify_report import params_yaml, to_json, to_text
from ..measure.lsq import HUBER_K
from ..measure.table import COMPONENTS, DIRECTIONS, ROTATION, outside_limits, read_table
from ..measure.protocol import check_errors
from ..model.display import add_units_argument
from ..model.machine import Symbol
from ..model.params import parse_value
from ..model.units import UNITS
from ..model.varying import MAX_POLYNOMIAL_COEFFICIENTS, MAX_TABLE_KNOTS
from .calibration_report import calibration_of, check_report
from .common import (add_assume_zero_argument, add_format_argument, add_hold_argument, add_machine_argument,
                     check_output, load, names, number, number_list, refuse_empty, to_json as json_text)


MIN_SIGMA = 1e-30   # internal units (mm, rad), as the smallest number a machine file may hold


def sigma_spec(machine, raw: str) -> dict[str, float]:
    """'--sigma 20um,10arcsec' -> {x, y, z: 0.02, kx, ky, kz, wx, wy, wz: 4.8e-5} (internal
    units). Items separated by commas: a length is every tool-point column's standard
    uncertainty, an angle every tool-direction column's and every component of a measured
    orientation's rotation vector (wx, wy, wz), COLUMN=VALUE one column's (later items win); a
    bare number is a length in the machine's unit."""
    out: dict[str, float] = {}
    for item in (t.strip() for t in raw.split(",")):
        column, sep, text = item.rpartition("=")
        column = column.strip()
        if sep and column not in COMPONENTS + DIRECTIONS + ROTATION:
            raise ChaincompError(f"--sigma: unknown column {column!r} (expected x, y, z, kx, ky, kz, or wx, wy, wz "
                                 f"for the components of a measured orientation)")
        value, error = None, None
        for kind, unit in (("length", machine.length_unit), ("angle", "rad")):
            try:
                value = parse_value(Symbol("--sigma", "constant", UNITS[unit], ""), text)
                break
            except ValueError as exc:
                error = str(exc)
                wrong_kind = re.match(r"(unit '.*' is an? \w+ unit) but", error)
                if not wrong_kind:
                    break
                error = (f"{wrong_kind.group(1)}: expected a length (tool point) or an angle (tool direction "
                         f"or orientation)")
        if value is None:
            raise ChaincompError(f"--sigma: {error}")
        if not value > 0:
            raise ChaincompError(f"--sigma: must be positive, got {text.strip()!r}")
        if value < MIN_SIGMA:   # 1/sigma squared overflows: at 1e-200 um the fit said 'nothing to identify'
            raise ChaincompError(f"--sigma: {text.strip()!r} is below {MIN_SIGMA:g} "
                                 f"{'mm' if kind == 'length' else 'rad'}: the weights 1/sigma^2 "
                                 "would leave a double's range")
        targets = [column] if sep else list(COMPONENTS if kind == "length" else DIRECTIONS + ROTATION)
        want = "length" if targets[0] in COMPONENTS else "angle"
        if kind != want:
            raise ChaincompError(f"--sigma {item}: {column} is a measured "
                                 + ("tool-point coordinate: " if want == "length"
                                    else "tool-direction or orientation component: ")
                                 + f"give {'a length, e.g. 20um' if want == 'length' else 'an angle, e.g. 10arcsec'}")
        out.update({c: value for c in targets})
    return out


VARY_FORMS = "NAME=table:K1,K2,... or NAME=poly:DEGREE (NAME@AXIS=... to name the axis)"


def vary_spec(machine, raw: str) -> Vary:
    """'EXX=table:0,100,200' (knots in the axis' declared unit) or 'EXX=poly:3'; the axis is the
    slide whose error block holds the error (chaincomp.calibration.find_slides) unless given as
    'EXX@X=...'."""
    def fail(msg):
        raise ChaincompError(f"--vary {raw}: {msg}")

    left, sep, form = raw.partition("=")
    if not sep:
        fail(f"expected {VARY_FORMS}")
    name, at, axis = (t.strip() for t in left.partition("@"))
    errors = [s.name for s in machine.errors]
    if name not in errors:
        fail(f"unknown error {name!r} for machine {machine.name!r} (errors: {', '.join(errors)})")
    axes = [s.name for s in machine.axes]
    if at:
        if axis not in axes:
            fail(f"{axis!r} is not an axis of {machine.name} (axes: {', '.join(axes)})")
    else:
        axis = slide_axis(machine, name)
        if axis is None:
            fail(f"{name} is not a component error of a slide (an error block after a translation along one "
                 f"linear axis), so the axis it varies along is not known: name it, e.g. "
                 f"--vary {name}@{axes[0]}={form.strip()}")
    a = machine.symbol(axis)
    kind, colon, rest = (t.strip() for t in form.partition(":"))
    if kind == "table":
        if not colon or not rest:
            fail(f"expected table:K1,K2,... (knots along {axis} in {a.unit.name})")
        knots = number_list(f"--vary {raw}", rest)
        if not 2 <= len(knots) <= MAX_TABLE_KNOTS:
            fail(f"a table needs 2 to {MAX_TABLE_KNOTS} knots, got {len(knots)}")
        for k0, k1 in zip(knots, knots[1:]):
            if not k1 > k0 or f"{k1:.10g}" == f"{k0:.10g}":
                fail(f"knots must increase (and differ in 10 significant digits): {k1:g} follows {k0:g}")
        lo, hi = a.limits
        outside = [k for k in knots if not lo <= k <= hi]
        if outside:
            fail(f"knot {outside[0]:g} lies outside {axis}'s limits [{lo:g}, {hi:g}] {a.unit.name}")
        return Vary(name, axis, "table", tuple(a.to_internal(k) for k in knots))
    if kind == "poly":
        if not re.fullmatch(r"[0-9]{1,3}", rest):
            fail(f"expected poly:DEGREE, an integer 0 to {MAX_POLYNOMIAL_COEFFICIENTS - 1}, got {rest!r}")
        degree = int(rest)
        if degree >= MAX_POLYNOMIAL_COEFFICIENTS:
            fail(f"the degree must be 0 to {MAX_POLYNOMIAL_COEFFICIENTS - 1} (the params format holds "
                 f"{MAX_POLYNOMIAL_COEFFICIENTS} coefficients), got {degree}")
        return Vary(name, axis, "poly", degree=degree)
    fail(f"unknown form {kind!r}: expected {VARY_FORMS}")


def loss_spec(raw: str) -> float | None:
    """'squares' -> None; 'huber' -> HUBER_K; 'huber:K' -> K (0.1 to 100 standard uncertainties)."""
    name, colon, k = (t.strip() for t in raw.partition(":"))
    if name == "squares" and not colon:
        return None
    if name != "huber":
        raise ChaincompError(f"--loss {raw}: expected squares, huber or huber:K")
    if not colon:
        return HUBER_K
    value = float(k) if re.fullmatch(r"[0-9]+(\.[0-9]*)?|\.[0-9]+", k) else math.nan
    if not 0.1 <= value <= 100:
        raise ChaincompError(f"--loss {raw}: K is a number of standard uncertainties, 0.1 to 100 (huber:1.5)")
    return value


def add_parser(sub) -> None:
    p = sub.add_parser("identify", help="fit error values to measured tool-tip coordinates",
                       description="Least-squares fit of the machine's error values to tool-tip "
                                   "coordinates measured at known axis positions (Gauss-Newton on the "
                                   "exact model). MEAS.csv: '#' comments, a header row naming every axis "
                                   "exactly as the machine file spells it (values in its declared unit) "
                                   "and any of x, y, z (tool tip in the machine's length unit) and kx, ky, kz "
                                   "(measured tool direction, a unit vector, where the machine has one) or qw, qx, "
                                   "qy, qz (the measured tool frame's orientation in the base frame, a unit "
                                   "quaternion, scalar first, where the machine has a tool frame: the residual is "
                                   "the rotation vector wx, wy, wz of R_measured R_model^T); an "
                                   "empty cell is not measured), one row per set-up. Reports each estimate "
                                   "with its standard uncertainty, the condition number, correlations above "
                                   "0.9, the errors these set-ups cannot identify, which get no value, and "
                                   "errors to assume zero so that the others can be (or --minimal fits a "
                                   "minimal identifiable set). Errors may be fitted as tables or polynomials "
                                   "along an axis (--vary). Refuses data that identify no error, or that "
                                   "leave no redundancy without --sigma.")
    add_machine_argument(p)
    p.add_argument("measurements", metavar="MEAS.csv", help="measured tool-tip coordinates")
    add_assume_zero_argument(p, "errors held at zero (not fitted)")
    add_hold_argument(p)
    p.add_argument("--sigma", metavar="SIGMA",
                   help="standard uncertainty of the measured coordinates, positive: a length for x, y, z "
                        "(e.g. 20um; a bare number is in the machine's length unit), an angle for the "
                        "direction kx, ky, kz and for each component wx, wy, wz of a measured orientation's "
                        "rotation vector (e.g. 10arcsec), or COLUMN=VALUE for one column, separated by "
                        "commas: 20um,10arcsec (default: one for all, estimated from the residuals; needed "
                        "when both points and directions or orientations are measured)")
    p.add_argument("--minimal", action="store_true",
                   help="fit a minimal identifiable set (QR with column pivoting of the scaled Jacobian); "
                        "every other parameter is held at zero and reported with the combination that "
                        "carries it")
    p.add_argument("--prefer", action="append", default=[], metavar="E1,E2",
                   help="errors to take into the minimal set first, in this order, each where it adds a "
                        "combination the data see (the rest chosen by pivoting); also kept out of the "
                        "suggested --assume-zero set; names separated by commas (repeatable)")
    p.add_argument("--vary", action="append", default=[], metavar="NAME=table:K1,K2,...|NAME=poly:DEG",
                   help="fit error NAME as a table on these knots (the axis' declared unit; linear between "
                        "them, held beyond) or a polynomial of this degree along its slide's axis "
                        "(NAME@AXIS=... names the axis); repeatable")
    p.add_argument("--smooth", type=number(0.0, MAX_SMOOTH), default=0.0, metavar="LAMBDA",
                   help="add LAMBDA x the sum of squared second differences of each table's knot values (in "
                        "the error's declared unit, e.g. um) to the weighted sum of squares; needs --sigma; "
                        f"0 to {MAX_SMOOTH:g}, where a table is already straight to a millionth of its unit "
                        "(more would only drown the data in rounding); default 0: none")
    p.add_argument("-o", "--output", metavar="params.yaml",
                   help="write the identified values as a params file (for eval and chaincompd); "
                        "never one of the inputs")
    p.add_argument("--strict", action="store_true",
                   help="with --sigma, refuse (exit 1, nothing written) a fit whose chi2/dof lies beyond its "
                        "99.9%% quantile (residuals larger than the uncertainties allow), which otherwise "
                        "is a warning naming the set-ups with the largest residuals")
    p.add_argument("--loss", default="squares", metavar="squares|huber[:K]",
                   help="squares (default) or Huber's robust loss, quadratic within K standard uncertainties and "
                        f"linear beyond (K default {HUBER_K}; iteratively reweighted): outliers are down-weighted "
                        "and listed with their standardized residuals")
    p.add_argument("--report", metavar="OUT.html",
                   help="also write a calibration report: one self-contained HTML file (set-up, the set-ups "
                        "measured, residuals before and after, dispersion, values with uncertainties and "
                        "correlations, what could not be seen, figures); never one of the inputs")
    add_units_argument(p)
    add_format_argument(p, what="report format")
    p.set_defaults(run=run)


def run(args) -> int:
    refuse_empty(("--sigma", args.sigma), *(("--prefer", v) for v in args.prefer),
                 *(("--assume-zero", v) for v in args.assume_zero), *(("--vary", v) for v in args.vary))
    machine = load(args.machine)
    check_output(args.output, args.measurements, args.machine, args.hold)
    check_report(args.report, args.output, args.measurements, args.machine)
    assume = check_errors(machine, names(",".join(args.assume_zero)), "--assume-zero")
    held = held_values(machine, args.hold, assume)
    sigma = sigma_spec(machine, args.sigma) if args.sigma is not None else None
    prefer = check_errors(machine, names(",".join(args.prefer)), "--prefer")
    vary = [vary_spec(machine, v) for v in args.vary]
    huber = loss_spec(args.loss)
    table = read_table(args.measurements, machine)
    for text in outside_limits(machine, table):
        print(f"chaincomp identify: warning: {text}", file=sys.stderr)
    fit = identify(machine, table, assume + list(held), sigma, vary=vary, smooth=args.smooth, minimal=args.minimal,
                   prefer=prefer, progress=lambda text: print(f"chaincomp identify: {text}", file=sys.stderr),
                   huber=huber, model=HeldModel(machine, held))
    fit.assumed_zero = [n for n in fit.assumed_zero if n not in held]
    if not fit.converged:
        units = ", ".join(f"{s.name} in {s.unit.name}" for s in machine.axes)
        hint = (f": a residual this large is most often a column in another unit (the axes are read in their "
                f"declared units, {units}; x, y, z in {machine.length_unit}) or another machine's measurements"
                if fit.rms > 1.0 else "")   # 1 mm: no geometric error of a machine is that large
        raise NoAnswer(f"the fit did not converge in {fit.iterations} Gauss-Newton iterations "
                             f"(rms residual {fit.rms / UNITS[machine.length_unit].to_internal:.4g} "
                             f"{machine.length_unit}); no values given{hint}", args.measurements)
    if fit.misfit is not None:
        if args.strict:
            raise OutsideLimit(f"{fit.misfit}; --strict: no values given", args.measurements)
        print(f"chaincomp identify: warning: {fit.misfit}", file=sys.stderr)
    if args.format == "json":
        print(json_text({**to_json(fit, args.measurements), "held": sorted(held)}))
    else:
        print(to_text(fit, args.measurements, args.units)
              + (f"\nheld at the values of {args.hold} (--hold): {', '.join(held)}" if held else ""))
    if args.output:
        _write_loadable(args.output, params_yaml(fit, args.measurements, held), machine)
        if args.format == "text":
            print(f"wrote {args.output}")
    if args.report:
        setup = [("machine file", args.machine), ("measurements", args.measurements),
                 ("sigma", args.sigma or "estimated from the residuals"),
                 ("assumed zero", ", ".join(assume) or "none"), ("held (--hold)", args.hold or "none"),
                 ("fitted as varying", ", ".join(args.vary) or "none"),
                 ("minimal set", "yes" if args.minimal else "no"), ("params written", args.output or "none")]
        write_report(args.report, calibration_of(fit, table, setup, args.units))
        if args.format == "text":
            print(f"wrote {args.report}")
    return 0
