"""The machine description: loading, validation, and the elementary chain it defines.

Expressions are kept as chaincomp.expressions trees, which the numeric verbs evaluate without
sympy; their sympy forms (Rotation.angle, Translation.vector, Machine.tool_point, ...) are
built when a symbolic verb first asks, so only those verbs import sympy."""

from __future__ import annotations

import math
import re
from dataclasses import dataclass, field
from fractions import Fraction
from functools import cache, cached_property, partial
from typing import Union

from ..errors import ChaincompError
from . import units
from .expressions import (MAX_LITERAL, NAME, RESERVED, ZERO, Expr, ExpressionError, check_sympy, constant,
                          from_sympy, linear_names, parse_tree, plausible)
from .yamlsource import describe, line_of, load_yaml, read_text

ROLES = ("axis", "constant", "error")
MAX_SYMBOLS = 256          # declared symbols of one machine
MAX_CHAIN_ELEMENTS = 256   # elements written in one chain or loop branch
MAX_MACHINE_TERMS = 2000   # terms all its expressions could expand to (expressions.MAX_TERMS each)
SENSES = {"right_hand": 1, "left_hand": -1}
AXES = ("x", "y", "z")
# The coordinates a rotation about each axis mixes: i' = c·i − s·j, j' = s·i + c·j.
ROT_PLANE = {"x": (1, 2), "y": (2, 0), "z": (0, 1)}


@dataclass(frozen=True)
class Symbol:
    """A declared symbol: an axis (commanded), a constant (nominal geometry) or an error (small)."""
    name: str
    role: str                  # "axis" | "constant" | "error"
    unit: units.Unit
    meaning: str
    nominal: float | None = None               # in the declared unit
    limits: tuple[float, float] | None = None  # in the declared unit
    line: int = 0
    unobservable: bool = False  # known not to move the tool point or direction (lint stays quiet)
    # the measuring instrument's frame to the machine's base (a base block): identified with the
    # errors, reported apart and never compensated (not a machine error)
    registration: bool = False

    @property
    def sym(self):
        """The sympy symbol (real)."""
        import sympy as sp
        return sp.Symbol(self.name, real=True)

    @property
    def small(self) -> bool:
        return self.role == "error"

    @property
    def default_position(self) -> float:
        """Where an axis stands when nothing sets it: 0, or mid-range when 0 is outside its
        limits (declared unit)."""
        lo, hi = self.limits
        return 0.0 if lo <= 0.0 <= hi else 0.5 * (lo + hi)

    @property
    def reference_value(self) -> float:
        """Internal value at the reference pose the load checks and lint use: an axis at its
        default position, a constant at its nominal, an error at zero."""
        if self.role == "axis":
            return self.to_internal(self.default_position)
        return self.to_internal(self.nominal) if self.role == "constant" else 0.0

    def to_internal(self, value: float) -> float:
        return value * self.unit.to_internal

    def from_internal(self, value: float) -> float:
        return value / self.unit.to_internal


def _tree(e) -> Expr:
    """An expression tree, from a tree, a number or a sympy expression (the symbolic verbs
    build some)."""
    if isinstance(e, Expr):
        return e
    if isinstance(e, int):
        return Expr(("num", Fraction(e)), repr(e))
    return constant(e) if isinstance(e, float) else from_sympy(e)


@dataclass(frozen=True)
class Rotation:
    """Rotation about a coordinate axis by the angle ``expr`` (rad), right-handed after ``sense``."""
    axis: str
    expr: Expr
    line: int = 0

    def __post_init__(self):
        object.__setattr__(self, "expr", _tree(self.expr))

    @cached_property
    def angle(self):
        """The angle in sympy."""
        return self.expr.to_sympy()

    def inverse(self) -> "Rotation":
        return Rotation(self.axis, -self.expr, self.line)


@dataclass(frozen=True)
class Translation:
    exprs: tuple[Expr, Expr, Expr]
    line: int = 0

    def __post_init__(self):
        object.__setattr__(self, "exprs", tuple(_tree(e) for e in self.exprs))

    @cached_property
    def vector(self) -> tuple:
        """The vector in sympy."""
        return tuple(e.to_sympy() for e in self.exprs)

    def inverse(self) -> "Translation":
        return Translation(tuple(-v for v in self.exprs), self.line)


Elementary = Union[Rotation, Translation]


