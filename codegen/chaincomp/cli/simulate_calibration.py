"""``chaincomp simulate-calibration``: a synthetic laser calibration as a params file with tables."""

from __future__ import annotations

import shlex
import sys

import numpy as np

from ..measure import calibration
from ..model.params import load_params
from ..model.varying import INTERPOLATIONS, MAX_TABLE_KNOTS, OUTSIDE
from .common import add_deprecated, add_machine_argument, add_seed_argument, check_output, integer, load

# Plausible sizes of the errors that are not tabulated, without --params (internal units).
_CONSTANT_SCALE = {"length": 3e-3, "angle": 5 * calibration.ARCSEC, "ratio": 5e-6}


def add_parser(sub) -> None:
    p = sub.add_parser("simulate-calibration",
                       help="write a synthetic laser calibration: each slide's errors as tables over its travel",
                       description="Write a params file in which each slide's component errors (the error "
                                   "block right after the slide's translation in the chain) are tables over "
                                   "the slide's travel with smooth, plausible shapes: positioning (scale "
                                   "error and waves, µm), straightness (from the slide's tilts, best-fit "
                                   "line removed, µm), pitch, yaw and roll (arcsec). The other errors are "
                                   "constants from --params, or small random values. The file says it is "
                                   "synthetic.")
    add_machine_argument(p)
    p.add_argument("-o", "--output", required=True, metavar="P.yaml", help="params file to write")
    p.add_argument("--knots", type=integer(2, MAX_TABLE_KNOTS), default=101,
                   help=f"points per table, over the axis limits (2 to {MAX_TABLE_KNOTS}, default 101)")
    add_seed_argument(p)
    p.add_argument("--params", metavar="P.yaml", help="error values: constants for the errors that are not "
                   "tabulated")
    # --base names a URDF link in import-urdf and export-urdf
    add_deprecated(p, "--base", "--params", "params", metavar="P.yaml")
    p.add_argument("--interpolation", default="monotone_cubic", choices=INTERPOLATIONS,
                   help="interpolation written into each table (default monotone_cubic)")
    p.add_argument("--outside", default="hold", choices=OUTSIDE,
                   help="behaviour outside each table written into it (default hold)")
    p.set_defaults(run=run)


def run(args) -> int:
    check_output(args.output, args.machine, args.params)
    machine = load(args.machine)
    tables = calibration.simulate(machine, args.knots, args.seed)
    if args.params:
        constants = load_params(args.params, machine)
    else:
        rng = np.random.default_rng((args.seed + 1) % 2**32)
        constants = {s.name: float(np.round(rng.uniform(-1, 1) * _CONSTANT_SCALE[s.unit.kind]
                                            / s.unit.to_internal, 3)) * s.unit.to_internal
                     for s in machine.errors}
    command = ["chaincomp", "simulate-calibration", args.machine, "--knots", str(args.knots), "--seed",
               str(args.seed)] + (["--params", args.params] if args.params else []) + \
              ["--interpolation", args.interpolation, "--outside", args.outside, "-o", args.output]
    slides = calibration.find_slides(machine)
    header = [
        f"SYNTHETIC calibration of {machine.name}: made up by a program, not measured on any machine.",
        "Written by: " + " ".join(shlex.quote(c) for c in command),
        "Each slide's component errors as tables over its travel, shaped like a laser-interferometer",
        "calibration (ISO 230-1 component errors, ISO 230-2 style): positioning = scale error + waves,",
        "straightness = what the slide's pitch/yaw make of its travel, best-fit line removed,",
        "pitch/yaw/roll = bow + long waves; µm and arcsec. Slides:",
        *(f"  {s.axis}: {', '.join(c.error for c in s.components)}" for s in slides),
        "Other errors: " + (f"constants from {args.params}." if args.params else "small random constants."),
    ]
    calibration.write(args.output, machine, tables, constants, header, args.interpolation, args.outside)
    n = len(tables)
    print(f"simulate-calibration: {machine.name}: {n} tables of {args.knots} points over "
          f"{', '.join(s.axis for s in slides)} -> {args.output}", file=sys.stderr)
    return 0
