"""Error values (and constant overrides) for a machine, from a params file or the command line.

An error may also vary along an axis (a table or a polynomial): chaincomp.varying."""

from __future__ import annotations

import math
import re

from ..errors import ChaincompError
from . import units
from .expressions import MAX_LITERAL
from .machine import Machine, Symbol
from .varying import MAX_VARYING_ERRORS, Varying, parse_varying
from .yamlsource import describe, load_yaml

# ASCII digits only (float() takes other scripts' digits; the C++ loader does not)
_VALUE = re.compile(r"\s*([-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?)\s*([^\s\d].*?)?\s*\Z", re.ASCII)


def parse_value(sym: Symbol, raw) -> float:
    """A value in the symbol's declared unit, or text 'VALUE UNIT'; returned in internal units.

    Raises ValueError with a message naming what was expected.
    """
    if isinstance(raw, bool):
        raise ValueError(f"expected a number, got {raw!r}")
    if isinstance(raw, (int, float)):
        try:
            value, unit = float(raw), sym.unit
        except OverflowError:  # an int beyond any float
            value, unit = (math.inf if raw > 0 else -math.inf), sym.unit
    elif isinstance(raw, str):
        m = _VALUE.match(raw)
        if not m:
            raise ValueError(f"expected a number optionally followed by a unit, got {raw!r}")
        value = float(m.group(1))
        try:
            unit = units.unit(m.group(2).strip()) if m.group(2) else sym.unit
        except KeyError as exc:
            raise ValueError(exc.args[0]) from None
    else:
        raise ValueError(f"expected a number, got {type(raw).__name__}")
    if not math.isfinite(value):
        raise ValueError(f"expected a finite number, got {raw!r}")
    if unit.kind != sym.unit.kind:
        raise ValueError(f"unit {unit.name!r} is {'an' if unit.kind == 'angle' else 'a'} {unit.kind} unit but "
                         f"{sym.name} is declared in "
                         f"{sym.unit.name!r} ({sym.unit.kind})")
    internal = value * unit.to_internal
    if not abs(internal) <= MAX_LITERAL:
        raise ValueError(f"{raw!r} is larger than {MAX_LITERAL:g} {units.INTERNAL[unit.kind]} in magnitude")
    return internal


def load_params(path: str, machine: Machine) -> dict[str, float | Varying]:
    """Values from a params file, by symbol name, in internal units (mm, rad).

    An error given as a table or polynomial over an axis is a ``Varying`` (callable on the
    axis value); chaincomp.numeric's models evaluate it at the axes (``varying.resolve``)."""
    doc = load_yaml(path)
    if not isinstance(doc, dict):
        raise ChaincompError("expected a mapping with 'values'", path, 1)
    for key in doc:
        if key not in ("machine", "values", "description"):
            raise ChaincompError(f"unknown field {key!r} (expected machine, values, description)",
                                 path, doc.lines[key], key)
    if "machine" in doc and not isinstance(doc["machine"], str):
        raise ChaincompError(f"expected the machine's name, got {describe(doc['machine'])}",
                             path, doc.lines["machine"], "machine")
    if "machine" in doc and doc["machine"] != machine.name:
        raise ChaincompError(f"params are for machine {doc['machine']!r}, not {machine.name!r}",
                             path, doc.lines["machine"], "machine")
    values = doc.get("values")
    if not isinstance(values, dict):
        raise ChaincompError("expected a mapping of symbol names to values", path,
                             doc.lines.get("values", 1), "values")
    out = {}
    for name, raw in values.items():
        line = values.lines[name]
        try:
            sym = machine.symbol(name)
        except KeyError:
            raise ChaincompError(f"unknown symbol {name!r} for machine {machine.name!r}", path, line,
                                 f"values.{name}") from None
        if sym.role == "axis":
            raise ChaincompError(f"{name!r} is an axis: axis values are commands, not parameters",
                                 path, line, f"values.{name}")
        if isinstance(raw, dict):
            out[name] = parse_varying(raw, name, path, line, machine)
            if sum(isinstance(v, Varying) for v in out.values()) > MAX_VARYING_ERRORS:
                raise ChaincompError(f"more than {MAX_VARYING_ERRORS} varying errors", path, line,
                                     f"values.{name}")
            continue
        if raw is None:
            raise ChaincompError("missing value", path, line, f"values.{name}")
        if isinstance(raw, list):
            raise ChaincompError("expected a number, or a mapping with 'table' or 'polynomial'", path, line,
                                 f"values.{name}")
        try:
            out[name] = parse_value(sym, raw)
        except ValueError as exc:
            raise ChaincompError(str(exc), path, line, f"values.{name}") from None
    return out


def parse_sets(items: list[str], machine: Machine) -> dict[str, float]:
    """``NAME=VALUE`` items from the command line, in internal units."""
    out, given = {}, {}
    for item in items:
        name, sep, raw = item.partition("=")
        name = name.strip()
        if not sep:
            raise ChaincompError(f"--set expects NAME=VALUE, got {item!r}")
        try:
            sym = machine.symbol(name)
        except KeyError:
            raise ChaincompError(f"--set: unknown symbol {name!r} for machine {machine.name!r} "
                                 f"(known: {', '.join(s.name for s in machine.symbols)})") from None
        if name in out:   # which of the two was meant? (--params, then --set, is the override)
            raise ChaincompError(f"--set {name} given twice ({given[name]!r}, then {raw.strip()!r}): set each "
                                 "symbol once")
        if re.search(r",\s*[A-Za-z_][A-Za-z0-9_]*\s*=", raw):
            raise ChaincompError(f"--set {name}: {raw!r} sets more than one symbol: give one --set per symbol "
                                 f"(--set {item.split(',')[0].strip()} --set {item.split(',', 1)[1].strip()})")
        try:
            out[name] = parse_value(sym, raw)
        except ValueError as exc:
            raise ChaincompError(f"--set {name}: {exc}") from None
        given[name] = raw.strip()
    return out