@dataclass(frozen=True)
class Machine:
    """A validated machine description: its symbols, chain (or loop branches) and tool."""
    name: str
    description: str
    file: str
    length_unit: str
    symbols: tuple[Symbol, ...]
    tool_chain: tuple[Elementary, ...]       # reference -> tool, leftmost first
    workpiece_chain: tuple[Elementary, ...]  # reference -> workpiece (empty: no loop)
    point: tuple[Expr, Expr, Expr]           # the tool point
    direction: tuple[Expr, Expr, Expr] | None  # the unit tool direction (numbers)
    source_text: str = field(repr=False, default="")
    # dh/mdh joints as written: (number, kind, nominal alpha (Expr), {parameter: error name}, line)
    joint_list: tuple = field(repr=False, default=())
    # With a tool frame: its x axis (unit, orthogonal to the direction, which is its z axis);
    # y = z × x. None: the tool has a point (and maybe a direction) only.
    reference: tuple[Expr, Expr, Expr] | None = None

    def __post_init__(self):
        for name in ("point", "direction", "reference"):
            v = getattr(self, name)
            if v is not None:
                object.__setattr__(self, name, tuple(_tree(e) for e in v))

    @cached_property
    def tool_point(self) -> tuple:
        """The tool point in sympy."""
        return tuple(e.to_sympy() for e in self.point)

    @cached_property
    def tool_direction(self) -> tuple | None:
        """The unit tool direction in sympy."""
        return None if self.direction is None else tuple(e.to_sympy() for e in self.direction)

    @cached_property
    def tool_reference(self) -> tuple | None:
        """The tool frame's x axis in sympy."""
        return None if self.reference is None else tuple(e.to_sympy() for e in self.reference)

    @cached_property
    def joints(self) -> tuple:
        """The dh/mdh joints as written, their nominal alpha in sympy."""
        return tuple((n, kind, alpha.to_sympy(), errors, line) for n, kind, alpha, errors, line in self.joint_list)

    @cached_property
    def frame_numbers(self) -> tuple | None:
        """The tool frame's x, y, z axes as numbers (y = z × x), or None."""
        if self.reference is None:
            return None
        x, z = ([e.value({}) for e in v] for v in (self.reference, self.direction))
        y = [z[(i + 1) % 3] * x[(i + 2) % 3] - z[(i + 2) % 3] * x[(i + 1) % 3] for i in range(3)]
        return x, y, z

    @property
    def tool_axes(self) -> list[tuple]:
        """The constant unit vectors the chain turns with the tool: the direction, and with a
        frame its x axis (the pose layout of the generated code after the point)."""
        return [v for v in (self.tool_direction, self.tool_reference) if v is not None]

    @property
    def tool_frame(self) -> tuple[tuple, tuple, tuple] | None:
        """The tool frame's x, y, z axes (constant unit vectors) or None."""
        import sympy as sp
        if self.tool_reference is None:
            return None
        x, z = self.tool_reference, self.tool_direction
        y = tuple(sp.nsimplify(sp.expand(z[(i + 1) % 3] * x[(i + 2) % 3] - z[(i + 2) % 3] * x[(i + 1) % 3]))
                  for i in range(3))
        return x, y, z

    def by_role(self, role: str) -> list[Symbol]:
        return [s for s in self.symbols if s.role == role]

    @property
    def axes(self) -> list[Symbol]:
        return self.by_role("axis")

    @property
    def constants(self) -> list[Symbol]:
        return self.by_role("constant")

    @property
    def errors(self) -> list[Symbol]:
        return self.by_role("error")

    def symbol(self, name: str) -> Symbol:
        for s in self.symbols:
            if s.name == name:
                return s
        raise KeyError(name)

    @property
    def chain(self) -> tuple[Elementary, ...]:
        """Elementary transforms giving the tool relative to the workpiece.

        With a structural loop that is inv(reference->workpiece) * (reference->tool); the
        inverse of a product of elementary transforms is the reversed product of their
        inverses, so no matrix is ever inverted.
        """
        return tuple(e.inverse() for e in reversed(self.workpiece_chain)) + self.tool_chain

    def nominal_values(self) -> dict[str, float]:
        """Internal values (mm, rad) of the large symbols at their nominals; errors at zero."""
        out = {}
        for s in self.symbols:
            out[s.name] = 0.0 if s.role == "error" or s.nominal is None else s.to_internal(s.nominal)
        return out


# ----------------------------------------------------------------------------- loading

class _Ctx:
    """Where we are in the file, for messages."""

    def __init__(self, path: str):
        self.path = path
        self.values: dict = {}    # name -> every symbol's value at the reference (axes: default position)
        self.errors: set = set()  # the error symbols' names
        self.symbols: list = []   # the declared symbols, and the errors dh/mdh/beta name themselves
        self.table: dict = {}     # name -> Symbol, of the same
        self.joints: list = []    # the dh/mdh joints, for lint: (number, kind, alpha, error names, line)
        self.joint = 0            # the last dh/mdh joint's number in the chain being read
        self.auto: dict = {}      # error name -> line of the element that auto-named it
        self.terms = 0            # the terms the expressions read so far could expand to (MAX_MACHINE_TERMS)

    def declare_error(self, name: str, unit: str, meaning: str, line: int, fld: str) -> str:
        """An error named by a dh/mdh/beta element: the declared one of that name, or a new one."""
        if name in self.table:
            sym = next(s for s in self.symbols if s.name == name)
            if sym.role != "error":
                raise self.fail(f"{name!r} is declared as {'an' if sym.role == 'axis' else 'a'} {sym.role}; "
                                f"the error this element names must be an error", line, fld)
            want = units.unit(unit).kind
            if sym.unit.kind != want:  # a twist error declared in um would be read as radians
                raise self.fail(f"{name!r} is declared in {sym.unit.name} on line {sym.line}, but this element "
                                f"uses it as its {meaning}, which is {'an' if want == 'angle' else 'a'} {want}",
                                line, fld)
            return name
        s = Symbol(name, "error", units.unit(unit), meaning, line=line)
        self.symbols.append(s)
        self.table[name] = s
        self.errors.add(name)
        self.values[name] = 0.0
        return name

    def fail(self, message: str, line: int | None, fld: str) -> ChaincompError:
        return ChaincompError(message, self.path, line, fld)


