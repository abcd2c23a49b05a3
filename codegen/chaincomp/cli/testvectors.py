"""``chaincomp testvectors``: reference values of a machine's model for the C++ tests."""

from __future__ import annotations

import math
import random

import mpmath

from ..errors import ChaincompError
from ..output import write_file
from ..symbolic.jets import JetModel
from ..symbolic.numeric import ExactModel
from .common import add_machine_argument, add_seed_argument, check_output, integer, load

# Realistic error sizes: lengths of a few µm, angles of a few arcsec (internal units).
_ERROR_SCALE = {"length": 5e-3, "angle": 20 * 4.8481368110953599e-06, "ratio": 20e-6}
# 40-digit arithmetic: 1000 vectors of five_axis_ac take 28 s (2 cores, 2026-12)
MAX_COUNT = 1000


def add_parser(sub) -> None:
    p = sub.add_parser("testvectors", help="write reference values of the exact and truncated models",
                       description="Random axes within limits and random errors of realistic size "
                                   "(µm, arcsec); for each, the exact pose and the order-1 and order-2 "
                                   "errors computed with 40-digit arithmetic. Plain text, one number per "
                                   "field, internal units (mm, rad).")
    add_machine_argument(p)
    p.add_argument("--count", type=integer(1, MAX_COUNT), default=50,
                   help=f"number of vectors (1 to {MAX_COUNT}, default 50)")
    add_seed_argument(p)
    p.add_argument("-o", "--output", required=True, metavar="FILE", help="file to write")
    p.set_defaults(run=run)


def run(args) -> int:
    check_output(args.output, args.machine)
    machine = load(args.machine)
    mpmath.mp.dps = 40
    rng = random.Random(args.seed)
    exact = ExactModel(machine)
    model = JetModel(machine, 2)
    params = [s for s in machine.symbols if s.role != "axis"]
    lines = [f"# chaincomp testvectors {machine.name}: count axes params pose_size; then per vector:",
             "# axes, params (kParams order), pose_exact, pose_nominal, error_order1, error_order2",
             f"{args.count} {len(machine.axes)} {len(params)} {3 + 3 * len(machine.tool_axes)}"]
    for _ in range(args.count):
        values = machine.nominal_values()
        for a in machine.axes:
            values[a.name] = a.to_internal(rng.uniform(*a.limits))
        for e in machine.errors:
            values[e.name] = rng.uniform(-1, 1) * _ERROR_SCALE[e.unit.kind]
        mp = {k: mpmath.mpf(v) for k, v in values.items()}
        zero = dict(mp, **{e.name: mpmath.mpf(0) for e in machine.errors})
        rows = [[values[a.name] for a in machine.axes], [values[s.name] for s in params]]
        # the generated Pose's layout: point, then direction and the frame's x axis where defined
        for pose in (exact.frame(mp, "mpmath"), exact.frame(zero, "mpmath")):
            rows.append([v for vector in pose if vector is not None for v in vector])
        rows += [model.pose_error(mp, k, "mpmath") for k in (1, 2)]
        if not all(math.isfinite(float(v)) for row in rows for v in row):
            at = ", ".join(f"{a.name} = {a.from_internal(values[a.name]):g}" for a in machine.axes)
            raise ChaincompError(f"the model is not finite at {at} (vector {len(lines) - 2}): the machine's "
                                 "expressions leave their domain within the axis limits", machine.file)
        lines.append(" ".join(" ".join(repr(float(v)) for v in row) for row in rows))
    write_file(args.output, "\n".join(lines) + "\n")
    return 0
