"""``chaincomp protocol``: the simplest measurement tests for each error (Freeman & Ford §5)."""

from __future__ import annotations

from ..errors import ChaincompError
from ..measure.pose_design import (DEFAULT_POSES, INDICES, MAX_POOL, MAX_POSES, design_json, design_poses, design_text,
                           is_arm, write_poses)
from ..measure.protocol import build_protocol, check_errors, check_measure, to_text
from ..measure.protocol import to_json as protocol_json
from ..measure.protocol_linear import build_linear_protocol, linear_only
from ..measure.protocol_linear import to_json as linear_json
from ..measure.protocol_linear import to_text as linear_text
from ..model.params import parse_sets
from .common import (DEFAULT_SEED, MAX_ORDER, add_assume_zero_argument, add_format_argument, add_machine_argument,
                     add_seed_argument, check_output, integer, load, names, number_list, to_json)


def add_parser(sub) -> None:
    p = sub.add_parser("protocol", help="plan the measurements that identify each error",
                       description="Plan a calibration. Machines with rotary axes: write the first-order "
                                   "tool-point equations at every set-up of the rotary axes over an angle "
                                   "grid, form the sum and the difference of every pair of set-ups for each "
                                   "measured coordinate, and find, error by error, the simplest equation "
                                   "(fewest unknowns, then fewest terms) given the errors already "
                                   "identified (Freeman & Ford). Machines with linear axes only: the laser "
                                   "runs per axis and channel, the body diagonals of ISO 230-6 and tracker "
                                   "points in the volume, with what each identifies (ranks from the model's "
                                   "gains). Arms (every axis revolute and 4 or more of them, or dh/mdh "
                                   "joints), or any machine with --poses N: N poses within the limits that "
                                   "maximise an observability index of the scaled identification Jacobian, "
                                   "reproducible by --seed, written as a set-ups CSV with -o.")
    add_machine_argument(p)
    p.add_argument("--angles", metavar="A,B,...",
                   help="values of every rotary axis, in its declared unit (default 0,90,180,270); "
                        "machines with rotary axes, without --poses")
    add_assume_zero_argument(p, "errors taken as zero (the paper sets DY = 0)")
    p.add_argument("--measure", default="x,y,z", metavar="X,Y,Z",
                   help="tool-tip coordinates that are measured (default x,y,z)")
    p.add_argument("--prefer", action="append", default=[], metavar="E1,E2",
                   help="when several errors can be isolated, take these first, in this order "
                        "(machines with rotary axes)")
    p.add_argument("--set", dest="sets", action="append", default=[], metavar="AXIS=VALUE",
                   help="value of an axis during the tests: a non-rotary axis over the angle grid, the axes "
                        "held during the laser runs, or a joint held in every pose (default 0, or mid-range)")
    p.add_argument("--order", type=integer(1, MAX_ORDER), default=1,
                   help="order of the equations: 1 (the tests are linear in the errors)")
    p.add_argument("--poses", type=integer(1, MAX_POSES), metavar="N",
                   help=f"design N poses (1 to {MAX_POSES}) within the axis limits that maximise --index "
                        f"(default {DEFAULT_POSES} for an arm)")
    p.add_argument("--index", choices=INDICES, default="min-sv",
                   help="with --poses: the observability index to maximise, min-sv (the smallest singular "
                        "value of the scaled Jacobian, default) or o1 (Borm & Menq: the geometric mean of the "
                        "singular values over the square root of N)")
    p.add_argument("--pool", type=integer(2, MAX_POOL), metavar="M",
                   help=f"with --poses: random candidate poses to choose from (default 20 N, at least 2000, "
                        f"at most {MAX_POOL})")
    add_seed_argument(p, "with --poses: random seed of the candidate pool")
    p.add_argument("-o", "--output", metavar="POSES.csv",
                   help="with --poses: write the poses as a set-ups CSV (axes in their declared units, empty "
                        "x, y, z columns to fill in) for 'simulate-measurements --setups' and 'identify'")
    add_format_argument(p)
    p.set_defaults(run=run)


def _only_with_poses(args) -> None:
    given = [o for o, v in (("--index", args.index != "min-sv"), ("--pool", args.pool is not None),
                            ("-o", args.output is not None), ("--seed", args.seed != DEFAULT_SEED)) if v]
    if given:
        raise ChaincompError(f"{given[0]}: only with --poses N (pose design)")


def run(args) -> int:
    if args.order != 1:
        raise ChaincompError(f"--order {args.order}: protocol equations are first order (--order 1): "
                             f"sums and differences isolate errors only when the equations are linear")
    machine = load(args.machine)
    fixed = {n: machine.symbol(n).from_internal(v) for n, v in parse_sets(args.sets, machine).items()}
    for n in fixed:
        if machine.symbol(n).role != "axis":
            raise ChaincompError(f"--set: {n!r} is not an axis (constants and errors are not set here)")
    assume = names(",".join(args.assume_zero), "--assume-zero")
    measure = names(args.measure, "--measure")
    if args.poses is not None or is_arm(machine):
        for option, given in (("--angles", args.angles is not None), ("--prefer", bool(args.prefer))):
            if given:
                raise ChaincompError(f"{option}: not with a pose design (--poses; arms get one by default)")
        return _poses(args, machine, fixed, assume, measure)
    _only_with_poses(args)
    if linear_only(machine):
        for option, given in (("--angles", args.angles is not None), ("--prefer", bool(args.prefer))):
            if given:
                raise ChaincompError(f"{option}: {machine.name} has no rotary axis (its protocol is laser runs, "
                                     f"diagonals and tracker points)")
        proto = build_linear_protocol(machine, measure, assume, fixed)
        print(to_json(linear_json(proto)) if args.format == "json" else linear_text(proto))
        return 0
    angles = list(dict.fromkeys(number_list("--angles", "0,90,180,270" if args.angles is None else args.angles)))
    proto = build_protocol(machine, angles, assume, measure, fixed, names(",".join(args.prefer), "--prefer"))
    print(to_json(protocol_json(proto)) if args.format == "json" else to_text(proto))
    return 0


def _poses(args, machine, fixed, assume, measure) -> int:
    check_output(args.output, args.machine)
    assume = check_errors(machine, assume, "--assume-zero")
    measure = check_measure(measure)
    for n, v in fixed.items():
        lo, hi = machine.symbol(n).limits
        if not lo <= v <= hi:
            raise ChaincompError(f"--set {n}: {v:g} {machine.symbol(n).unit.name} is outside the axis' limits "
                                 f"[{lo:g}, {hi:g}]")
    design = design_poses(machine, args.poses or DEFAULT_POSES, args.seed, args.index, measure, assume,
                          args.pool, fixed={n: machine.symbol(n).to_internal(v) for n, v in fixed.items()})
    if args.output:
        write_poses(args.output, design, f"chaincomp protocol {machine.name} --poses {len(design)} "
                                         f"--index {design.index} --seed {design.seed}")
    print(to_json(design_json(design, args.output)) if args.format == "json" else design_text(design, args.output))
    return 0