def _require_map(ctx: _Ctx, node, fld: str, line, allowed: set[str], required: set[str] = frozenset()):
    if not isinstance(node, dict):
        raise ctx.fail(f"expected a mapping, got {describe(node)}", line, fld)
    for key in node:
        if key not in allowed:
            raise ctx.fail(f"unknown field {key!r} (expected one of: {', '.join(sorted(allowed))})",
                           line_of(node, key), f"{fld}.{key}")
    for key in sorted(required):
        if key not in node:
            raise ctx.fail(f"missing required field {key!r}", line_of(node) if line is None else line, fld)
    return node


# YAML 1.1 (PyYAML) wants a dot and a signed exponent (1.0e+3): 1e3 and 1.5e3 come as text.
_EXPONENT_NUMBER = re.compile(r"[-+]?(?:[0-9]+(?:\.[0-9]*)?|\.[0-9]+)[eE][-+]?[0-9]+")


def _number(ctx: _Ctx, value, fld: str, line) -> float:
    if isinstance(value, str) and _EXPONENT_NUMBER.fullmatch(value):
        if not math.isfinite(float(value)):
            raise ctx.fail(f"expected a finite number, got {value!r}", line, fld)
        value = float(value)
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise ctx.fail(f"expected a number, got {describe(value)}", line, fld)
    if isinstance(value, float) and not math.isfinite(value):
        raise ctx.fail(f"expected a finite number, got {value!r}", line, fld)
    if abs(value) > MAX_LITERAL:
        shown = str(value) if len(str(value)) <= 24 else str(value)[:20] + "..."
        raise ctx.fail(f"{shown} is larger than {MAX_LITERAL:g} in magnitude", line, fld)
    return float(value)


def _parse_symbol(ctx: _Ctx, node, i: int, line) -> Symbol:
    fld = f"symbols[{i}]"
    _require_map(ctx, node, fld, line, {"name", "role", "unit", "meaning", "nominal", "limits", "unobservable",
                                        "registration"},
                 {"name", "role", "unit"})
    name = node["name"]
    if not isinstance(name, str) or not NAME.match(name):
        raise ctx.fail(f"invalid symbol name {name!r} (letters, digits and '_', starting with a letter)",
                       line_of(node, "name"), f"{fld}.name")
    if name in RESERVED:
        raise ctx.fail(f"symbol name {name!r} is reserved", line_of(node, "name"), f"{fld}.name")
    fld = f"symbols.{name}"
    role = node["role"]
    if role not in ROLES:
        raise ctx.fail(f"unknown role {role!r} (expected one of: {', '.join(ROLES)})",
                       line_of(node, "role"), f"{fld}.role")
    try:
        unit = units.unit(str(node["unit"]))
    except KeyError as exc:
        raise ctx.fail(exc.args[0], line_of(node, "unit"), f"{fld}.unit") from None
    meaning = node.get("meaning", "")
    if not isinstance(meaning, str):
        raise ctx.fail(f"expected text, got {describe(meaning)}", line_of(node, "meaning"), f"{fld}.meaning")
    nominal = None
    if "nominal" in node:
        nominal = _number(ctx, node["nominal"], f"{fld}.nominal", line_of(node, "nominal"))
        if role == "error":
            raise ctx.fail("an error symbol has no nominal value (its value comes from a params file)",
                           line_of(node, "nominal"), f"{fld}.nominal")
        if role == "axis":   # nothing would read it: an axis stands at 0 (or mid-range) unless set
            raise ctx.fail("an axis has no nominal value: it stands at 0 (or mid-range where 0 is outside its "
                           "limits) unless a verb sets it (--set AXIS=VALUE)", line_of(node, "nominal"),
                           f"{fld}.nominal")
    elif role == "constant":
        raise ctx.fail("a constant needs a 'nominal' value", line_of(node), fld)
    limits = None
    if "limits" in node:
        lim = node["limits"]
        lline = line_of(node, "limits")
        if not isinstance(lim, list) or len(lim) != 2:
            raise ctx.fail(f"expected [low, high], got {describe(lim)}", lline, f"{fld}.limits")
        lo, hi = (_number(ctx, v, f"{fld}.limits", lline) for v in lim)
        if not lo < hi:
            raise ctx.fail(f"low limit {lo:g} must be below high limit {hi:g}", lline, f"{fld}.limits")
        limits = (lo, hi)
    elif role == "axis":
        raise ctx.fail("an axis needs 'limits: [low, high]'", line_of(node), fld)
    if nominal is not None and limits is not None and not limits[0] <= nominal <= limits[1]:
        raise ctx.fail(f"nominal {nominal:g} lies outside limits {list(limits)}", line_of(node, "nominal"),
                       f"{fld}.nominal")
    if role == "axis" and unit.kind == "ratio":
        raise ctx.fail(f"an axis must have a length or angle unit, not {unit.name!r}",
                       line_of(node, "unit"), f"{fld}.unit")
    flags = {}
    for flag in ("unobservable", "registration"):
        flags[flag] = node.get(flag, False)
        if not isinstance(flags[flag], bool):
            raise ctx.fail(f"expected true or false, got {describe(flags[flag])}", line_of(node, flag),
                           f"{fld}.{flag}")
        if flags[flag] and role != "error":
            raise ctx.fail(f"only an error symbol can be marked {flag}", line_of(node, flag), f"{fld}.{flag}")
    return Symbol(name, role, unit, meaning, nominal, limits, line or 0, **flags)


