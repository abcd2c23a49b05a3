"""Pieces shared by the verbs: loading a machine with its values."""

from __future__ import annotations

import os
import sys

from ..errors import ChaincompError
from ..machine import Machine, load_machine
from ..params import load_params, parse_sets


def add_machine_argument(p) -> None:
    p.add_argument("machine", metavar="MACHINE.yaml", help="machine description (configs/machines/*.yaml)")


def add_values_arguments(p) -> None:
    p.add_argument("--params", metavar="P.yaml", help="error values (configs/params/*.yaml)")
    p.add_argument("--set", dest="sets", action="append", default=[], metavar="NAME=VALUE",
                   help="set a symbol (axis, constant or error) in its declared unit, or as "
                        "'VALUE UNIT'; repeatable, applied after --params")


def check_order(order: int) -> int:
    if order < 1 or order > 6:
        raise ChaincompError(f"--order must be between 1 and 6, got {order}")
    return order


def values_for(machine: Machine, params_path: str | None, sets: list[str]) -> tuple[dict, bool]:
    """Internal values of every symbol, and whether any error value was given.

    Axes default to 0 (or the middle of their range when 0 is outside it), constants to
    their nominal, errors to 0; then the params file, then --set.
    """
    values = machine.nominal_values()
    for s in machine.axes:
        values[s.name] = s.to_internal(s.default_position)
    given = {}
    if params_path:
        given.update(load_params(params_path, machine))
    given.update(parse_sets(sets, machine))
    values.update(given)
    for s in machine.axes:
        v = s.from_internal(values[s.name])
        lo, hi = s.limits
        if not lo <= v <= hi:
            print(f"chaincomp: warning: axis {s.name} = {v:g} {s.unit.name} is outside its limits "
                  f"[{lo:g}, {hi:g}]", file=sys.stderr)
    has_errors = any(machine.symbol(n).role == "error" for n in given)
    return values, has_errors


def load(path: str) -> Machine:
    return load_machine(path)


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
    if not output:
        return
    for path in inputs:
        if path and _same_file(output, path):
            raise ChaincompError(f"{option} {output}: is also an input ({path}); "
                                 f"refusing to overwrite it")
    folder = os.path.dirname(os.path.abspath(output))
    if not os.path.isdir(folder):
        raise ChaincompError(f"{option} {output}: folder {folder} does not exist")
    if os.path.isdir(output):
        raise ChaincompError(f"{option} {output}: is a folder, expected a file name")
    if not os.access(folder, os.W_OK) or (os.path.exists(output) and not os.access(output, os.W_OK)):
        raise ChaincompError(f"{option} {output}: not writable")
