"""Pieces shared by the verbs: loading a machine with its values."""

from __future__ import annotations

import argparse
import json
import math
import os
import re
import sys

from ..errors import ChaincompError
from ..escape import one_line
from ..model.machine import Machine, Symbol, load_machine
from ..model.numbers import parse_number
from ..model.params import load_params, parse_sets, parse_value
from ..model.units import UNITS


# Older spellings of options (docs/reference/cli.md, "Deprecated spellings"): accepted, with a
# warning naming the new one, until this release removes them.
REMOVED_IN = "0.3.0"


class DeprecatedAlias(argparse.Action):
    """An older spelling: stores its value as ``replacement`` does (appends with append=True),
    after one warning on stderr."""

    def __init__(self, option_strings, dest, replacement: str, append: bool = False, **kwargs):
        self.replacement, self.append = replacement, append
        kwargs.setdefault("help", f"deprecated spelling of {replacement} (removed in {REMOVED_IN})")
        super().__init__(option_strings, dest, **kwargs)

    def warn(self, parser, option_string) -> None:
        print(f"{parser.prog}: warning: {option_string} is deprecated and will be removed in {REMOVED_IN}: "
              f"use {self.replacement}", file=sys.stderr)

    def __call__(self, parser, namespace, values, option_string=None):
        self.warn(parser, option_string)
        if self.append:
            values = [*(getattr(namespace, self.dest, None) or []), values]
        setattr(namespace, self.dest, values)


def add_deprecated(p, old: str, replacement: str, dest: str, **kwargs) -> None:
    """``old`` kept as an older spelling of ``replacement`` (same dest, same type)."""
    p.add_argument(old, dest=dest, action=DeprecatedAlias, replacement=replacement, **kwargs)


# Verbs whose machine file was once --machine: main() moves that option's value to the first
# argument before parsing (hoist_machine_option), so the file stays a required positional and
# argparse never has an optional positional before another (which made "replay M.yaml --model
# LIB IN.lcmlog" fail: argparse gave the first chunk M.yaml to IN.lcmlog).
MACHINE_ONCE_AN_OPTION: set[str] = set()


def add_machine_argument(p, optional: bool = False, alias: bool = False) -> None:
    """The machine file, the first positional argument of every verb that takes one. alias: also
    --machine (the older spelling of replay and laser-to-params), moved into place by
    hoist_machine_option; it stays in the parser for --help and the grammar's walk."""
    p.add_argument("machine", metavar="MACHINE.yaml", nargs="?" if optional else None,
                   help="machine description (configs/machines/*.yaml)")
    if alias:
        MACHINE_ONCE_AN_OPTION.add(p.prog.split()[-1])
        add_deprecated(p, "--machine", "the first argument (MACHINE.yaml)", "machine_option", metavar="MACHINE.yaml")


def hoist_machine_option(argv: list[str]) -> list[str]:
    """``VERB ... --machine M ...`` as ``VERB M ...`` with the deprecation warning, for the verbs
    of MACHINE_ONCE_AN_OPTION; any other command line unchanged. A file given twice becomes two
    arguments, which argparse refuses as it refuses any extra argument."""
    if not argv or argv[0] not in MACHINE_ONCE_AN_OPTION:
        return argv
    rest, found = [], []
    tokens = iter(argv[1:])
    for token in tokens:
        if token == "--":
            rest += [token, *tokens]
        elif token == "--machine":
            found.append(next(tokens, None))
        elif token.startswith("--machine="):
            found.append(token.split("=", 1)[1])
        else:
            rest.append(token)
    if not found or None in found:   # none, or one without its value: argparse says which
        return argv
    print(f"chaincomp {argv[0]}: warning: --machine is deprecated and will be removed in {REMOVED_IN}: "
          f"use the first argument (MACHINE.yaml)", file=sys.stderr)
    return [argv[0], *found, *rest]


def add_format_argument(p, choices: tuple[str, ...] = ("text", "json"), default: str | None = "text",
                        what: str = "output format") -> None:
    """--format, the same in every verb; --json kept as an alias of --format json."""
    shown = f" (default {default})" if default else ""
    p.add_argument("--format", choices=choices, default=default, help=f"{what}{shown}")
    if "json" in choices:
        p.add_argument("--json", dest="format", action="store_const", const="json",
                       help="the same as --format json")