def _expr(ctx: _Ctx, value, symbols, fld: str, line, want: str | None = None) -> Expr:
    try:
        expr = parse_tree(value, symbols)
        ctx.terms += expr.terms
        if ctx.terms > MAX_MACHINE_TERMS:
            raise ExpressionError(f"the machine's expressions up to this one could expand to up to {ctx.terms} terms "
                                  f"(at most {MAX_MACHINE_TERMS} in all; derive expands them): use fewer symbols in "
                                  f"powered sums and products, or smaller powers")
        if not plausible(expr, ctx.values, ctx.errors):
            expr = _symbolic_check(ctx, expr)
    except ExpressionError as exc:
        raise ctx.fail(str(exc), line, fld) from None
    if want is not None:
        _check_kind(ctx, expr, want, fld, line)
    return expr


def _symbolic_check(ctx: _Ctx, expr: Expr) -> Expr:
    """What the numeric screen doubts, sympy decides (and words): the expression as sympy
    evaluates it must be finite, real and analytic in the errors at the reference values.
    What passes is kept in sympy's form (e^2/e is e: no division by zero error)."""
    import sympy as sp
    table = {n: sp.Symbol(n, real=True) for n in ctx.table}
    e = expr.to_sympy(table)
    check_sympy(e, expr.source)
    _check_at_nominal(e, {table[n]: sp.Float(v) for n, v in ctx.values.items()}, {table[n] for n in ctx.errors})
    return from_sympy(e, expr.source)


def _numeric(expr, at: dict) -> complex | None:
    """The value of ``expr`` at ``at`` (every symbol), or None where it is not finite."""
    import sympy as sp
    value = sp.N(expr.xreplace(at), 17)
    if not value.is_number or value.has(sp.zoo, sp.nan, sp.oo, -sp.oo):
        return None
    c = complex(value)
    return c if math.isfinite(c.real) and math.isfinite(c.imag) else None


def _check_at_nominal(expr, at: dict, errors: set) -> None:
    """An expression must be finite and real at the nominal values (axes at their default
    positions, errors zero), and analytic in the errors there: the truncated series are its
    Taylor expansion about zero error, which a division by an error or the square root of
    one does not have."""
    import sympy as sp
    where = ", ".join(f"{s} = {float(at[s]):g}" for s in sorted(expr.free_symbols, key=str) if s not in errors)
    where = f" ({where}, errors zero)" if where else " (errors zero)"
    for node in sp.preorder_traversal(expr):
        if not (node.free_symbols & errors):
            continue
        names = ", ".join(sorted(str(e) for e in node.free_symbols & errors))
        arg, bad = None, None
        if node.is_Pow and not (node.exp.is_Integer and node.exp >= 0):
            arg = _numeric(node.base, at)
            if arg is not None and abs(arg) < 1e-300:
                bad = "divides by" if node.exp.is_negative else f"takes a power {node.exp} of"
        elif isinstance(node, sp.Abs):   # sqrt(e^2) is |e|: no derivative at zero
            arg = _numeric(node.args[0], at)
            if arg is not None and abs(arg) < 1e-300:
                bad = "takes the absolute value of"
        elif isinstance(node, (sp.asin, sp.acos)):
            arg = _numeric(node.args[0], at)
            if arg is not None and abs(abs(arg.real) - 1) < 1e-12:
                bad = f"takes {node.func.__name__} at ±1 of"
        elif isinstance(node, sp.tan):
            arg = _numeric(sp.cos(node.args[0]), at)
            if arg is not None and abs(arg) < 1e-15:
                bad = "takes tan at ±90° of"
        elif isinstance(node, sp.atan2):
            y, x = (_numeric(a, at) for a in node.args)
            if y is not None and x is not None and abs(y) < 1e-300 and abs(x) < 1e-300:
                bad = "takes atan2(0, 0) of"
            elif y is not None and x is not None and abs(y) < 1e-300 and x.real < 0 and node.args[0].free_symbols & errors:
                bad = "takes atan2 on its branch cut (y = 0, x < 0: it jumps by 2 pi) of"
        if bad:
            raise ExpressionError(f"{expr} is not analytic in the errors at zero: it {bad} an expression "
                                  f"that vanishes with {names}{where}; errors must enter through sums, "
                                  f"products and smooth functions of them")
    value = _numeric(expr, at)
    if value is None:
        raise ExpressionError(f"{expr} is not finite at the nominal values{where}")
    if abs(value.imag) > 1e-12 * max(1.0, abs(value.real)):
        raise ExpressionError(f"{expr} is not real at the nominal values{where}")


def _vector(ctx: _Ctx, value, symbols, fld: str, line, want: str | None = None) -> tuple[Expr, Expr, Expr]:
    if not isinstance(value, list) or len(value) != 3:
        raise ctx.fail(f"expected a list of three expressions [x, y, z], got {describe(value)}", line, fld)
    return tuple(_expr(ctx, v, symbols, f"{fld}[{i}]", line, want) for i, v in enumerate(value))


