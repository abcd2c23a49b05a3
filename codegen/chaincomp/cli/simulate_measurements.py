"""``chaincomp simulate-measurements``: tool-tip coordinates of a machine with known errors."""

from __future__ import annotations

import itertools
import sys

import numpy as np

from ..errors import ChaincompError
from ..identify import read_table, simulate, write_table
from ..params import load_params, parse_sets
from .common import add_machine_argument, load
from .identify import length
from .protocol import names


def add_parser(sub) -> None:
    p = sub.add_parser("simulate-measurements",
                       help="write the tool-tip coordinates a machine with given errors would measure",
                       description="Evaluate the exact model with the error values of --params at each "
                                   "set-up, add Gaussian noise, and write a CSV that 'chaincomp identify' "
                                   "reads: one column per axis (declared unit), then the measured "
                                   "coordinates (the machine's length unit).")
    add_machine_argument(p)
    p.add_argument("--params", metavar="P.yaml", help="error values (errors not given are zero)")
    p.add_argument("--setups", default="grid:0,90,180,270", metavar="SPEC",
                   help="'grid:A,B,...' every rotary axis over these values (other axes at 0, or "
                        "mid-range, or --set), 'random:N' N set-ups uniform within the axis limits, "
                        "or a CSV file with a column per axis (default grid:0,90,180,270)")
    p.add_argument("--set", dest="sets", action="append", default=[], metavar="AXIS=VALUE",
                   help="value of an axis not on the grid")
    p.add_argument("--noise", default="0", metavar="LENGTH",
                   help="standard deviation of the noise on each coordinate, e.g. 1um (default 0)")
    p.add_argument("--measure", default="x,y,z", metavar="X,Y,Z", help="coordinates written (default x,y,z)")
    p.add_argument("--seed", type=int, default=0, help="random seed (default 0)")
    p.add_argument("-o", "--output", required=True, metavar="MEAS.csv", help="CSV file to write")
    p.set_defaults(run=run)


def setups(machine, spec: str, sets: list[str], rng) -> dict[str, np.ndarray]:
    """Axis values (internal units) per set-up."""
    fixed = parse_sets(sets, machine)
    for name in fixed:
        if machine.symbol(name).role != "axis":
            raise ChaincompError(f"--set: {name!r} is not an axis (constants and errors go in --params)")
    kind, _, arg = spec.partition(":")
    if kind == "grid" and arg:
        try:
            values = [float(v) for v in names(arg)]
        except ValueError:
            raise ChaincompError(f"--setups: expected grid:A,B,... with numbers, got {spec!r}") from None
        rotary = [s for s in machine.axes if s.unit.kind == "angle" and s.name not in fixed]
        lists = []
        for s in rotary:
            lo, hi = s.limits
            inside = [v for v in values if lo <= v <= hi]
            if len(inside) < len(values):
                print(f"chaincomp simulate-measurements: note: {s.name} values outside [{lo:g}, {hi:g}] "
                      f"left out", file=sys.stderr)
            lists.append([s.to_internal(v) for v in inside])
        rows = list(itertools.product(*lists))
        out = {s.name: np.array([r[i] for r in rows]) for i, s in enumerate(rotary)}
    elif kind == "random" and arg:
        try:
            n = int(arg)
        except ValueError:
            n = 0
        if n < 1:
            raise ChaincompError(f"--setups: expected random:N with N >= 1, got {spec!r}")
        out = {s.name: s.to_internal(rng.uniform(*s.limits, n)) for s in machine.axes if s.name not in fixed}
    else:
        out = read_table(spec, machine, coords_required=False).axes
        out = {k: v for k, v in out.items() if k not in fixed}
    count = len(next(iter(out.values()))) if out else 1
    for s in machine.axes:
        if s.name not in out:
            default = s.to_internal(s.default_position)
            out[s.name] = np.full(count, fixed.get(s.name, default))
    return out


def run(args) -> int:
    machine = load(args.machine)
    measure = [c.lower() for c in names(args.measure)]
    for c in measure:
        if c not in ("x", "y", "z"):
            raise ChaincompError(f"--measure: unknown coordinate {c!r} (expected x, y, z)")
    if not measure:
        raise ChaincompError("--measure: name at least one coordinate (x, y, z)")
    noise = length(machine, "--noise", args.noise)
    values = load_params(args.params, machine) if args.params else {}
    rng = np.random.default_rng(args.seed)
    axes = setups(machine, args.setups, args.sets, rng)
    # simulate at the axis values exactly as written (15 digits, declared units), so that
    # identify, reading them back, evaluates the model at the same angles
    axes = {k: machine.symbol(k).to_internal(np.array([float(f"{machine.symbol(k).from_internal(x):.15g}")
                                                        for x in v])) for k, v in axes.items()}
    coords = simulate(machine, values, axes, noise, rng, measure)
    comments = [f"chaincomp simulate-measurements {machine.name}: params {args.params or '(all errors zero)'}, "
                f"set-ups {args.setups}, noise {args.noise}, seed {args.seed}",
                f"axes in their declared units; x, y, z: tool tip in {machine.length_unit}"]
    try:
        write_table(args.output, machine, axes, coords, measure, comments)
    except OSError as exc:
        raise ChaincompError(f"cannot write: {exc.strerror}", args.output) from None
    return 0
