"""``chaincomp simulate-measurements``: tool-tip coordinates of a machine with known errors."""

from __future__ import annotations

import itertools
import math
import re
import sys

import numpy as np

from ..errors import ChaincompError
from ..measure.identify import simulate, simulate_orientations
from ..measure.table import (COMPONENTS, MAX_ROWS, QUATERNION, coordinate_named_axes, outside_limits, read_table,
                             write_table)
from ..measure.protocol import check_measure
from ..measure.protocol_linear import auto_levels
from ..model.expressions import MAX_LITERAL
from ..model.machine import Symbol
from ..model.params import load_params, parse_sets, parse_value
from ..model.units import UNITS
from .common import (add_machine_argument, add_seed_argument, check_output, length, load, names, number_list,
                     refuse_empty)

_SPECS = "'auto', 'grid:A,B,...', 'random:N' or a CSV file of set-ups"


def add_parser(sub) -> None:
    p = sub.add_parser("simulate-measurements",
                       help="write the tool-tip coordinates a machine with given errors would measure",
                       description="Evaluate the exact model with the error values of --params at each "
                                   "set-up, add Gaussian noise, and write a CSV that 'chaincomp identify' "
                                   "reads: one column per axis (declared unit), then the measured "
                                   "coordinates (the machine's length unit).")
    add_machine_argument(p)
    p.add_argument("--params", metavar="P.yaml", help="error values (errors not given are zero)")
    p.add_argument("--setups", "--set-ups", dest="setups", default="auto", metavar="SPEC",
                   help="'auto': every axis at its two limits and mid-range (a rotary axis whose limits "
                        "span a turn at 0, 90, 180, 270 deg instead), all combinations; 'grid:A,B,...': "
                        "every rotary axis over these values (in its declared unit), other axes at 0 (or "
                        "mid-range, or --set); "
                        "'random:N': N set-ups uniform within the axis limits; or a CSV file with a "
                        "column per axis (default auto)")
    p.add_argument("--set", dest="sets", action="append", default=[], metavar="AXIS=VALUE",
                   help="hold an axis at this value (within its limits) in every set-up")
    p.add_argument("--noise", default="0", metavar="LENGTH",
                   help="standard deviation of the noise on each coordinate, e.g. 1um (default 0)")
    p.add_argument("--angle-noise", default="0", metavar="ANGLE",
                   help="standard deviation of the noise on each component of the measured orientation's "
                        "rotation vector (about the base axes), e.g. 10arcsec (default 0); with q")
    p.add_argument("--measure", default="x,y,z", metavar="x,y,z",
                   help="coordinates written (default x,y,z); q (or qw,qx,qy,qz) adds the tool frame's "
                        "orientation (unit quaternion qw, qx, qy, qz), where the machine has a tool frame")
    add_seed_argument(p, "random seed of the noise and of random:N set-ups")
    p.add_argument("-o", "--output", required=True, metavar="MEAS.csv",
                   help="CSV file to write (never one of the inputs)")
    p.set_defaults(run=run)


