"""Safe parsing of the math text in machine files into sympy expressions."""

from __future__ import annotations

import keyword
import tokenize

import sympy as sp
from sympy.core.function import AppliedUndef
from sympy.parsing.sympy_parser import (auto_number, auto_symbol, factorial_notation,
                                        parse_expr, repeated_decimals)

FUNCTIONS = {
    "sin": sp.sin, "cos": sp.cos, "tan": sp.tan, "asin": sp.asin, "acos": sp.acos,
    "atan": sp.atan, "atan2": sp.atan2, "sqrt": sp.sqrt, "pi": sp.pi,
}
# Names a symbol may not take: the functions above, Python keywords and the names the parser
# itself calls (a symbol called 'Integer' would break every number), and words the generated C++ needs.
RESERVED = set(FUNCTIONS) | set(keyword.kwlist) | {
    "Integer", "Float", "Rational", "Symbol", "Function", "factorial",
    "E", "I", "oo", "nan", "zoo", "S", "N", "O", "Q", "lambda", "and", "or", "not", "if",
    "else", "for", "while", "do", "int", "double", "float", "char", "long", "short", "void",
    "auto", "const", "static", "struct", "class", "namespace", "return", "switch", "case",
    "default", "new", "delete", "this", "true", "false", "operator", "template", "typename",
    "using", "union", "enum", "goto", "break", "continue", "register", "volatile", "signed",
    "unsigned", "sizeof", "friend", "inline", "virtual", "public", "private", "protected",
    "try", "catch", "throw", "bool", "extern", "mutable", "explicit", "export", "typedef",
    "model", "params", "out", "ws", "std", "Eigen",
}
_TRANSFORMS = (auto_symbol, repeated_decimals, auto_number, factorial_notation)
_GLOBALS = {"Integer": sp.Integer, "Float": sp.Float, "Rational": sp.Rational,
            "Symbol": sp.Symbol, "Function": sp.Function, "factorial": sp.factorial}


class ExpressionError(ValueError):
    pass


def parse(text: object, symbols: dict[str, sp.Symbol]) -> sp.Expr:
    """Parse ``text`` (a string or number) using only the declared ``symbols``.

    Decimal numbers become exact rationals, so derived formulas stay exact.
    """
    if isinstance(text, bool) or not isinstance(text, (str, int, float)):
        raise ExpressionError(f"expected a number or an expression, got {text!r}")
    source = str(text).strip()
    if not source:
        raise ExpressionError("empty expression")
    source = source.replace("^", "**")  # both spellings of a power, even mixed
    local = dict(FUNCTIONS)
    local.update(symbols)
    try:
        expr = parse_expr(source, local_dict=local, global_dict=dict(_GLOBALS),
                          transformations=_TRANSFORMS, evaluate=True)
    except (SyntaxError, tokenize.TokenError, TypeError, AttributeError, ValueError) as exc:
        raise ExpressionError(f"cannot parse expression {source!r}: {exc.__class__.__name__}") from None
    if not isinstance(expr, sp.Expr):
        raise ExpressionError(f"{source!r} is not an expression")
    unknown_funcs = sorted({str(f.func) for f in expr.atoms(AppliedUndef)})
    if unknown_funcs:
        raise ExpressionError(f"unknown function {unknown_funcs[0]!r} in {source!r} "
                              f"(known: {', '.join(sorted(k for k in FUNCTIONS if k != 'pi'))})")
    declared = set(symbols.values())
    unknown = sorted(str(s) for s in expr.free_symbols if s not in declared)
    if unknown:
        raise ExpressionError(f"unknown symbol {unknown[0]!r} in {source!r} (declare it under 'symbols')")
    expr = expr.xreplace({f: sp.Rational(str(f)) for f in expr.atoms(sp.Float)})
    if expr.has(sp.zoo, sp.oo, sp.nan, -sp.oo):
        raise ExpressionError(f"{source!r} is not finite")
    return expr
