"""``chaincomp simulate-thermal``: a synthetic log of temperatures and drift from a known
thermal model, for trying ``thermal fit`` and for its tests."""

from __future__ import annotations

import shlex
import sys

from ..errors import ChaincompError
from ..escape import one_line
from ..measure import thermal as T
from ..output import write_file
from .common import add_deprecated, add_machine_argument, add_seed_argument, check_output, load, number

MAX_SAMPLES = T.MAX_ROWS


def add_parser(sub) -> None:
    p = sub.add_parser("simulate-thermal", help="a synthetic warm-up log (temperatures and drift) from a known model",
                       description="Run a simulated machine through a spindle duty cycle: each of five sensors "
                                   f"({', '.join(s.name for s in T.DEFAULT_SENSORS)}) follows the hall's "
                                   "temperature and the spindle's heat through its own lags, and each error of "
                                   "--truth drifts as the model says (computed on a step ten times finer than "
                                   "--rate, then sampled). Noise is added to both. The CSV is what 'chaincomp "
                                   "thermal fit' reads.")
    add_machine_argument(p)
    p.add_argument("--truth", metavar="TRUE.yaml", help="the true thermal model (its sensors among the simulated "
                   "ones); required")
    # --model names a compiled library elsewhere (replay, chaincompd)
    add_deprecated(p, "--model", "--truth", "truth", metavar="TRUE.yaml")
    p.add_argument("-o", "--output", required=True, metavar="LOG.csv", help="log to write")
    p.add_argument("--cycle", default="warmup", metavar="CYCLE",
                   help=f"spindle duty: {' or '.join(T.CYCLES)} (default warmup), or DUTY:SECONDS,... with duty "
                        "from 0 to 1, e.g. 1:3600,0:1800")
    p.add_argument("--rate", type=number(0, 10, above=True), default=1.0, help="readings per second (default 1, "
                   "at most 10)")
    p.add_argument("--temperature-noise", type=number(0, 10), default=0.02, metavar="K",
                   help="standard deviation of each temperature reading (default 0.02 K)")
    p.add_argument("--drift-noise", type=number(0, 1e3), default=0.3, metavar="SIGMA",
                   help="standard deviation of each drift reading, um for a length error, arcsec for an angle, "
                        "ppm for a ratio (default 0.3)")
    p.add_argument("--hall", default="default", metavar="SWINGS",
                   help="the hall's climate about 20 degC: AMPLITUDE:PERIOD,... (K, s), e.g. 2:86400,1:7200 "
                        "(default " + ",".join(f"{a:g}:{q:g}" for a, q in T.HALL[1]) + "); phases from --seed")
    p.add_argument("--sensor-lags", type=number(0, 100, above=True), default=1.0, metavar="SCALE",
                   help="each simulated sensor's own time constants (of the spindle's heat and of the hall's "
                        "temperature) times this (default 1)")
    add_seed_argument(p, "random seed of the noise and the hall's swings")
    p.set_defaults(run=run)


def run(args) -> int:
    if not args.truth:
        raise ChaincompError("--truth TRUE.yaml: the true thermal model is needed")
    check_output(args.output, args.machine, args.truth)
    machine = load(args.machine)
    model = T.load_model(args.truth, machine)
    known = {s.name for s in T.DEFAULT_SENSORS}
    for s in model.sensors:
        if s not in known:
            raise ChaincompError(f"sensor {s} is not simulated (sensors: {', '.join(sorted(known))})", args.truth)
    cycle = T.parse_cycle(args.cycle)
    duration = sum(s for _, s in cycle)
    if duration * args.rate + 1 > MAX_SAMPLES:
        raise ChaincompError(f"--cycle {duration:g} s at --rate {args.rate:g}: more than {MAX_SAMPLES} readings")
    if duration * args.rate < 9:
        raise ChaincompError(f"--cycle {duration:g} s at --rate {args.rate:g}: fewer than 10 readings")
    hall = T.parse_hall(args.hall)
    t, temps, drift = T.simulate(model, T.sensors_with_lags(args.sensor_lags), cycle, args.rate,
                                 args.temperature_noise, args.drift_noise, args.seed, hall=hall)
    header = ["time [s]"] + [f"{n} [degC]" for n in temps] + [f"{n} [{model.errors[n].unit.name}]" for n in drift]
    command = ["chaincomp", "simulate-thermal", args.machine, "--truth", args.truth, "-o", args.output,
               "--cycle", args.cycle, "--rate", f"{args.rate:g}", "--seed", str(args.seed), "--hall", args.hall,
               "--sensor-lags", f"{args.sensor_lags:g}"]
    lines = [f"# Written by: {one_line(' '.join(shlex.quote(c) for c in command))}",
             f"# {len(t)} readings over {duration:g} s; temperature noise {args.temperature_noise:g} K, drift noise "
             f"{args.drift_noise:g} (um or arcsec)", ",".join(header)]
    columns = [t] + list(temps.values()) + list(drift.values())
    for k in range(len(t)):
        lines.append(",".join(f"{c[k]:.6f}" if i else f"{c[k]:.3f}" for i, c in enumerate(columns)))
        if k and k % 200000 == 0:
            print(f"simulate-thermal: {k}/{len(t)} rows", file=sys.stderr)
    write_file(args.output, "\n".join(lines) + "\n")
    print(f"simulate-thermal: {len(t)} readings of {len(temps)} sensors and {len(drift)} drift columns of "
          f"{machine.name} -> {args.output}", file=sys.stderr)
    return 0