def _check_kind(ctx: _Ctx, expr: Expr, want: str, fld: str, line) -> None:
    """A translation reads its expressions as lengths (mm), a rotation as an angle (rad). A
    symbol that stands there as a term of its own (times a number) must be of that kind: an
    error declared in arcsec as an error block's dx, or an axis in mm as a rotation's angle,
    would be read in the wrong unit without a word (4 arcsec as 19 nm). A ratio (ppm) is an
    angle to first order (a squareness in um/m), but never a length."""
    names = linear_names(expr.node)
    for n in names or ():
        s = ctx.table.get(n)
        if s is None:
            continue
        kind = s.unit.kind
        if (want == "length" and kind != "length") or (want == "angle" and kind == "length"):
            if want == "length":
                where, fix = "a translation, which reads it as a length (mm)", \
                    "declare it in a length unit, or multiply it by its lever arm or travel"
            else:
                where, fix = "a rotation, which reads it as an angle (rad)", \
                    "declare it in an angle unit, or divide it by its lever arm"
            raise ctx.fail(f"{s.role} {n!r} is declared in {s.unit.name} (a{'n' if kind == 'angle' else ''} {kind}) "
                           f"{f'on line {s.line} ' if s.line else ''}but stands in {where}: {fix}", line, fld)


_BLOCK_KEYS = ("dx", "dy", "dz", "ex", "ey", "ez")


def _parse_element(ctx: _Ctx, node, fld: str, line, symbols, default_sense: int | None,
                   default_order: str | None) -> list[Elementary]:
    if not isinstance(node, dict):
        raise ctx.fail(f"expected a chain element (rotate / translate / errors), got {describe(node)}",
                       line, fld)
    kinds = [k for k in ("rotate", "translate", "dh", "mdh", "beta") if k in node] or \
        (["errors"] if "errors" in node else [])
    if len(kinds) != 1:
        raise ctx.fail("each chain element has exactly one of 'rotate', 'translate', 'errors', 'dh', 'mdh' "
                       "or 'beta'" + (f" (found {', '.join(kinds)})" if kinds else
                                      f" (found fields: {', '.join(map(str, node)) or 'none'})"), line, fld)
    kind = kinds[0]
    common = {"label"}
    if kind in _JOINT_PARAMS:
        return _parse_joint(ctx, node, kind, fld, line, symbols)
    if kind == "rotate":
        _require_map(ctx, node, fld, line, common | {"rotate", "angle", "sense"}, {"angle"})
        axis = node["rotate"]
        if axis not in AXES:
            raise ctx.fail(f"rotation axis must be x, y or z, got {axis!r}", line_of(node, "rotate"),
                           f"{fld}.rotate")
        sense = _sense(ctx, node, fld, default_sense)
        angle = _expr(ctx, node["angle"], symbols, f"{fld}.angle", line_of(node, "angle"), "angle")
        return [Rotation(axis, angle.scaled(sense), line or 0)]
    if kind == "translate":
        _require_map(ctx, node, fld, line, common | {"translate"})
        return [Translation(_vector(ctx, node["translate"], symbols, f"{fld}.translate",
                                    line_of(node, "translate"), "length"), line or 0)]
    _require_map(ctx, node, fld, line, common | {"errors", "order", "sense"})
    block = node["errors"]
    bline = line_of(node, "errors")
    _require_map(ctx, block, f"{fld}.errors", bline, set(_BLOCK_KEYS))
    if not block:
        raise ctx.fail(f"an error block needs at least one of {', '.join(_BLOCK_KEYS)}", bline, f"{fld}.errors")
    vals = {k: _expr(ctx, block[k], symbols, f"{fld}.errors.{k}", line_of(block, k),
                     "length" if k.startswith("d") else "angle") if k in block
            else Expr(ZERO) for k in _BLOCK_KEYS}
    order = node.get("order", default_order)
    if order is None:
        raise ctx.fail("state the order of the error block's factors, e.g. 'order: txyz' "
                       "(T(dx,dy,dz)·Rx(ex)·Ry(ey)·Rz(ez)), here or as 'error_block_order' at the top",
                       line, f"{fld}.order")
    order = _block_order(ctx, order, f"{fld}.order", line_of(node, "order") or line)
    sense = _sense(ctx, node, fld, default_sense)
    out: list[Elementary] = []
    for factor in order:  # factors the block leaves at zero are identities: left out
        if factor == "t":
            if any(not vals[k].is_zero for k in ("dx", "dy", "dz")):
                out.append(Translation((vals["dx"], vals["dy"], vals["dz"]), line or 0))
        elif not vals["e" + factor].is_zero:
            out.append(Rotation(factor, vals["e" + factor].scaled(sense), line or 0))
    return out


# dh: standard Denavit-Hartenberg, Rz(theta)·Tz(d)·Tx(a)·Rx(alpha); mdh: Craig's modified,
# Rx(alpha)·Tx(a)·Rz(theta)·Tz(d); beta: Hayati's rotation about y, for nearly parallel
# consecutive axes. Parameters in internal units (mm, rad), right-handed whatever the
# machine's rotation_sense (the conventions define them so).
_JOINT_PARAMS = {"dh": ("theta", "d", "a", "alpha"), "mdh": ("alpha", "a", "theta", "d"), "beta": ("beta",)}
_JOINT_FACTOR = {"theta": ("rot", "z"), "d": ("trans", 2), "a": ("trans", 0), "alpha": ("rot", "x"),
                 "beta": ("rot", "y")}
_AUTO_UNIT = {"theta": "arcsec", "alpha": "arcsec", "beta": "arcsec", "d": "um", "a": "um"}


