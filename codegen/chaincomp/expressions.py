"""The math text of machine, check and tolerance files, parsed into sympy expressions by a
small recursive-descent parser that can only build arithmetic: nothing in the text is ever
evaluated as Python (no ``eval``, no ``parse_expr``).

Grammar (whitespace between tokens is free)::

    expr   := term (('+' | '-') term)*
    term   := unary (('*' | '/') unary)*
    unary  := ('+' | '-') unary | power
    power  := atom (('^' | '**') unary)?        # right-associative: a^b^c = a^(b^c)
    atom   := NUMBER | NAME | FUNC '(' expr (',' expr)* ')' | '(' expr ')'
    NUMBER := decimal digits with an optional fraction and exponent (1, 2.5, .5, 1e-3)
    NAME   := a declared symbol, or pi
    FUNC   := sin cos tan asin acos atan atan2 sqrt

The work sympy does on a parsed expression is bounded before it sees it: text length,
nesting depth, literal size, exponents (small constant rationals) and the degree a power
tower or product could expand to.
"""

from __future__ import annotations

import keyword
import math
import re

import sympy as sp

from .yamlsource import describe

FUNCTIONS = {
    "sin": sp.sin, "cos": sp.cos, "tan": sp.tan, "asin": sp.asin, "acos": sp.acos,
    "atan": sp.atan, "atan2": sp.atan2, "sqrt": sp.sqrt, "pi": sp.pi,
}
_ARITY = {"atan2": 2}

MAX_LENGTH = 1000      # characters of one expression
MAX_DEPTH = 32         # nesting of brackets, signs, powers and calls
MAX_LITERAL = 1e15     # magnitude of a number as written
MAX_LITERAL_CHARS = 40
MAX_EXPONENT = 64      # |p/q| of a power's constant exponent, and q
MAX_DEGREE = 64        # degree a product or power tower could expand to
MAX_MAGNITUDE = 1e100  # any number sympy folds the constants into

# C++ words and standard macros or library names the generated code would collide with.
_CXX = {
    "alignas", "alignof", "and", "and_eq", "asm", "auto", "bitand", "bitor", "bool", "break", "case",
    "catch", "char", "char8_t", "char16_t", "char32_t", "class", "compl", "concept", "const",
    "consteval", "constexpr", "constinit", "const_cast", "continue", "co_await", "co_return",
    "co_yield", "decltype", "default", "delete", "do", "double", "dynamic_cast", "else", "enum",
    "explicit", "export", "extern", "false", "float", "for", "friend", "goto", "if", "inline", "int",
    "long", "mutable", "namespace", "new", "noexcept", "not", "not_eq", "nullptr", "operator", "or",
    "or_eq", "private", "protected", "public", "register", "reinterpret_cast", "requires", "return",
    "short", "signed", "sizeof", "static", "static_assert", "static_cast", "struct", "switch",
    "template", "this", "thread_local", "throw", "true", "try", "typedef", "typeid", "typename",
    "union", "unsigned", "using", "virtual", "void", "volatile", "wchar_t", "while", "xor", "xor_eq",
    "final", "override", "main",
    # macros and names of <cmath>, <cerrno>, <cstdint>, <cassert> ... that the generated code includes
    "NAN", "INFINITY", "HUGE_VAL", "HUGE_VALF", "HUGE_VALL", "EOF", "NULL", "errno", "assert",
    "EDOM", "ERANGE", "EILSEQ", "FP_NAN", "FP_INFINITE", "FP_ZERO", "FP_NORMAL", "FP_SUBNORMAL",
    "M_PI", "M_E", "M_SQRT2", "DBL_MAX", "DBL_MIN", "DBL_EPSILON", "FLT_MAX", "INT_MAX", "INT_MIN",
    "SIZE_MAX", "stdin", "stdout", "stderr", "offsetof", "isnan", "isinf", "isfinite", "signbit",
    "fabs", "abs", "exp", "log", "pow", "fma", "hypot", "sincos", "floor", "ceil", "round",
    "unix", "linux", "i386", "BUFSIZ", "CHAR_BIT", "RAND_MAX", "EXIT_SUCCESS", "EXIT_FAILURE",
}
# Names a symbol may not take: the functions above, Python keywords, sympy's own names that
# printed formulas would read wrongly, C++ words and macros, and names the generated code uses.
RESERVED = set(FUNCTIONS) | set(keyword.kwlist) | _CXX | {
    "Integer", "Float", "Rational", "Symbol", "Function", "factorial",
    "E", "I", "oo", "nan", "zoo", "S", "N", "O", "Q", "lambda",
    "model", "params", "out", "ws", "std", "Eigen", "chaincomp", "Model", "Params", "Axes", "Pose",
    "Trig", "Workspace", "Status",
}