class _FormatOrController(argparse.Action):
    """--format text|json; a controller's name there is the older spelling of --controller."""

    def __call__(self, parser, namespace, values, option_string=None):
        if values in ("text", "json"):
            namespace.format = values
            return
        print(f"{parser.prog}: warning: {option_string} {values} is deprecated and will be removed in {REMOVED_IN}: "
              f"use --controller {values} (--format is text or json)", file=sys.stderr)
        namespace.target = values


def add_controller_arguments(p, controllers: tuple[str, ...]) -> None:
    """--controller (the format a controller reads; required, checked by require_controller) and
    --format text|json for the report, as in every verb. Older spellings: --format CONTROLLER,
    --report text|json."""
    p.add_argument("--controller", dest="target", choices=controllers, help="the controller's format (required)")
    p.add_argument("--format", choices=("text", "json") + controllers, default="text", metavar="{text,json}",
                   action=_FormatOrController, help="report format (default text)")
    p.add_argument("--json", dest="format", action="store_const", const="json", help="the same as --format json")
    add_deprecated(p, "--report", "--format", "format", choices=("text", "json"))


def require_controller(args, controllers: tuple[str, ...]) -> None:
    if not args.target:
        raise ChaincompError(f"--controller: the controller's format is needed (one of {', '.join(controllers)})")


# A seed of 1 in every verb: one default, so that one verb's output reproduces another's.
DEFAULT_SEED = 1


def add_seed_argument(p, what: str = "random seed") -> None:
    p.add_argument("--seed", type=seed, default=DEFAULT_SEED,
                   help=f"{what} (0 to 2^32-1, default {DEFAULT_SEED})")


def add_assume_zero_argument(p, what: str = "errors held at zero") -> None:
    p.add_argument("--assume-zero", action="append", default=[], metavar="E1,E2",
                   help=f"{what}: names separated by commas (repeatable)")


def add_hold_argument(p) -> None:
    """--hold, the same in every fitting verb (identify, probe plan, probe fit)."""
    p.add_argument("--hold", metavar="P.yaml",
                   help="hold the errors this params file gives at its values, tables along an axis included "
                        "(e.g. the linear axes' from a laser calibration): not fitted, and written as given with -o")


# The model of the error: its order in the errors, or the exact chain. plot's older spelling
# (--model first|second|exact) maps onto these.
MODEL_NAMES = {"first": "1", "second": "2", "exact": "exact"}


def model_choice(allowed: tuple[str, ...]):
    """'1', '2', 'exact' (or a difference such as 'exact-1' where allowed); the older names too."""
    def parse(text: str) -> str:
        value = "-".join(MODEL_NAMES.get(part, part) for part in text.strip().split("-"))
        if value not in allowed:
            raise argparse.ArgumentTypeError(f"expected one of {', '.join(allowed)}, got {text!r}")
        return value
    return parse


def add_model_argument(p, allowed: tuple[str, ...] = ("1", "2", "exact"), names: tuple[str, ...] = ("--order",),
                       what: str = "model") -> None:
    p.add_argument(*names, dest="model", type=model_choice(allowed), default="1", metavar="{" + ",".join(allowed) + "}",
                   help=f"{what}: 1 first order, 2 second order, exact the chain multiplied out (default 1)")


def add_values_arguments(p) -> None:
    p.add_argument("--params", metavar="P.yaml", help="error values (configs/params/*.yaml)")
    p.add_argument("--set", dest="sets", action="append", default=[], metavar="NAME=VALUE",
                   help="set a symbol (axis, constant or error) in its declared unit, or as "
                        "'VALUE UNIT'; repeatable, applied after --params")


def refuse_empty(*given: tuple[str, str | None], hint: str = "leave the option out for its default") -> None:
    """Refuse an option given an empty value (an unset shell variable, say): a typo, not a
    request for the default. given: (option, value) pairs, value None when not given."""
    for option, value in given:
        if value is not None and not value.strip():
            raise ChaincompError(f"{option}: an empty value ({hint})")