def _parse_joint(ctx: _Ctx, node, kind: str, fld: str, line, symbols) -> list[Elementary]:
    names = _JOINT_PARAMS[kind]
    _require_map(ctx, node, fld, line, {"label", kind, "errors"})
    if kind == "beta":
        values = {"beta": node["beta"]}
        vline = {"beta": line_of(node, "beta")}
    else:
        values = _require_map(ctx, node[kind], f"{fld}.{kind}", line_of(node, kind), set(names), set(names))
        vline = {k: line_of(values, k) for k in names}
        ctx.joint += 1
    joint = ctx.joint
    raw = node.get("errors", {})
    eline = line_of(node, "errors")
    if raw == "auto":
        raw = {k: "auto" for k in names}
    if not isinstance(raw, dict):
        raise ctx.fail(f"expected 'auto' or a mapping of {', '.join(names)} to error names, got {describe(raw)}",
                       eline, f"{fld}.errors")
    _require_map(ctx, raw, f"{fld}.errors", eline, set(names))
    errors: dict[str, str] = {}
    nominal: dict[str, Expr] = {}
    out: list[Elementary] = []
    for k in names:
        value = _expr(ctx, values[k], symbols, f"{fld}.{kind}.{k}" if kind != "beta" else f"{fld}.beta", vline[k],
                      "angle" if _JOINT_FACTOR[k][0] == "rot" else "length")
        nominal[k] = value
        if k in raw:
            err = raw[k]
            efld = f"{fld}.errors.{k}"
            if err == "auto":
                err = f"d{k}{joint}"
                # J restarts in each loop branch and a beta takes its joint's J: two elements
                # auto-naming one error would silently share it.
                if err in ctx.auto:
                    raise ctx.fail(f"'auto' names this error {err!r}, already auto-named by the element at "
                                   f"line {ctx.auto[err]}; name this element's errors explicitly",
                                   line_of(raw, k) or eline, efld)
                if err in ctx.table:   # declared, or named by an earlier element: sharing it is as silent
                    sym = next(s for s in ctx.symbols if s.name == err)
                    raise ctx.fail(f"'auto' names this error {err!r}, already declared "
                                   f"{f'on line {sym.line}' if sym.line else 'elsewhere'}; name this element's "
                                   "errors explicitly", line_of(raw, k) or eline, efld)
                ctx.auto[err] = line or 0
            elif not isinstance(err, str) or not NAME.match(err):
                raise ctx.fail(f"expected an error name or 'auto', got {describe(err)}", line_of(raw, k), efld)
            elif err in ctx.auto:
                raise ctx.fail(f"{err!r} is the error 'auto' named for the element at line {ctx.auto[err]}; "
                               "give each element its own errors", line_of(raw, k), efld)
            if err in RESERVED:
                raise ctx.fail(f"error name {err!r} is reserved", line_of(raw, k), efld)
            value = value.plus(ctx.declare_error(err, _AUTO_UNIT[k], f"joint {joint} {k} error ({kind})",
                                                 line_of(raw, k) or line or 0, efld))
            errors[k] = err
        what, where = _JOINT_FACTOR[k]
        if what == "rot":
            if not value.is_zero:
                out.append(Rotation(where, value, line or 0))
        elif not value.is_zero:
            vec = [Expr(ZERO)] * 3
            vec[where] = value
            out.append(Translation(tuple(vec), line or 0))
    if kind != "beta":
        ctx.joints.append((joint, kind, nominal["alpha"], errors, line or 0))
    return out


def _block_order(ctx: _Ctx, order, fld: str, line) -> str:
    if not isinstance(order, str) or sorted(order) != sorted("txyz"):
        raise ctx.fail(f"order must be a permutation of the letters t, x, y, z (e.g. 'txyz'), got {order!r}",
                       line, fld)
    return order


def _sense(ctx: _Ctx, node, fld: str, default: int | None) -> int:
    if "sense" in node:
        if not isinstance(node["sense"], str) or node["sense"] not in SENSES:
            raise ctx.fail(f"sense must be one of {', '.join(SENSES)}, got {node['sense']!r}",
                           line_of(node, "sense"), f"{fld}.sense")
        return SENSES[node["sense"]]
    if default is None:
        raise ctx.fail("no rotation sense: set 'rotation_sense' at the top of the file or 'sense' here",
                       line_of(node), fld)
    return default


def _parse_chain(ctx, node, fld, line, symbols, sense, order) -> tuple[Elementary, ...]:
    if not isinstance(node, list) or not node:
        raise ctx.fail(f"expected a non-empty list of chain elements, got {describe(node)}", line, fld)
    if len(node) > MAX_CHAIN_ELEMENTS:
        raise ctx.fail(f"{len(node)} chain elements (at most {MAX_CHAIN_ELEMENTS})", line, fld)
    out: list[Elementary] = []
    for i, el in enumerate(node):
        out.extend(_parse_element(ctx, el, f"{fld}[{i}]", line_of(node, i), symbols, sense, order))
    return tuple(out)


_TOP = {"name", "description", "length_unit", "rotation_sense", "error_block_order", "symbols",
        "chain", "loop", "tool"}


