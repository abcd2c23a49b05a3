"""``chaincomp simulate-log``: an lcm-logger log of commanded axes for a bundled machine."""

from __future__ import annotations

import sys

import lcm

from ..buildtree import import_lcmtypes
from ..errors import ChaincompError
from ..toolpath import toolpath
from .common import add_machine_argument, load


def add_parser(sub) -> None:
    p = sub.add_parser("simulate-log", help="write an lcm-logger log of commanded axes (a 5-axis toolpath)",
                       description="Write a log, playable with lcm-logplayer, of lcmt_axis_command messages "
                                   "along a smooth toolpath within the machine's limits (a circle with the "
                                   "tool tilted and turning), sampled at --rate.")
    add_machine_argument(p)
    p.add_argument("-o", "--output", required=True, metavar="OUT.lcmlog")
    p.add_argument("--rate", type=float, default=1000.0, help="samples per second (default 1000)")
    p.add_argument("--seconds", type=float, default=10.0, help="duration (default 10 s)")
    p.add_argument("--channel", default="CHAINCOMP_COMMAND", help="channel (default CHAINCOMP_COMMAND)")
    p.add_argument("--start-utime", type=int, default=1_700_000_000_000_000, help="first timestamp, µs")
    p.set_defaults(run=run)


def run(args) -> int:
    if args.rate <= 0 or args.seconds <= 0:
        raise ChaincompError("--rate and --seconds must be positive")
    machine = load(args.machine)
    types = import_lcmtypes()
    path = toolpath(machine, args.rate, args.seconds)
    try:
        log = lcm.EventLog(args.output, "w", overwrite=True)
    except (IOError, OSError) as exc:
        raise ChaincompError(f"cannot create {args.output!r}: {exc}") from None
    msg = types.lcmt_axis_command()
    msg.machine = machine.name
    msg.num_axes = len(machine.axes)
    step_us = 1e6 / args.rate
    for i, row in enumerate(path):
        msg.utime = args.start_utime + int(round(i * step_us))
        msg.seq = i + 1
        msg.axes = [float(v) for v in row] + [0.0] * (8 - len(row))
        log.write_event(msg.utime, args.channel, msg.encode())
        if i and i % 200000 == 0:
            print(f"simulate-log: {i}/{len(path)} records", file=sys.stderr)
    log.close()
    print(f"simulate-log: {len(path)} commands of {machine.name} at {args.rate:g} Hz -> {args.output}",
          file=sys.stderr)
    return 0