def values_for(machine: Machine, params_path: str | None, sets: list[str]) -> tuple[dict, bool]:
    """Internal values of every symbol, and whether any error value was given.

    Axes default to 0 (or the middle of their range when 0 is outside it), constants to
    their nominal, errors to 0; then the params file, then --set.
    """
    refuse_empty(("--params", params_path), hint="leave the option out for no error values")
    values = machine.nominal_values()
    for s in machine.axes:
        values[s.name] = s.to_internal(s.default_position)
    given = {}
    if params_path:
        given.update(load_params(params_path, machine))
    given.update(parse_sets(sets, machine))
    values.update(given)
    for s in machine.symbols:   # axes; and constants or errors the machine file gives limits too
        if s.limits is None or not isinstance(values.get(s.name), (int, float)):
            continue   # an error given as a table or polynomial varies: its values are not one number
        v = s.from_internal(values[s.name])
        lo, hi = s.limits
        if not lo <= v <= hi:
            print(one_line(f"chaincomp: warning: {s.role} {s.name} = {v:g} {s.unit.name} is outside its limits "
                           f"[{lo:g}, {hi:g}]" + (f" ({machine.file}:{s.line})" if s.role != "axis" else "")),
                  file=sys.stderr)
    has_errors = any(machine.symbol(n).role == "error" for n in given)
    return values, has_errors


def load(path: str) -> Machine:
    """The machine, with chaincomp.lint's warnings on stderr (``chaincomp lint`` shows them too)."""
    machine = load_machine(path)
    from ..analysis.lint import lint
    for f in lint(machine):
        print(one_line(f"chaincomp: {f.level}: {machine.file}:{f}"), file=sys.stderr)
    return machine


def _same_file(a: str, b: str) -> bool:
    """Whether paths a and b name one file (links and other spellings too)."""
    try:
        sa, sb = os.stat(a), os.stat(b)
    except OSError:
        return os.path.abspath(a) == os.path.abspath(b)
    return (sa.st_dev, sa.st_ino) == (sb.st_dev, sb.st_ino)


def check_output(output: str | None, *inputs: str | None, option: str = "-o") -> None:
    """Refuse, before anything is written, an output that is one of the inputs, or whose
    folder does not exist or cannot be written to."""
    if output is None:
        return
    refuse_empty((option, output), hint="expected a file name")
    for path in inputs:
        if path and _same_file(output, path):
            raise ChaincompError(f"{option} {output}: is also an input ({path}); "
                                 f"refusing to overwrite it")
    folder = os.path.dirname(os.path.abspath(output))
    if not os.path.isdir(folder):
        raise ChaincompError(f"{option} {output}: folder {folder} does not exist")
    if os.path.isdir(output):
        raise ChaincompError(f"{option} {output}: is a folder, expected a file name")
    if os.path.exists(output) and not os.access(output, os.W_OK):
        raise ChaincompError(f"{option} {output}: not writable")
    # a regular file is replaced from a temporary file beside it (beside the file a link names); a
    # pipe or device is written into (chaincomp.output)
    special = os.path.exists(output) and not os.path.isfile(output)
    if not special and not os.access(os.path.dirname(os.path.realpath(output)), os.W_OK):
        raise ChaincompError(f"{option} {output}: not writable")


def check_image(output: str | None, *inputs: str | None, option: str = "-o") -> None:
    """check_output, and a file type matplotlib can write (it would fail only after the work)."""
    check_output(output, *inputs, option=option)
    ext = os.path.splitext(output or "")[1].lower().lstrip(".")
    if output and ext:
        from matplotlib.backend_bases import FigureCanvasBase
        kinds = FigureCanvasBase.get_supported_filetypes()
        if ext not in kinds:
            raise ChaincompError(f"{option} {output}: cannot write .{ext} images (use one of "
                                 f"{', '.join('.' + k for k in sorted(kinds))})")


# Option values: argparse `type=` functions, so that every verb refuses a bad value the same
# way, before any work, in argparse's one line naming the option.

MAX_SEED = 2**32 - 1   # numpy's and Python's seeders both take any value in [0, 2^32)


def integer(lo: int, hi: int):
    """An integer in [lo, hi], written as plain digits (no '1e3', '0x10', '1_000')."""
    def parse(text: str) -> int:
        t = text.strip()   # str.strip takes more than int() does (e.g. '\x1f'): parse what was matched
        if not re.fullmatch(r"[+-]?[0-9]{1,30}", t):
            raise argparse.ArgumentTypeError(f"expected an integer, got {text!r}")
        value = int(t)
        if not lo <= value <= hi:
            raise argparse.ArgumentTypeError(f"must be between {lo} and {hi}, got {value}")
        return value
    return parse


