"""``chaincomp simulate-log``: an lcm-logger log of commanded axes for a bundled machine."""

from __future__ import annotations

import argparse
import os
import sys

import lcm

from ..emit.buildtree import import_lcmtypes
from ..errors import ChaincompError
from ..measure.toolpath import MAX_SAMPLES, toolpath
from ..output import staged
from .common import add_machine_argument, check_output, integer, load, number


MAX_CHANNEL = 63           # liblcm: LCM_MAX_CHANNEL_NAME_LENGTH
MAX_AXES = 8               # lcmt_axis_command.axes, runtime kMaxAxes
MAX_UTIME = 2**62          # int64 µs, with room for any duration after it
_LOG_HEADER = 28           # an LCM log event: sync word, event number, utime, channel and data lengths


def channel(text: str) -> str:
    if not 1 <= len(text.encode()) <= MAX_CHANNEL or not text.isprintable() or text.strip() != text:
        raise argparse.ArgumentTypeError(f"expected 1 to {MAX_CHANNEL} printable characters without leading or "
                                         f"trailing spaces, got {text!r}")
    return text


def add_parser(sub) -> None:
    p = sub.add_parser("simulate-log", help="write an lcm-logger log of commanded axes (a 5-axis toolpath)",
                       description="Write a log, playable with lcm-logplayer, of lcmt_axis_command messages "
                                   "along a smooth toolpath within the machine's limits (a circle with the "
                                   "tool tilted and turning), sampled at --rate.")
    add_machine_argument(p)
    p.add_argument("-o", "--output", required=True, metavar="OUT.lcmlog", help="log file to write")
    # timestamps are whole µs: above 1 MHz two samples would share one
    p.add_argument("--rate", type=number(0, 1e6, above=True), default=1000.0,
                   help="samples per second (up to 1e6, default 1000)")
    p.add_argument("--seconds", type=number(0, 1e9, above=True), default=10.0,
                   help=f"duration (default 10 s; at most {MAX_SAMPLES} samples in all)")
    p.add_argument("--channel", type=channel, default="CHAINCOMP_COMMAND",
                   help=f"channel, 1 to {MAX_CHANNEL} characters (default CHAINCOMP_COMMAND)")
    p.add_argument("--start-utime", type=integer(0, MAX_UTIME), default=1_700_000_000_000_000,
                   help="first timestamp, µs since 1970 (0 to 2^62)")
    p.set_defaults(run=run)


def run(args) -> int:
    check_output(args.output, args.machine)
    machine = load(args.machine)
    if len(machine.axes) > MAX_AXES:
        raise ChaincompError(f"{machine.name} has {len(machine.axes)} axes; lcmt_axis_command carries {MAX_AXES}",
                             machine.file)
    types = import_lcmtypes()
    path = toolpath(machine, args.rate, args.seconds)
    # liblcm's writer ignores a failed write (a full disk, /dev/full): count the bytes instead
    with staged(args.output) as (target,):
        try:
            log = lcm.EventLog(target, "w", overwrite=True)
        except (IOError, OSError) as exc:
            raise ChaincompError(f"cannot create {args.output!r}: {exc}") from None
        msg = types.lcmt_axis_command()
        msg.machine = machine.name
        msg.num_axes = len(machine.axes)
        step_us = 1e6 / args.rate
        expected = 0
        try:
            for i, row in enumerate(path):
                msg.utime = args.start_utime + int(round(i * step_us))
                msg.seq = i + 1
                msg.axes = [float(v) for v in row] + [0.0] * (8 - len(row))
                data = msg.encode()
                log.write_event(msg.utime, args.channel, data)
                expected += _LOG_HEADER + len(args.channel.encode()) + len(data)
                if i and i % 200000 == 0:
                    print(f"simulate-log: {i}/{len(path)} records", file=sys.stderr)
        except OSError as exc:   # liblcm reports some failures (a file too large), not all (a full disk)
            log.close()
            raise ChaincompError(f"cannot write: {exc.strerror}", args.output) from None
        log.close()
        written = os.path.getsize(target)
        if written != expected:   # never a short log that replay would read as the whole run
            raise ChaincompError(f"cannot write: {written} of {expected} bytes written (is the disk full?)",
                                 args.output)
    print(f"simulate-log: {len(path)} commands of {machine.name} at {args.rate:g} Hz -> {args.output}",
          file=sys.stderr)
    return 0