def setups(machine, spec: str, sets: list[str], rng) -> dict[str, np.ndarray]:
    """Axis values (internal units) per set-up."""
    fixed = parse_sets(sets, machine)
    for name, value in fixed.items():
        s = machine.symbol(name)
        if s.role != "axis":
            raise ChaincompError(f"--set: {name!r} is not an axis (constants and errors go in --params)")
        lo, hi = s.limits
        if not lo <= s.from_internal(value) <= hi:
            raise ChaincompError(f"--set {name}: {s.from_internal(value):g} {s.unit.name} is outside the "
                                 f"axis' limits [{lo:g}, {hi:g}]")
    free = [s for s in machine.axes if s.name not in fixed]
    kind, colon, arg = spec.partition(":")
    if kind in ("auto", "grid", "random") and not any(s.limits[1] > s.limits[0] for s in free):
        # one pose repeated identifies nothing: refuse rather than write it without a word
        raise ChaincompError(f"--setups {spec}: no axis of {machine.name} is left to move "
                             + (f"(--set holds {', '.join(fixed)}" if fixed else "(")
                             + (f"; {', '.join(s.name for s in free)} cannot move within its limits" if free else "")
                             + "): every set-up would be the same pose; free an axis or give a set-ups file")
    levels = None
    if kind == "auto" and not colon:
        levels = {s.name: auto_levels(s) for s in free}
    elif kind == "grid" and arg:
        values = number_list("--setups", arg)
        rotary = [s for s in free if s.unit.kind == "angle"]
        if not rotary:
            raise ChaincompError(f"--setups {spec}: a grid turns the rotary axes, and {machine.name} has none "
                                 f"{'left free of --set ' if fixed else ''}(axes "
                                 f"{', '.join(s.name for s in machine.axes)}): use auto or random:N")
        levels = {}
        for s in rotary:
            lo, hi = s.limits
            inside = [v for v in values if lo <= v <= hi]
            if not inside:
                raise ChaincompError(f"--setups {spec}: no value within {s.name}'s limits [{lo:g}, {hi:g}]")
            if len(inside) < len(values):
                print(f"chaincomp simulate-measurements: note: {s.name} values outside [{lo:g}, {hi:g}] "
                      f"left out", file=sys.stderr)
            levels[s.name] = [s.to_internal(v) for v in inside]
    elif kind == "random" and arg:
        n = int(arg) if arg.isdigit() else 0
        if not 1 <= n <= MAX_ROWS:
            raise ChaincompError(f"--setups: expected random:N with 1 <= N <= {MAX_ROWS}, got {spec!r}")
        out = {s.name: s.to_internal(rng.uniform(*s.limits, n)) for s in free}
    elif kind in ("auto", "grid", "random"):
        raise ChaincompError(f"--setups: expected {_SPECS}, got {spec!r}")
    else:
        table = read_table(spec, machine, coords_required=False)
        for text in outside_limits(machine, table, skip=fixed):
            print(f"chaincomp simulate-measurements: warning: {text}", file=sys.stderr)
        out = table.axes
        out = {k: v for k, v in out.items() if k not in fixed}
    if levels is not None:
        count = math.prod(len(v) for v in levels.values())
        if count > MAX_ROWS:
            raise ChaincompError(f"--setups {spec}: {count} set-ups, more than {MAX_ROWS}: use random:N")
        rows = list(itertools.product(*levels.values()))
        out = {name: np.array([r[i] for r in rows]) for i, name in enumerate(levels)}
    count = len(next(iter(out.values()))) if out else 1
    for s in machine.axes:
        if s.name not in out:
            out[s.name] = np.full(count, fixed.get(s.name, s.to_internal(s.default_position)))
    return out


def _angle(raw: str) -> float:
    """--angle-noise: an angle with its unit (a bare number only if 0) -> rad, zero or positive."""
    try:
        value = parse_value(Symbol("--angle-noise", "constant", UNITS["rad"], ""), raw)
    except ValueError as exc:
        raise ChaincompError(f"--angle-noise: {exc}") from None
    if value != 0 and re.fullmatch(r"\s*[-+0-9.eE]+\s*", raw):
        raise ChaincompError(f"--angle-noise: give the unit, e.g. {raw.strip()}arcsec or {raw.strip()}rad, got {raw!r}")
    if value < 0:
        raise ChaincompError(f"--angle-noise: must be zero or positive, got {raw!r}")
    return value