def number(lo: float = -math.inf, hi: float = math.inf, above: bool = False):
    """A finite number in [lo, hi] (in (lo, hi] with above=True): nan and inf refused."""
    def parse(text: str) -> float:
        try:
            value = parse_number(text)
        except ValueError as exc:
            raise argparse.ArgumentTypeError(str(exc)) from None
        if value < lo or value > hi or (above and value == lo):
            want = (f"above {lo:g}" if above else f"at least {lo:g}") + (f" and at most {hi:g}" if hi < math.inf
                                                                          else "")
            raise argparse.ArgumentTypeError(f"must be {want}, got {text!r}")
        return value
    return parse


seed = integer(0, MAX_SEED)

# Time grows steeply with the order: derive five_axis_ac takes 10 s at order 3, 32 s at 4,
# 135 s at 5 (2 cores, 2026-12): 4 keeps every verb within a minute.
MAX_ORDER = 4


def add_order_argument(p, default: int, what: str = "highest total degree in the errors") -> None:
    p.add_argument("--order", type=integer(1, MAX_ORDER), default=default,
                   help=f"{what} (1 to {MAX_ORDER}, default {default})")


def number_list(option: str, text: str) -> list[float]:
    """'0, 90,180' -> [0.0, 90.0, 180.0]: finite numbers separated by commas, none empty."""
    out = []
    for item in (t.strip() for t in text.split(",")):
        try:
            out.append(parse_number(item))
        except ValueError as exc:
            raise ChaincompError(f"{option}: {exc} (numbers separated by commas)") from None
    return out


def _non_finite(obj, path: str):
    """The path and value of the first non-finite number in a nest of dicts and lists."""
    if isinstance(obj, dict):
        items = ((f"{path}.{k}" if path else str(k), v) for k, v in obj.items())
    elif isinstance(obj, (list, tuple)):
        items = ((f"{path}[{i}]", v) for i, v in enumerate(obj))
    else:
        try:
            return None if math.isfinite(obj) else (path, obj)
        except TypeError:
            return None   # strings, None, booleans are not numbers that can overflow
    for p, v in items:
        found = _non_finite(v, p)
        if found:
            return found
    return None


def check_finite(doc) -> None:
    """Refuse a result holding nan or inf, naming the quantity (e.g. 'error.exact[2]')."""
    found = _non_finite(doc, "")
    if found:
        raise ChaincompError(f"the result {found[0]} is not finite ({found[1]}): the machine's expressions "
                             "or the values given leave their domain here (e.g. acos of more than 1, a division "
                             "by zero)")


def to_json(doc) -> str:
    """Valid JSON always: a non-finite number is refused (check_finite), never printed as NaN."""
    check_finite(doc)
    return json.dumps(doc, indent=2, allow_nan=False)


def names(text: str | None, option: str = "list") -> list[str]:
    """'A, B,C' -> ['A', 'B', 'C']; repeated options arrive joined by commas; an empty name
    ('A,,B', 'A,') is refused: it is a typo, not a request."""
    if not text:
        return []
    out = [t.strip() for t in text.split(",")]
    if not all(out):
        raise ChaincompError(f"{option}: empty name in {text!r}")
    return out


def assignments(items: list[str], option: str, form: str) -> dict[str, str]:
    """KEY=VALUE items of an option (``form`` names them, e.g. "AXIS=VALUE"), stripped, each
    key once, in order."""
    out: dict[str, str] = {}
    for item in items:
        key, eq, value = (x.strip() for x in item.partition("="))
        if not eq or not key or not value:
            raise ChaincompError(f"{option}: expected {form}, got {item!r}")
        if key in out:
            raise ChaincompError(f"{option}: {key} given twice")
        out[key] = value
    return out


def length(machine, option: str, raw: str, positive: bool = False) -> float:
    """'1um', '0.001 mm' or a bare number in the machine's length unit -> mm, finite and >= 0
    (> 0 if ``positive``)."""
    try:
        value = parse_value(Symbol(option, "constant", UNITS[machine.length_unit], ""), raw)
    except ValueError as exc:
        raise ChaincompError(f"{option}: {exc}") from None
    if value < 0 or (positive and value == 0):
        raise ChaincompError(f"{option}: must be {'positive' if positive else 'zero or positive'}, got {raw!r}")
    return value