# An identifier, matched on the whole string (\Z: '$' would also match before a final newline).
NAME = re.compile(r"[A-Za-z][A-Za-z0-9_]*\Z")
# [0-9], not \d: \d takes every script's digits, which float() then reads as numbers.
_TOKEN = re.compile(r"\s*(?:(?P<num>(?:[0-9]+\.?[0-9]*|\.[0-9]+)(?:[eE][-+]?[0-9]+)?)|(?P<name>[A-Za-z_][A-Za-z0-9_]*)"
                    r"|(?P<op>\*\*|[-+*/^(),]))")


class ExpressionError(ValueError):
    pass


def _shown(source: str) -> str:
    return repr(source if len(source) <= 80 else source[:77] + "...")


class _Parser:
    def __init__(self, source: str, symbols: dict[str, sp.Symbol]):
        self.source = source
        self.symbols = symbols
        self.tokens = self._tokenize(source)
        self.pos = 0
        self.depth = 0

    def fail(self, why: str) -> ExpressionError:
        return ExpressionError(f"cannot parse expression {_shown(self.source)}: {why}")

    def _tokenize(self, s: str) -> list[tuple[str, str]]:
        out, i = [], 0
        while i < len(s):
            if s[i:].strip() == "":
                break
            m = _TOKEN.match(s, i)
            if not m:
                ch = s[i:].lstrip()[0]
                raise self.fail(f"unexpected character {ch!r}")
            kind = m.lastgroup
            out.append((kind, m.group(kind)))
            i = m.end()
            if kind in ("num", "name") and i < len(s) and (s[i].isalnum() or s[i] in "._"):
                raise self.fail(f"unexpected {s[i]!r} after {m.group(kind)!r}")
        return out

    def peek(self) -> str | None:
        return self.tokens[self.pos][1] if self.pos < len(self.tokens) else None

    def take(self, want: str | None = None) -> tuple[str, str]:
        if self.pos >= len(self.tokens):
            raise self.fail("it ends too early" + (f" (expected {want!r})" if want else ""))
        tok = self.tokens[self.pos]
        if want is not None and tok[1] != want:
            raise self.fail(f"expected {want!r}, found {tok[1]!r}")
        self.pos += 1
        return tok

    def enter(self) -> None:
        self.depth += 1
        if self.depth > MAX_DEPTH:
            raise ExpressionError(f"expression {_shown(self.source)} is nested more than {MAX_DEPTH} deep")

    # Each rule returns (expression, degree): the degree bounds what expanding it could give.
    def expr(self):
        self.enter()
        e, d = self.term()
        while self.peek() in ("+", "-"):
            op = self.take()[1]
            f, g = self.term()
            e, d = (e + f if op == "+" else e - f), max(d, g)
        self.depth -= 1
        return e, d

    def term(self):
        e, d = self.unary()
        while self.peek() in ("*", "/"):
            op = self.take()[1]
            f, g = self.unary()
            if op == "/" and f == 0:
                raise ExpressionError(f"division by zero in {_shown(self.source)}")
            e, d = (e * f if op == "*" else e / f), self._degree(d + g)
        return e, d

    def unary(self):
        if self.peek() in ("+", "-"):
            self.enter()
            op = self.take()[1]
            e, d = self.unary()
            self.depth -= 1
            return (e if op == "+" else -e), d
        return self.power()

    def power(self):
        base, d = self.atom()
        if self.peek() not in ("^", "**"):
            return base, d
        self.enter()
        self.take()
        exp, _ = self.unary()
        self.depth -= 1
        if exp.free_symbols or not exp.is_Rational:
            raise ExpressionError(f"exponent {exp} in {_shown(self.source)}: exponents must be constant "
                                  f"rational numbers (write a varying power with sqrt, sin, ...)")
        if abs(exp) > MAX_EXPONENT or exp.q > MAX_EXPONENT:
            raise ExpressionError(f"exponent {exp} in {_shown(self.source)} is larger than {MAX_EXPONENT}")
        if base == 0 and exp < 0:
            raise ExpressionError(f"division by zero in {_shown(self.source)}")
        if base.is_Number and abs(exp) * math.log10(max(abs(base.p), base.q, 1)) > math.log10(MAX_MAGNITUDE):
            raise ExpressionError(f"{_shown(self.source)} holds a number larger than {MAX_MAGNITUDE:g}")
        return base ** exp, self._degree(d * math.ceil(abs(exp)))

    def atom(self):
        kind, text = self.take()
        if kind == "num":
            return self._number(text), 0
        if kind == "name":
            if text in FUNCTIONS and text != "pi":
                return self._call(text)
            if self.peek() == "(":
                raise ExpressionError(f"unknown function {text!r} in {_shown(self.source)} "
                                      f"(known: {', '.join(sorted(k for k in FUNCTIONS if k != 'pi'))})")
            if text == "pi":
                return sp.pi, 0
            if text not in self.symbols:
                raise ExpressionError(f"unknown symbol {text!r} in {_shown(self.source)} "
                                      f"(declare it under 'symbols')")
            return self.symbols[text], 1
        if text == "(":
            e = self.expr()
            self.take(")")
            return e
        raise self.fail(f"unexpected {text!r}")

    def _call(self, name: str):
        self.enter()
        self.take("(")
        args, deg = [self.expr()[0]], 1
        while self.peek() == ",":
            self.take()
            args.append(self.expr()[0])
        self.take(")")
        self.depth -= 1
        want = _ARITY.get(name, 1)
        if len(args) != want:
            raise ExpressionError(f"{name} takes {want} argument{'s' if want > 1 else ''}, got {len(args)} "
                                  f"in {_shown(self.source)}")
        return FUNCTIONS[name](*args), deg

    def _number(self, text: str) -> sp.Rational:
        if len(text) > MAX_LITERAL_CHARS:
            raise ExpressionError(f"number {text[:20]}... in {_shown(self.source)} has more than "
                                  f"{MAX_LITERAL_CHARS} characters")
        value = float(text)
        if not abs(value) <= MAX_LITERAL:
            raise ExpressionError(f"number {text} in {_shown(self.source)} is larger than {MAX_LITERAL:g}")
        if value == 0:
            return sp.Integer(0)
        if abs(value) < 1 / MAX_LITERAL**2:
            raise ExpressionError(f"number {text} in {_shown(self.source)} is smaller than "
                                  f"{1 / MAX_LITERAL**2:g} (write 0, or use a smaller unit)")
        return sp.Rational(text)

    def _degree(self, d: int) -> int:
        if d > MAX_DEGREE:
            raise ExpressionError(f"expression {_shown(self.source)} would expand to a polynomial of degree "
                                  f"over {MAX_DEGREE}")
        return d


