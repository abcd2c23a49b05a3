"""``chaincomp probe simulate``: a LinuxCNC probe log of a plan run on a machine with known
errors (docs/guide/probing.md); it only writes the log."""

from __future__ import annotations

import numpy as np

from ..errors import ChaincompError
from ..measure import probe as P
from ..model.machine import Symbol
from ..model.params import load_params, parse_value
from ..model.units import UNITS
from ..output import write_file
from .common import assignments, check_output, length, load, number_list, refuse_empty


def run_simulate(args) -> int:
    machine = load(args.machine)
    sphere = sphere_of(machine, args)
    check_output(args.output, args.machine, args.plan, args.params)
    noise = length(machine, "--noise", args.noise)
    touches = P.read_plan(args.plan, machine)
    values = {k: v for k, v in (load_params(args.params, machine) if args.params else {}).items()}
    backlash = {}
    for name, raw in assignments(args.backlash, "--backlash", "AXIS=ANGLE").items():
        if name not in {a.name for a in P.machine_axes(machine).rotary}:
            raise ChaincompError(f"--backlash {name}: not a rotary axis of {machine.name}")
        backlash[name] = parse_value(Symbol("--backlash", "constant", UNITS["deg"], ""), raw)
    log = P.simulate_log(machine, touches, values, sphere.centre, sphere, noise, np.random.default_rng(args.seed),
                         backlash)
    write_file(args.output, log)
    return 0


def add_sphere_arguments(p, what: str) -> None:
    p.add_argument("--sphere", required=True, metavar="X,Y,Z",
                   help=f"{what} centre of the calibration sphere in the workpiece frame (the machine's length unit)")
    p.add_argument("--radius", required=True, metavar="R", help="the sphere's radius (e.g. 12.5 or 12.5mm)")
    p.add_argument("--stylus", default="0", metavar="R",
                   help="the stylus ball's effective radius, as calibrated (default 0: the tool point is the touch)")


def sphere_of(machine, args) -> P.Sphere:
    refuse_empty(("--sphere", args.sphere), ("--radius", args.radius), ("--stylus", args.stylus))
    centre = number_list("--sphere", args.sphere)
    if len(centre) != 3:
        raise ChaincompError(f"--sphere: expected X,Y,Z (three numbers), got {args.sphere!r}")
    unit = UNITS[machine.length_unit].to_internal
    radius = length(machine, "--radius", args.radius, positive=True)
    stylus = length(machine, "--stylus", args.stylus)
    return P.Sphere(tuple(v * unit for v in centre), radius, stylus)
