"""``chaincomp report``: the machine's derived model as a Markdown or LaTeX document."""

from __future__ import annotations

import sys

from ..analysis import report
from ..errors import ChaincompError
from ..output import write_file
from ..symbolic.derive import derive
from .common import (DEFAULT_SEED, add_assume_zero_argument, add_format_argument, add_machine_argument,
                     add_order_argument, check_output, load, names)


def add_parser(sub) -> None:
    p = sub.add_parser("report", help="write the derived model as a document (Markdown or LaTeX)",
                       description="Write the symbol table, the chain as an equation, the nominal pose, "
                                   "the error formulas collected by error and axis factor, and the error "
                                   "gain matrix, as Markdown (default) or LaTeX.")
    add_machine_argument(p)
    add_order_argument(p, 1)
    p.add_argument("-o", "--output", metavar="FILE", help="write here (default: standard output)")
    add_format_argument(p, ("markdown", "latex"), None, "output format (latex for a .tex output, else markdown)")
    p.add_argument("--protocol", action="store_true",
                   help="append the measurement protocol (chaincomp protocol with its defaults)")
    add_assume_zero_argument(p, "with --protocol: errors taken as zero")
    p.set_defaults(run=run)


def run(args) -> int:
    check_output(args.output, args.machine)
    if args.assume_zero and not args.protocol:
        raise ChaincompError("--assume-zero goes with --protocol")
    machine = load(args.machine)
    d = derive(machine, args.order, progress=True)
    fmt = args.format or ("latex" if (args.output or "").lower().endswith(".tex") else "markdown")
    proto = None
    if args.protocol:
        from ..measure.plan import plan_text
        zero = names(",".join(args.assume_zero), "--assume-zero")
        proto = plan_text(machine, DEFAULT_SEED, zero)
    text = (report.latex if fmt == "latex" else report.markdown)(d, proto, progress=True)
    if not args.output:
        sys.stdout.write(text)
        return 0
    write_file(args.output, text)
    print(f"wrote {args.output} ({fmt}, {machine.name}, order {d.order})", file=sys.stderr)
    return 0
