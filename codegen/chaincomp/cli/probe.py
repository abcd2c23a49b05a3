"""``chaincomp probe plan|fit|simulate``: sphere probing of the rotary axes' location errors
(docs/guide/probing.md)."""

from __future__ import annotations

import shlex
import sys

from ..analysis.calibration_report import write_report
from ..errors import ChaincompError
from ..measure import probe as P
from ..measure.calibration import _write_loadable
from ..measure.identify import held_values
from ..measure.identify_report import params_yaml
from ..measure.protocol import check_errors
from ..model.machine import Symbol
from ..model.params import parse_value
from ..model.units import UNITS
from ..output import write_files
from .calibration_report import calibration_of_probe, check_report
from .common import (add_assume_zero_argument, add_format_argument, add_hold_argument, add_machine_argument,
                     add_seed_argument, check_output, length, load, names, number, to_json)
from .probe_simulate import add_sphere_arguments, run_simulate, sphere_of


def add_parser(sub) -> None:
    p = sub.add_parser("probe", help="sphere probing of the rotary axes: plan a probing program, fit its logs",
                       description="Calibrate the rotary axes' location errors with a touch probe and a sphere on "
                                   "the table (the KinematicsOpt / CYCLE996 kind): plan the positions and a "
                                   "LinuxCNC program, fit the probe logs (docs/guide/probing.md).")
    verbs = p.add_subparsers(dest="probe_verb", metavar="ACTION", required=True)
    pl = verbs.add_parser("plan", help="rotary positions and a probing program (LinuxCNC G-code and CSV)",
                          description="Choose rotary positions within the limits (a grid over each rotary axis, or "
                                      "--positions), put the probe on the sphere by the nominal model's inverse "
                                      "kinematics, judge the set (the condition number and the uncertainties a fit "
                                      "would have at 1 um per centre coordinate; a near-singular set is refused, "
                                      "exit 4) and write a LinuxCNC program (G38.2 touches, PROBEOPEN log) and a "
                                      "CSV plan of every touch.")
    add_machine_argument(pl)
    add_sphere_arguments(pl, "nominal")
    pl.add_argument("--positions", metavar="A=V,B=V;...",
                    help="rotary positions, separated by ';', each every rotary axis = value in its declared unit "
                         "(default: a grid of --per-axis values of each)")
    pl.add_argument("--per-axis", type=int, default=P.DEFAULT_PER_AXIS, choices=range(2, 13), metavar="K",
                    help=f"values per rotary axis of the default grid (2 to 12, default {P.DEFAULT_PER_AXIS})")
    pl.add_argument("--backlash-step", metavar="ANGLE",
                    help="also approach every position from above, coming back this far (e.g. 2deg): the fit "
                         "reports each rotary axis' backlash")
    pl.add_argument("--clearance", default=str(P.DEFAULT_CLEARANCE), metavar="LENGTH",
                    help=f"start this far off the surface and aim as far past it (default {P.DEFAULT_CLEARANCE:g})")
    pl.add_argument("--feed", type=number(0, 10_000, above=True), default=100.0, metavar="F",
                    help="the probing feed in mm/min (default 100)")
    pl.add_argument("--log-name", default="probe-log.txt", metavar="NAME",
                    help="the file PROBEOPEN opens (beside LinuxCNC's INI file; default probe-log.txt)")
    pl.add_argument("--gcode", metavar="OUT.ngc", help="write the LinuxCNC program")
    pl.add_argument("--csv", metavar="OUT.csv", help="write the plan: every touch, for any controller")
    add_hold_argument(pl)
    add_assume_zero_argument(pl)
    add_format_argument(pl)
    pl.set_defaults(run=run_plan)

    f = verbs.add_parser("fit", help="sphere centres and the rotary axes' location errors from probe logs",
                         description="Read the logs (LinuxCNC's probe log; or a CSV of touched points or of sphere "
                                     "centres, docs/guide/probing.md), fit each position's sphere centre (a probed "
                                     "radius off the nominal is refused, exit 4), and identify the errors with the "
                                     "sphere's position as nuisance parameters; the errors a sphere cannot see are "
                                     "found, held at zero and explained; a near-singular fit is refused (exit 4). "
                                     "Reports the dispersion of the centres before and after, per rotary axis, the "
                                     "estimates with uncertainties, correlations and the backlash where measured.")
    add_machine_argument(f)
    f.add_argument("logs", metavar="LOG", nargs="+", help="probe logs: LinuxCNC's (any name), or .csv files")
    add_sphere_arguments(f, "the nominal")
    f.add_argument("--plan", metavar="PLAN.csv", help="the plan the LinuxCNC logs ran (probe plan --csv): each "
                   "touch's position and approach; without it consecutive touches at the same rotary values are one "
                   "position")
    f.add_argument("--radius-tolerance", default=str(P.DEFAULT_RADIUS_TOLERANCE), metavar="LENGTH",
                   help=f"refuse a probed sphere radius further than this from --radius (default "
                        f"{P.DEFAULT_RADIUS_TOLERANCE:g})")
    add_hold_argument(f)
    add_assume_zero_argument(f)
    f.add_argument("-o", "--output", metavar="params.yaml",
                   help="write the identified errors as a params file of the machine (the sphere left out), for "
                        "eval, export and chaincompd; never one of the inputs")
    f.add_argument("--report", metavar="OUT.html",
                   help="also write a calibration report: one self-contained HTML file (set-up, the positions "
                        "probed, each centre's residual before and after, dispersion per rotary axis, values with "
                        "uncertainties and correlations, backlash, what a sphere cannot see, figures)")
    add_format_argument(f)
    f.set_defaults(run=run_fit)

    s = verbs.add_parser("simulate", help="a LinuxCNC probe log of a plan run on a machine with known errors",
                         description="Run the plan's touches on the machine with the errors of --params (the true "
                                     "machine) and the sphere at --sphere (its true centre): each G38.2 move stops "
                                     "where the stylus first touches the sphere; Gaussian noise on the logged "
                                     "linear coordinates. For tests and for trying a plan.")
    add_machine_argument(s)
    s.add_argument("plan", metavar="PLAN.csv", help="the plan (probe plan --csv)")
    add_sphere_arguments(s, "the true")
    s.add_argument("--params", metavar="P.yaml", help="the true machine's errors (default none)")
    s.add_argument("--noise", default="0.001", metavar="LENGTH", help="standard deviation of each logged coordinate "
                   "(default 0.001, 1 um in mm)")
    s.add_argument("--backlash", action="append", default=[], metavar="AXIS=ANGLE",
                   help="a rotary axis' lost motion (e.g. C=20arcsec; repeatable)")
    add_seed_argument(s)
    s.add_argument("-o", "--output", required=True, metavar="LOG", help="the probe log to write")
    s.set_defaults(run=run_simulate)   # a verb that only writes: in a module that prints nothing


