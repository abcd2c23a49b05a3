"""Entry point: dispatches to the verb modules; user errors exit 2 with one clear line, and
anything unexpected exits 3 with one line too (CHAINCOMP_DEBUG=1 shows the traceback)."""

from __future__ import annotations

import argparse
import importlib
import json
import os
import sys

import numpy as np

from .. import __version__
from ..errors import ChaincompError, NoAnswer, OutsideLimit
from ..escape import one_line
# Each verb's module, in the order of the top-level help. A command imports only its own verb's
# module (every module pulls in its own libraries: all of them together cost ~0.4 s per run).
VERB_MODULES = {
    "derive": "derive", "eval": "eval", "generate": "generate", "testvectors": "testvectors",
    "protocol": "protocol", "identify": "identify", "simulate-measurements": "simulate_measurements",
    "simulate-log": "simulate_log", "replay": "replay", "plot": "plot", "check": "check",
    "report": "report", "budget": "budget", "simulate-calibration": "simulate_calibration",
    "build": "build", "lint": "lint", "iso230-2": "iso230_2", "laser-to-params": "laser_to_params",
    "status": "status", "import-urdf": "import_urdf", "export-urdf": "export_urdf",
    "import-ur-calibration": "import_ur_calibration", "ballbar": "ballbar", "export": "export",
    "thermal": "thermal", "simulate-thermal": "simulate_thermal", "probe": "probe",
}


class _Parser(argparse.ArgumentParser):
    """argparse's errors as one line, like every other error (argparse prints the usage first)."""

    def error(self, message: str):
        self.exit(2, f"{self.prog}: error: {message} (see {self.prog} --help)\n")


class _VerbList(argparse.HelpFormatter):
    """Every verb and its help on one line: argparse measures the verbs' names at the indent of
    'VERB', two columns short of where it prints them, and wraps the longest ones."""

    def __init__(self, prog):
        super().__init__(prog, max_help_position=32, width=120)

    def add_argument(self, action):
        super().add_argument(action)
        if action.help is not argparse.SUPPRESS:
            self._action_max_length += 2


def build_parser(only: str | None = None) -> argparse.ArgumentParser:
    """The whole command line, or with ``only`` just that verb's (its module alone imported)."""
    parser = _Parser(
        prog="chaincomp",
        formatter_class=_VerbList,
        description="Geometric error models of machine tools: derive, evaluate and generate "
                    "compensation code from a machine description. The machine file is the first "
                    "argument of every verb that takes one; 'chaincomp VERB --help' lists its options.",
        epilog="Exit codes: 0 done, 1 a result outside a limit ('check' found differences, identify --strict), 2 bad input (one line naming the file, "
               "line and field, or the option), 3 internal error (one line; set CHAINCOMP_DEBUG=1 for the "
               "traceback), 4 no answer (a fit that does not converge, no daemon heard), 130 interrupted. With "
               "--format json an error is also one JSON object on stdout: {\"error\": {verb, kind, exit, message}}. "
               "The grammar of every option: docs/reference/grammar.md.")
    parser.add_argument("--version", action="version", version=f"chaincomp {__version__}",
                        help="print the version and exit")
    sub = parser.add_subparsers(dest="verb", metavar="VERB", required=True)
    for verb, module in VERB_MODULES.items():
        if only is None or verb == only:
            importlib.import_module(f"{__package__}.{module}").add_parser(sub)
    return parser


# Options whose values may start with '-' (e.g. --range -60:60), which argparse would
# otherwise take for an option.
_SIGNED_VALUE_OPTIONS = ("--range", "--range2", "--angles")


def _join_signed_values(argv: list[str]) -> list[str]:
    out: list[str] = []
    for token in argv:
        if out and out[-1] in _SIGNED_VALUE_OPTIONS and token.startswith("-"):
            out[-1] = f"{out[-1]}={token}"
        else:
            out.append(token)
    return out


def main(argv: list[str] | None = None) -> int:
    argv = sys.argv[1:] if argv is None else list(argv)
    parser = build_parser(argv[0] if argv and argv[0] in VERB_MODULES else None)
    from .common import hoist_machine_option   # filled by the verbs build_parser imported
    try:
        args = parser.parse_args(_join_signed_values(hoist_machine_option(argv)))
    except SystemExit as exc:   # --help, or a bad option (already reported in one line)
        return exc.code if isinstance(exc.code, int) else 0
    debug = os.environ.get("CHAINCOMP_DEBUG") == "1"
    action = getattr(args, "thermal_verb", None) or getattr(args, "probe_verb", None)
    if action:   # a verb of a group (thermal fit, probe plan): named as argparse names it
        args.verb = f"{args.verb} {action}"
    try:
        # numpy's warnings on nan and overflow would print formulas on stderr: the verbs
        # check their results and name what is not finite instead
        with np.errstate(all="ignore"):
            return args.run(args) or 0
    except OutsideLimit as exc:
        return _failed(args, "outside limit", f"error: {one_line(exc)}", 1)
    except NoAnswer as exc:
        return _failed(args, "no answer", f"error: {one_line(exc)}", 4)
    except ChaincompError as exc:
        return _failed(args, "bad input", f"error: {one_line(exc)}", 2)
    except KeyboardInterrupt:
        return _failed(args, "interrupted", "interrupted", 130)
    except BrokenPipeError:
        return 0
    except (MemoryError, RecursionError) as exc:
        if debug:
            raise
        # numpy's "cannot allocate" is a MemoryError too; both mean an input beyond this machine
        return _failed(args, "bad input", "error: the input is too large or too deeply nested to process "
                       f"({type(exc).__name__}); give smaller grids, counts or files", 2)
    except Exception as exc:   # a bug: one line, not a stack, for the user; the stack for developers
        if debug:
            raise
        return _failed(args, "internal error", f"internal error: {type(exc).__name__}: {one_line(exc)} "
                       "(please report this with the command line; CHAINCOMP_DEBUG=1 shows the traceback)", 3)


def _failed(args, kind: str, line: str, code: int) -> int:
    """The one line on stderr; in a JSON mode also one JSON object on stdout, so that a reader of
    the JSON always gets JSON (docs/reference/errors.md, exit codes)."""
    print(f"chaincomp {args.verb}: {line}", file=sys.stderr)
    if getattr(args, "format", None) == "json":   # --json is --format json in every verb
        print(json.dumps({"error": {"verb": args.verb, "kind": kind, "exit": code,
                                    "message": f"chaincomp {args.verb}: {line}"}}))
    return code


if __name__ == "__main__":
    sys.exit(main())
