"""``chaincomp lint``: modelling mistakes that load but cannot be meant (chaincomp.lint)."""

from __future__ import annotations

import sys

from ..analysis.lint import lint
from ..errors import ChaincompError
from ..escape import one_line
from ..model.machine import load_machine
from .common import add_format_argument, add_machine_argument, to_json


def add_parser(sub) -> None:
    p = sub.add_parser("lint", help="check a machine file for modelling mistakes",
                       description="Load the machine (which refuses outright mistakes: unknown or unused "
                                   "symbols, expressions not finite, real and analytic in the errors at the "
                                   "nominal values) and warn about an error symbol or axis that never moves "
                                   "the tool point or direction. Every verb prints these warnings when it "
                                   "loads a machine; exit 0 with warnings, 2 with --strict. --format json prints "
                                   "the findings as one JSON object on standard output.")
    add_machine_argument(p)
    p.add_argument("--strict", action="store_true", help="exit 2 when there is any warning")
    add_format_argument(p)
    p.set_defaults(run=run)


def run(args) -> int:
    machine = load_machine(args.machine)
    findings = lint(machine)
    for f in findings:
        print(one_line(f"chaincomp lint: {f.level}: {machine.file}:{f}"), file=sys.stderr)
    if findings and args.strict:
        raise ChaincompError(f"{len(findings)} warning{'s' if len(findings) > 1 else ''} (--strict)",
                             machine.file)
    if args.format == "json":   # (a --strict refusal above prints the error object instead)
        print(to_json({"machine": machine.name, "file": machine.file,
                       "findings": [{"level": f.level, "line": f.line, "field": f.field, "message": f.message}
                                    for f in findings]}))
    if not findings and args.format != "json":
        print(one_line(f"{machine.file}: {machine.name}: no findings"))
    return 0
