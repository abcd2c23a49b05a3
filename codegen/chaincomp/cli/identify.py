"""``chaincomp identify``: error values from measured tool-tip coordinates (least squares)."""

from __future__ import annotations

from ..errors import ChaincompError
from ..identify import identify, params_yaml, read_table, to_json, to_text
from ..machine import Symbol
from ..params import parse_value
from ..protocol import check_errors
from ..units import UNITS
from .common import add_assume_zero_argument, add_format_argument, add_machine_argument, check_output, load, to_json as json_text
from .protocol import names


def length(machine, option: str, raw: str, positive: bool = False) -> float:
    """'1um', '0.001 mm' or a bare number in the machine's length unit -> mm, finite and >= 0
    (> 0 if ``positive``)."""
    try:
        value = parse_value(Symbol(option, "constant", UNITS[machine.length_unit], ""), raw)
    except ValueError as exc:
        raise ChaincompError(f"{option}: {exc}") from None
    if value < 0 or (positive and value == 0):
        raise ChaincompError(f"{option}: must be {'positive' if positive else 'zero or positive'}, got {raw!r}")
    return value


def add_parser(sub) -> None:
    p = sub.add_parser("identify", help="fit error values to measured tool-tip coordinates",
                       description="Least-squares fit of the machine's error values to tool-tip "
                                   "coordinates measured at known axis positions (Gauss-Newton on the "
                                   "exact model). MEAS.csv: '#' comments, a header row naming every axis "
                                   "exactly as the machine file spells it (values in its declared unit) "
                                   "and any of x, y, z (tool tip in the machine's length unit; an empty "
                                   "cell is not measured), one row per set-up. Reports each estimate with "
                                   "its standard uncertainty, the condition number, correlations above "
                                   "0.9, the errors these set-ups cannot identify, which get no value, and "
                                   "errors to assume zero so that the others can be. Refuses data that "
                                   "identify no error, or that leave no redundancy without --sigma.")
    add_machine_argument(p)
    p.add_argument("measurements", metavar="MEAS.csv", help="measured tool-tip coordinates")
    add_assume_zero_argument(p, "errors held at zero (not fitted)")
    p.add_argument("--sigma", metavar="LENGTH",
                   help="standard uncertainty of each measured coordinate, positive, e.g. 1um "
                        "(default: estimated from the residuals)")
    p.add_argument("-o", "--output", metavar="params.yaml",
                   help="write the identified values as a params file (for eval and chaincompd); "
                        "never one of the inputs")
    add_format_argument(p, what="report format")
    p.set_defaults(run=run)


def run(args) -> int:
    machine = load(args.machine)
    check_output(args.output, args.measurements, args.machine)
    assume = check_errors(machine, names(",".join(args.assume_zero)), "--assume-zero")
    sigma = length(machine, "--sigma", args.sigma, positive=True) if args.sigma is not None else None
    table = read_table(args.measurements, machine)
    fit = identify(machine, table, assume, sigma)
    if not fit.converged:
        raise ChaincompError(f"the fit did not converge in {fit.iterations} Gauss-Newton iterations "
                             f"(rms residual {fit.rms / UNITS[machine.length_unit].to_internal:.4g} "
                             f"{machine.length_unit}); no values given", args.measurements)
    print(json_text(to_json(fit, args.measurements)) if args.format == "json"
          else to_text(fit, args.measurements))
    if args.output:
        try:
            with open(args.output, "w", encoding="utf-8") as f:
                f.write(params_yaml(fit, args.measurements))
        except OSError as exc:
            raise ChaincompError(f"cannot write: {exc.strerror}", args.output) from None
        if args.format == "text":
            print(f"wrote {args.output}")
    return 0
