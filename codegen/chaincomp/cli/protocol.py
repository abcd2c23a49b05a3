"""``chaincomp protocol``: the simplest measurement tests for each error (Freeman & Ford §5)."""

from __future__ import annotations

from ..errors import ChaincompError
from ..params import parse_sets
from ..protocol import build_protocol, to_text
from ..protocol import to_json as protocol_json
from .common import MAX_ORDER, add_assume_zero_argument, add_format_argument, add_machine_argument, integer, load, number_list, to_json


def names(text: str | None, option: str = "list") -> list[str]:
    """'A, B,C' -> ['A', 'B', 'C']; repeated options arrive joined by commas; an empty name
    ('A,,B', 'A,') is refused: it is a typo, not a request."""
    if not text:
        return []
    out = [t.strip() for t in text.split(",")]
    if not all(out):
        raise ChaincompError(f"{option}: empty name in {text!r}")
    return out


def add_parser(sub) -> None:
    p = sub.add_parser("protocol", help="find the simplest measurement tests for each error",
                       description="Write the first-order tool-point equations at every set-up of the "
                                   "rotary axes over an angle grid, form the sum and the difference of "
                                   "every pair of set-ups for each measured coordinate, and find, error "
                                   "by error, the simplest equation (fewest unknowns, then fewest terms) "
                                   "given the errors already identified. Reports assumed zeros, one line "
                                   "per test, simultaneous sets, and errors the set-ups cannot identify.")
    add_machine_argument(p)
    p.add_argument("--angles", default="0,90,180,270", metavar="A,B,...",
                   help="values of every rotary axis, in its declared unit (default 0,90,180,270)")
    add_assume_zero_argument(p, "errors taken as zero (the paper sets DY = 0)")
    p.add_argument("--measure", default="x,y,z", metavar="X,Y,Z",
                   help="tool-tip coordinates that are measured (default x,y,z)")
    p.add_argument("--prefer", action="append", default=[], metavar="E1,E2",
                   help="when several errors can be isolated, take these first, in this order")
    p.add_argument("--set", dest="sets", action="append", default=[], metavar="AXIS=VALUE",
                   help="value of a non-rotary axis during the tests (default 0, or mid-range)")
    p.add_argument("--order", type=integer(1, MAX_ORDER), default=1,
                   help="order of the equations: 1 (the tests are linear in the errors)")
    add_format_argument(p)
    p.set_defaults(run=run)


def run(args) -> int:
    if args.order != 1:
        raise ChaincompError(f"--order {args.order}: protocol equations are first order (--order 1): "
                             f"sums and differences isolate errors only when the equations are linear")
    angles = list(dict.fromkeys(number_list("--angles", args.angles)))
    machine = load(args.machine)
    fixed = {n: machine.symbol(n).from_internal(v) for n, v in parse_sets(args.sets, machine).items()}
    proto = build_protocol(machine, angles, names(",".join(args.assume_zero), "--assume-zero"),
                           names(args.measure, "--measure"), fixed, names(",".join(args.prefer), "--prefer"))
    print(to_json(protocol_json(proto)) if args.format == "json" else to_text(proto))
    return 0