def load_machine(path: str) -> Machine:
    """Load and validate a machine description; every problem names file, line and field."""
    ctx = _Ctx(path)
    doc = load_yaml(path)
    top_line = getattr(doc, "line", 1)
    _require_map(ctx, doc, "(top level)", top_line, _TOP, {"name", "symbols", "tool"})
    name = doc["name"]
    if not isinstance(name, str) or not NAME.match(name):
        raise ctx.fail(f"machine name must be an identifier (letters, digits, '_'), got {name!r}",
                       line_of(doc, "name"), "name")
    if name in RESERVED:
        raise ctx.fail(f"machine name {name!r} is reserved (a C++ or Python word, or a name the generated "
                       f"code uses)", line_of(doc, "name"), "name")
    length_unit = doc.get("length_unit", "mm")
    if not isinstance(length_unit, str) or length_unit not in units.UNITS or \
            units.UNITS[length_unit].kind != "length":
        raise ctx.fail(f"length_unit must be a length unit, got {length_unit!r}",
                       line_of(doc, "length_unit"), "length_unit")
    sense = None
    if "rotation_sense" in doc:
        if not isinstance(doc["rotation_sense"], str) or doc["rotation_sense"] not in SENSES:
            raise ctx.fail(f"rotation_sense must be one of {', '.join(SENSES)}, got {doc['rotation_sense']!r}",
                           line_of(doc, "rotation_sense"), "rotation_sense")
        sense = SENSES[doc["rotation_sense"]]
    order = None
    if "error_block_order" in doc:
        order = _block_order(ctx, doc["error_block_order"], "error_block_order",
                             line_of(doc, "error_block_order"))

    raw_symbols = doc["symbols"]
    if not isinstance(raw_symbols, list) or not raw_symbols:
        raise ctx.fail(f"expected a non-empty list of symbols, got {describe(raw_symbols)}",
                       line_of(doc, "symbols"), "symbols")
    if len(raw_symbols) > MAX_SYMBOLS:
        raise ctx.fail(f"{len(raw_symbols)} symbols (at most {MAX_SYMBOLS})", line_of(doc, "symbols"), "symbols")
    symbols: list[Symbol] = []
    seen: dict[str, int] = {}
    for i, node in enumerate(raw_symbols):
        s = _parse_symbol(ctx, node, i, line_of(raw_symbols, i))
        if s.name in seen:
            raise ctx.fail(f"duplicate symbol name {s.name!r} (first declared on line {seen[s.name]})",
                           s.line, f"symbols[{i}].name")
        seen[s.name] = s.line
        symbols.append(s)
    table = {s.name: s for s in symbols}
    ctx.symbols, ctx.table = symbols, table   # dh/mdh/beta elements may add errors to both
    ctx.errors = {s.name for s in symbols if s.role == "error"}
    ctx.values = {s.name: s.reference_value for s in symbols}

    if ("chain" in doc) == ("loop" in doc):
        both = "loop" in doc
        raise ctx.fail("give exactly one of 'chain' (a serial chain) or 'loop' (tool and workpiece branches)",
                       line_of(doc, "loop") if both else top_line, "loop" if both else "chain")
    if "chain" in doc:
        tool_chain = _parse_chain(ctx, doc["chain"], "chain", line_of(doc, "chain"), table, sense, order)
        work_chain: tuple[Elementary, ...] = ()
    else:
        loop = _require_map(ctx, doc["loop"], "loop", line_of(doc, "loop"), {"tool", "workpiece"},
                            {"tool", "workpiece"})
        tool_chain = _parse_chain(ctx, loop["tool"], "loop.tool", line_of(loop, "tool"), table, sense, order)
        ctx.joint = 0   # joints are numbered per branch
        work_chain = _parse_chain(ctx, loop["workpiece"], "loop.workpiece", line_of(loop, "workpiece"),
                                  table, sense, order)

    tool = _require_map(ctx, doc["tool"], "tool", line_of(doc, "tool"),
                        {"point", "direction", "reference", "rotation"}, {"point"})
    point = _vector(ctx, tool["point"], table, "tool.point", line_of(tool, "point"), "length")
    direction = reference = None
    written: tuple = ()   # the tool vectors as written, for their exact sympy forms
    if "rotation" in tool:
        direction, reference, rows = _tool_rotation(ctx, tool, table)
        written = ("rotation", rows)
    elif "direction" in tool:
        d = _constant_vector(ctx, tool, "direction", table)
        direction = _normalised(ctx, _numbers(d), "direction", line_of(tool, "direction"), "tool.direction")
        written = ("direction", d, None)
        if "reference" in tool:
            r = _constant_vector(ctx, tool, "reference", table)
            reference = _orthogonal_part(ctx, tool, direction, _numbers(r))
            written = ("direction", d, r)
    elif "reference" in tool:
        raise ctx.fail("a tool reference needs a tool direction (the frame's z axis)", line_of(tool, "reference"),
                       "tool.reference")
    if len(symbols) > MAX_SYMBOLS:
        raise ctx.fail(f"{len(symbols)} symbols with the errors dh/mdh/beta elements name (at most {MAX_SYMBOLS})",
                       line_of(doc, "chain") or line_of(doc, "loop"), "chain" if "chain" in doc else "loop")
    exact = cache(partial(_tool_sympy, *written))   # both vectors' sympy forms, made once when asked

    def numbers(v, which: int):
        return None if v is None else tuple(Expr(("num", c), repr(c), partial(lambda i: exact()[which][i], i))
                                            for i, c in enumerate(v))
    machine = Machine(name, str(doc.get("description", "")), path, length_unit, tuple(symbols),
                      tool_chain, work_chain, point, numbers(direction, 0), read_text(path), tuple(ctx.joints),
                      reference=numbers(reference, 1))
    _check_usage(ctx, machine)
    return machine


