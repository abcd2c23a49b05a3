"""``chaincomp replay``: a logged command stream through the daemon's compiled compensator."""

from __future__ import annotations

import os
import subprocess

from ..emit.buildtree import binary
from ..errors import ChaincompError
from ..output import staged
from .common import _same_file, add_format_argument, add_machine_argument, check_output, load


def add_parser(sub) -> None:
    p = sub.add_parser("replay", help="run a logged command stream through the compiled compensator",
                       description="Run every command of an lcm-logger log through the same compiled C++ "
                                   "compensator the daemon uses (same runtime settings: limits, ramp, "
                                   "rejections), and write a corrected log (the original records plus "
                                   "the corrected targets, original timestamps kept) and/or a CSV of "
                                   "event, utime, seq, result, commanded, corrected, correction, residuals, "
                                   "flags, status. Rejected records are listed and counted by reason; targets "
                                   "the limits clamped, those of them held back towards no correction, and "
                                   "commands clamped into limits are counted; the targets are counted as "
                                   "full, partial or uncorrected, with the objective (|point|^2 + "
                                   "(direction_weight * direction)^2) before and after; --format json prints that "
                                   "summary as one JSON object on standard output.")
    add_machine_argument(p, alias=True)
    p.add_argument("input", metavar="IN.lcmlog", help="lcm-logger log of commands")
    p.add_argument("--model", metavar="LIB.so", help="a model library made by chaincomp build for this machine file")
    p.add_argument("--params", required=True, metavar="P.yaml", help="error values (configs/params/*.yaml)")
    p.add_argument("--config", metavar="R.yaml", help="runtime settings, direction_weight among them (default: built-in "
                   "defaults)")
    p.add_argument("--thermal", metavar="T.yaml", help="a thermal model (chaincomp thermal fit): the log's "
                   "temperature readings drive its errors, as chaincompd --thermal does")
    p.add_argument("-o", "--output", metavar="OUT.lcmlog", help="corrected log")
    p.add_argument("--csv", metavar="OUT.csv", help="CSV of every command")
    p.add_argument("--channel", default="CHAINCOMP_COMMAND", help="command channel (default CHAINCOMP_COMMAND)")
    add_format_argument(p, what="summary format: text on standard error, or json on standard output")
    p.set_defaults(run=run)


def run(args) -> int:
    if os.path.isdir(args.input):
        raise ChaincompError(f"{args.input}: is a folder, expected a log file")
    if not os.path.isfile(args.input):
        raise ChaincompError(f"{args.input}: no such log file")
    load(args.machine)  # the machine's mistakes with file, line and field, as every verb reports them
    inputs = (args.input, args.machine, args.params, args.config, args.model, args.thermal)
    check_output(args.output, *inputs, option="-o")
    check_output(args.csv, *inputs, option="--csv")
    if args.csv and args.output and (os.path.abspath(args.csv) == os.path.abspath(args.output)
                                     or _same_file(args.csv, args.output)):
        raise ChaincompError(f"--csv {args.csv}: is also the -o output")
    outputs = {flag: path for flag, path in (("--out", args.output), ("--csv", args.csv)) if path}
    # the binary writes temporary files; they are put in place only when it succeeds
    with staged(*outputs.values()) as tmps:
        cmd = [binary("chaincomp_replay"), "--machine", args.machine, "--params", args.params, "--in", args.input,
               "--channel", args.channel]
        for flag, value in (("--config", args.config), *zip(outputs, tmps), ("--model", args.model),
                            ("--format", args.format), ("--thermal", args.thermal)):
            if value:
                cmd += [flag, value]
        code = subprocess.run(cmd).returncode
        if code != 0:   # the binary said why; leaving by an exception puts nothing in place
            raise SystemExit(code)
    return 0