def parse(text: object, symbols: dict[str, sp.Symbol]) -> sp.Expr:
    """Parse ``text`` (a string or number) using only the declared ``symbols``.

    Decimal numbers become exact rationals, so derived formulas stay exact. Raises
    ExpressionError, with the text, for anything outside the grammar or its bounds.
    """
    if isinstance(text, bool) or not isinstance(text, (str, int, float)):
        raise ExpressionError(f"expected a number or an expression, got {describe(text)}")
    if isinstance(text, (int, float)):
        if not (isinstance(text, int) or math.isfinite(text)):
            raise ExpressionError(f"expected a finite number, got {text!r}")
        if isinstance(text, int) and abs(text) > MAX_LITERAL:
            raise ExpressionError(f"number {str(text)[:20]}{'...' if len(str(text)) > 20 else ''} is larger "
                                  f"than {MAX_LITERAL:g}")
        source = repr(text)
    else:
        source = text.strip()
    if not source:
        raise ExpressionError("empty expression")
    if len(source) > MAX_LENGTH:
        raise ExpressionError(f"expression of {len(source)} characters (at most {MAX_LENGTH})")
    p = _Parser(source, symbols)
    expr, _ = p.expr()
    if p.pos != len(p.tokens):
        raise p.fail(f"unexpected {p.tokens[p.pos][1]!r}")
    if expr.has(sp.zoo, sp.oo, -sp.oo, sp.nan):
        raise ExpressionError(f"{_shown(source)} is not finite")
    # I itself, and constants sympy keeps unevaluated off the real line: (-8)^(1/3), acos(2)
    if expr.has(sp.I) or any(n.is_number and n.is_real is False for n in sp.preorder_traversal(expr)):
        raise ExpressionError(f"{_shown(source)} is not real")
    for n in expr.atoms(sp.Number):
        if abs(n) > MAX_MAGNITUDE:
            raise ExpressionError(f"{_shown(source)} holds a number larger than {MAX_MAGNITUDE:g}")
    return expr