def _constant_vector(ctx: _Ctx, tool, key: str, table) -> tuple[Expr, Expr, Expr]:
    v = _vector(ctx, tool[key], table, f"tool.{key}", line_of(tool, key))
    if any(c.names for c in v):
        raise ctx.fail(f"the tool {key} must be a constant vector", line_of(tool, key), f"tool.{key}")
    return v


def _numbers(v) -> list[float]:
    return [float(c.value({})) for c in v]


def _normalised(ctx: _Ctx, v: list[float], what: str, line, fld: str) -> list[float]:
    norm = math.sqrt(sum(c * c for c in v))
    if norm < 1e-12:
        raise ctx.fail(f"the tool {what} must not be zero", line, fld)
    return [c / norm for c in v]


def _orthogonal_part(ctx: _Ctx, tool, direction: list[float], r: list[float]) -> list[float]:
    """The tool frame's x axis: the part of tool.reference orthogonal to the direction, normalised."""
    norm_r = math.sqrt(sum(c * c for c in r))
    along = sum(a * b for a, b in zip(r, direction))
    x = [a - along * b for a, b in zip(r, direction)]
    if norm_r == 0 or math.sqrt(sum(c * c for c in x)) < 1e-6 * norm_r:
        raise ctx.fail("the tool reference must not be (nearly) parallel to the tool direction "
                       f"(its part orthogonal to the direction is the frame's x axis; got {r})",
                       line_of(tool, "reference"), "tool.reference")
    return _normalised(ctx, x, "reference", line_of(tool, "reference"), "tool.reference")


def _tool_rotation(ctx: _Ctx, tool, table):
    """tool.rotation: the frame's axes as the columns of a rotation matrix (rows written as
    lists): (direction = z column, reference = x column, the rows as written)."""
    line = line_of(tool, "rotation")
    for key in ("direction", "reference"):
        if key in tool:
            raise ctx.fail(f"give either tool.rotation or tool.direction/reference, not both", line_of(tool, key),
                           f"tool.{key}")
    rows = tool["rotation"]
    if not isinstance(rows, list) or len(rows) != 3:
        raise ctx.fail(f"expected three rows [[...], [...], [...]], got {describe(rows)}", line, "tool.rotation")
    m = [_vector(ctx, row, table, f"tool.rotation[{i}]", line) for i, row in enumerate(rows)]
    if any(c.names for row in m for c in row):
        raise ctx.fail("the tool rotation must be constant", line, "tool.rotation")
    f = [_numbers(row) for row in m]
    for i in range(3):
        for j in range(3):
            dot = sum(f[k][i] * f[k][j] for k in range(3))
            if abs(dot - (i == j)) > 1e-9:
                raise ctx.fail(f"the tool rotation is not orthonormal (columns {i} and {j}: dot product {dot!r}, "
                               "want within 1e-9 of 0 or 1)", line, "tool.rotation")
    det = (f[0][0] * (f[1][1] * f[2][2] - f[1][2] * f[2][1]) - f[0][1] * (f[1][0] * f[2][2] - f[1][2] * f[2][0])
           + f[0][2] * (f[1][0] * f[2][1] - f[1][1] * f[2][0]))
    if det < 0:
        raise ctx.fail("the tool rotation is a reflection (determinant -1)", line, "tool.rotation")
    z = _normalised(ctx, [f[k][2] for k in range(3)], "rotation", line, "tool.rotation")
    x = [f[k][0] for k in range(3)]
    along = sum(a * b for a, b in zip(x, z))
    return z, _normalised(ctx, [a - along * b for a, b in zip(x, z)], "rotation", line, "tool.rotation"), m


def _tool_sympy(kind: str, *written) -> tuple:
    """(direction, reference or None) in sympy from the tool vectors as written: exact unit
    vectors (nsimplify), as the derived formulas and generated code print them."""
    import sympy as sp

    def normalised(v):
        norm = sp.sqrt(sum(c**2 for c in v))
        return tuple(sp.nsimplify(c / norm) for c in v)

    def orthogonal(r, d):
        along = sum(a * b for a, b in zip(r, d))
        return normalised(tuple(sp.nsimplify(sp.expand(a - along * b)) for a, b in zip(r, d)))

    if kind == "rotation":
        m = [[c.to_sympy() for c in row] for row in written[0]]
        z = normalised(tuple(m[k][2] for k in range(3)))
        return z, orthogonal(tuple(m[k][0] for k in range(3)), z)
    d = normalised(tuple(c.to_sympy() for c in written[0]))
    return d, None if written[1] is None else orthogonal(tuple(c.to_sympy() for c in written[1]), d)


def _check_usage(ctx: _Ctx, machine: Machine) -> None:
    used: set[str] = set()
    for el in machine.chain:
        exprs = (el.expr,) if isinstance(el, Rotation) else el.exprs
        for e in exprs:
            used |= e.names
    for e in machine.point:
        used |= e.names
    for s in machine.symbols:
        if s.name not in used:
            raise ctx.fail(f"symbol {s.name!r} is declared but never used in the chain or tool", s.line,
                           f"symbols.{s.name}")