def run(args) -> int:
    refuse_empty(("--params", args.params), hint="leave the option out for every error zero")
    refuse_empty(("--angle-noise", args.angle_noise))
    machine = load(args.machine)
    for s in coordinate_named_axes(machine):
        raise ChaincompError(f"axis {s.name!r} has the name of the measured coordinate {s.name}: the "
                             f"measurement file's column {s.name!r} would mean either; rename the axis",
                             machine.file, s.line, "symbols")
    is_file = args.setups.partition(":")[0] not in ("auto", "grid", "random")
    check_output(args.output, args.machine, args.params, args.setups if is_file else None)
    asked = names(args.measure)
    quaternion = [c for c in asked if c.lower() in ("q",) + QUATERNION]
    if quaternion and machine.tool_reference is None:
        raise ChaincompError(f"--measure {quaternion[0]}: {machine.name} has no tool frame (tool: reference or "
                             f"rotation in {machine.file}), so there is no orientation to measure")
    if quaternion and sorted({c.lower() for c in quaternion}) not in (["q"], sorted(QUATERNION)):
        raise ChaincompError(f"--measure: give the orientation as q or as all four of qw, qx, qy, qz, once, "
                             f"got {', '.join(quaternion)}")
    if quaternion and len(quaternion) not in (1, 4):
        raise ChaincompError(f"--measure: {', '.join(quaternion)}: the orientation named more than once")
    rest = [c for c in asked if c not in quaternion]
    measure = check_measure(rest) if rest or not quaternion else []
    noise = length(machine, "--noise", args.noise)
    angle_noise = _angle(args.angle_noise)
    if angle_noise and not quaternion:
        raise ChaincompError("--angle-noise: no orientation is measured (add q to --measure)")
    values = load_params(args.params, machine) if args.params else {}
    rng = np.random.default_rng(args.seed)
    axes = setups(machine, args.setups, args.sets, rng)
    # simulate at the axis values exactly as written (15 digits, declared units), so that
    # identify, reading them back, evaluates the model at the same angles
    axes = {k: machine.symbol(k).to_internal(np.array([float(f"{machine.symbol(k).from_internal(x):.15g}")
                                                        for x in v])) for k, v in axes.items()}
    count = len(next(iter(axes.values())))
    print(f"chaincomp simulate-measurements: {count} set-up{'s' if count != 1 else ''} ({args.setups}) "
          f"of {', '.join(s.name for s in machine.axes)}", file=sys.stderr)
    coords = simulate(machine, values, axes, noise, rng, measure)
    quats = simulate_orientations(machine, values, axes, angle_noise, rng) if quaternion else None
    measured = [COMPONENTS.index(c) for c in measure]
    bad = np.flatnonzero(~np.isfinite(coords[:, measured]).all(axis=1)
                         | (quats is not None and ~np.isfinite(quats).all(axis=1)))
    if bad.size:   # written as 'nan' cells, which identify then refuses line by line
        r = int(bad[0])
        at = ", ".join(f"{s.name} = {s.from_internal(axes[s.name][r]):g} {s.unit.name}" for s in machine.axes)
        raise ChaincompError(f"set-up {r + 1} ({at}) gives a tool {'point' if quats is None else 'pose'} "
                             f"that is not finite ({bad.size} of {count} set-ups): the machine's expressions "
                             "leave their domain there (e.g. sqrt or acos of an axis beyond its limits)")
    if not (np.abs(coords[~np.isnan(coords)]) <= MAX_LITERAL).all():
        raise ChaincompError(f"the simulated coordinates reach beyond {MAX_LITERAL:g} {machine.length_unit} "
                             f"(or are not finite), which identify would refuse: check --noise and the "
                             f"values in --params")
    comments = [f"chaincomp simulate-measurements {machine.name}: params {args.params or '(all errors zero)'}, "
                f"set-ups {args.setups}, noise {args.noise}"
                + (f", angle noise {args.angle_noise}" if quaternion else "") + f", seed {args.seed}",
                f"axes in their declared units; x, y, z: tool tip in {machine.length_unit}"
                + ("; qw, qx, qy, qz: the tool frame's orientation in the base frame (unit quaternion)"
                   if quaternion else "")]
    write_table(args.output, machine, axes, coords, measure, comments, quats)
    return 0