def _held(machine, path: str | None, assume=()) -> dict:
    return held_values(machine, path, assume)


def _command() -> str:
    return "chaincomp " + " ".join(shlex.quote(a) for a in sys.argv[1:])


def run_plan(args) -> int:
    machine = load(args.machine)
    sphere = sphere_of(machine, args)
    for out in (args.gcode, args.csv):
        check_output(out, args.machine, args.hold, option="--gcode" if out == args.gcode else "--csv")
    if args.gcode and args.csv and args.gcode == args.csv:
        raise ChaincompError("--gcode and --csv name the same file")
    axes = P.machine_axes(machine)
    positions = P.parse_positions(machine, axes, args.positions) if args.positions is not None else None
    step = 0.0
    if args.backlash_step is not None:
        step = parse_value(Symbol("--backlash-step", "constant", UNITS["deg"], ""), args.backlash_step)
        if not 0 < step <= UNITS["deg"].to_internal * 30:
            raise ChaincompError(f"--backlash-step: expected an angle above 0 and at most 30 deg, got "
                                 f"{args.backlash_step!r}")
    clearance = length(machine, "--clearance", args.clearance, positive=True)
    assume = check_errors(machine, names(",".join(args.assume_zero)), "--assume-zero")
    plan = P.make_plan(machine, sphere, positions, args.per_axis, step, clearance, _held(machine, args.hold, assume),
                       assume)
    files = {}
    if args.gcode:
        files[args.gcode] = P.gcode(plan, args.log_name, args.feed, _command())
    if args.csv:
        files[args.csv] = P.plan_csv(plan, _command())
    write_files(files)
    if args.format == "json":
        f = plan.valuation.fit
        print(to_json({"machine": machine.name, "positions": [{n: machine.symbol(n).from_internal(v)
                                                                for n, v in p.items()} for p in plan.positions],
                       "touches": len(plan.touches), "condition_number": f.condition, "rank": f.rank,
                       "uncertainty_per_um": {n: {"value": g, "unit": u} for n, (g, u) in P.noise_gain(f).items()},
                       "unidentifiable": P.gauge_explanations(machine, plan.valuation),
                       "units": "internal (mm, rad)", "notes": plan.notes, "written": list(files)}))
    else:
        print(P.plan_text(plan, list(files)))
    return 0


def run_fit(args) -> int:
    machine = load(args.machine)
    sphere = sphere_of(machine, args)
    check_output(args.output, args.machine, args.plan, args.hold, *args.logs)
    check_report(args.report, args.output, args.machine, args.plan, args.hold, *args.logs)
    tolerance = length(machine, "--radius-tolerance", args.radius_tolerance, positive=True)
    plan = P.read_plan(args.plan, machine) if args.plan else None
    assume = check_errors(machine, names(",".join(args.assume_zero)), "--assume-zero")
    held = _held(machine, args.hold, assume)
    groups = P.read_logs(args.logs, machine, plan)
    pf = P.probe_fit(machine, groups, sphere, held, assume, tolerance)
    source = ", ".join(args.logs)
    print(to_json(P.to_json(pf, source)) if args.format == "json" else P.to_text(pf, source))
    if args.output:
        _write_loadable(args.output, params_yaml(P.production_fit(pf), f"sphere probing: {source}", held), machine)
        if args.format == "text":
            print(f"wrote {args.output}")
    if args.report:
        write_report(args.report, calibration_of_probe(pf, source))
        if args.format == "text":
            print(f"wrote {args.report}")
    return 0
