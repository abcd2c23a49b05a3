"""The math text of machine, check and tolerance files, parsed by a small recursive-descent
parser that can only build arithmetic: nothing in the text is ever evaluated as Python (no
``eval``, no sympy ``parse_expr``). It builds a small immutable tree of our own (Expr), which
evaluates numerically (numbers, numpy arrays, mpmath) and as truncated Taylor series in the
errors without sympy; ``Expr.to_sympy`` builds the sympy expression, operation by operation,
for the symbolic verbs, which alone import sympy.

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
nesting depth, literal size, exponents (small constant rationals), the degree a power
tower or product could expand to and the number of terms it could expand to (a multinomial
(a+b+c+d+e)^64 is of degree 64 but has 635 376 terms). A chain of sums or products is built
as a balanced tree, so a flat sum of hundreds of terms is not hundreds of levels deep.
"""

from __future__ import annotations

import keyword
import math
import re
from fractions import Fraction

from . import jetmath as J
from .yamlsource import describe

# The functions the grammar knows (and pi): their sympy forms are looked up by name.
FUNCTIONS = ("sin", "cos", "tan", "asin", "acos", "atan", "atan2", "sqrt", "pi")
_ARITY = {"atan2": 2}

MAX_LENGTH = 1000      # characters of one expression
MAX_DEPTH = 32         # nesting of brackets, signs, powers and calls
MAX_LITERAL = 1e15     # magnitude of a number as written
MAX_LITERAL_CHARS = 40
MAX_EXPONENT = 64      # |p/q| of a power's constant exponent, and q
MAX_DEGREE = 64        # degree a product or power tower could expand to
MAX_TERMS = 1000       # terms any part of an expression could expand to (sympy's expand: derive)
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


# ----------------------------------------------------------------------------- the tree
# A node is a tuple: ("num", Fraction or float), ("sym", name), ("pi",), ("add"|"sub"|"mul"|"div",
# a, b), ("neg", a), ("pow", a, Fraction exponent), or a function's name with its arguments
# ("sin", a), ("atan2", y, x).
ZERO = ("num", Fraction(0))


def _balanced(op: str, nodes: list):
    """``nodes`` joined by ``op`` (add or mul) as a balanced tree: the same value as the chain
    the text reads, but log2(n) levels deep rather than n. Every function over the tree
    recurses (evaluation, series, sympy); a flat sum of 500 terms overflowed Python's stack."""
    if len(nodes) == 1:
        return nodes[0]
    half = len(nodes) // 2
    return (op, _balanced(op, nodes[:half]), _balanced(op, nodes[half:]))


def _chain(op: str, inverse: str, items: list):
    """The tree of ``a op b inverse c ...`` (``items``: (is op, node), the first an op): the
    terms of op balanced, then ``inverse`` of the balanced others once, so a divisor stays a
    divisor (a*b/c*d is (a*b*d)/c, never a*b/(c/d), which would divide by d)."""
    ups = [n for up, n in items if up]
    downs = [n for up, n in items if not up]
    node = _balanced(op, ups)
    return (inverse, node, _balanced(op, downs)) if downs else node


def fold(node) -> Fraction | None:
    """The exact value of a node built from numbers by + - * / and integer powers, else None."""
    op = node[0]
    if op == "num":
        return node[1] if isinstance(node[1], Fraction) else None
    if op == "neg":
        a = fold(node[1])
        return None if a is None else -a
    if op == "pow":
        a = fold(node[1])
        if a is None or node[2].denominator != 1 or (a == 0 and node[2] < 0):
            return None
        return a ** int(node[2])
    if op in ("add", "sub", "mul", "div"):
        a, b = fold(node[1]), fold(node[2])
        if a is None or b is None or (op == "div" and b == 0):
            return None
        return a + b if op == "add" else a - b if op == "sub" else a * b if op == "mul" else a / b
    return None


def _names(node, out: set) -> set:
    if node[0] == "sym":
        out.add(node[1])
    elif node[0] not in ("num", "pi"):
        for a in node[1:]:
            if isinstance(a, tuple):
                _names(a, out)
    return out


def linear_names(node) -> list[str] | None:
    """The symbols of ``node`` if it is a sum of symbols, each times a constant (no symbol in
    the constant), plus constants: ``-X``, ``j1 + j1_zero``, ``(j2 + j2_zero)/sqrt(2)``; else None
    (a product of symbols, a function of one: ``L*EBX``, ``Y*sin(EC0Y)``). Such a sum has the
    dimension of each of its symbols, which the machine loader holds against where it stands."""
    op = node[0]
    if op == "sym":
        return [node[1]]
    if op in ("num", "pi") or not _names(node, set()):
        return []
    if op == "neg":
        return linear_names(node[1])
    if op in ("add", "sub"):
        a, b = linear_names(node[1]), linear_names(node[2])
        return None if a is None or b is None else a + b
    if op == "mul":
        a_const, b_const = not _names(node[1], set()), not _names(node[2], set())
        if a_const or b_const:
            return linear_names(node[2] if a_const else node[1])
        return None
    if op == "div" and not _names(node[2], set()):
        return linear_names(node[1])
    return None


def _real_symbols(names) -> dict:
    import sympy as sp
    return {n: sp.Symbol(n, real=True) for n in names}


def _size(number) -> float:
    """The larger of a number's numerator and denominator (a rational), or of its magnitude and
    inverse (a float: a function of constants made a number), at least 1: what a power multiplies."""
    if number.is_Rational:
        return float(max(abs(number.p), number.q, 1))
    value = abs(float(number))
    return max(value, 1.0 / value if value else 1.0, 1.0)


def _to_sympy(node, table: dict, source: str):
    """The sympy expression of ``node``, built by the same operations in the same order as
    the text reads, with sympy's own view of what is zero (x/(a - a) divides by zero)."""
    import sympy as sp
    op = node[0]
    if op == "num":
        v = node[1]
        return sp.Rational(v.numerator, v.denominator) if isinstance(v, Fraction) else sp.Float(v)
    if op == "sym":
        return table[node[1]]
    if op == "pi":
        return sp.pi
    if op == "neg":
        return -_to_sympy(node[1], table, source)
    if op == "pow":
        base, exp = _to_sympy(node[1], table, source), sp.Rational(node[2].numerator, node[2].denominator)
        if base == 0 and exp < 0:
            raise ExpressionError(f"division by zero in {_shown(source)}")
        if base.is_Number and abs(exp) * math.log10(_size(base)) > math.log10(MAX_MAGNITUDE):
            raise ExpressionError(f"{_shown(source)} holds a number larger than {MAX_MAGNITUDE:g}")
        return base ** exp
    args = [_to_sympy(a, table, source) for a in node[1:]]
    if op == "add":
        return args[0] + args[1]
    if op == "sub":
        return args[0] - args[1]
    if op == "mul":
        return args[0] * args[1]
    if op == "div":
        if args[1] == 0:
            raise ExpressionError(f"division by zero in {_shown(source)}")
        return args[0] / args[1]
    return numeric_constant(getattr(sp, op)(*args))


# Digits of a function of a constant evaluated to a number (numeric_constant): past a double's 17.
CONSTANT_DIGITS = 20


def numeric_constant(e):
    """``e`` as a number (sp.Float of CONSTANT_DIGITS digits) when it is a constant that sympy
    can only keep as a function application: sin(157079632679/100000000000), cos(3/10),
    atan(2). Kept exact, each such value became a new generator of the derivation's
    coefficients, the product of every rotation by a decimal angle (a URDF's 1.5707963268, a
    calibrated 3.1408) expanded over them and a 7-axis arm did not derive in 300 s (#41).
    What sympy knows in closed form stays exact: sin(pi/2) = 1, cos(pi/4) = sqrt(2)/2, so a
    rotation by pi/2 still swaps two axes exactly."""
    import sympy as sp
    if e.is_number and not e.is_Number and e.has(sp.Function) and e.is_real:   # acos(2): refused as not real
        return sp.Float(e.evalf(CONSTANT_DIGITS), CONSTANT_DIGITS)
    return e


# A numeric sine or cosine of a rotation below this is 0 (and the other +-1): sin_cos.
QUARTER_TURN_TOLERANCE = 1e-9


def sin_cos(angle):
    """The sine and cosine of a rotation's angle (sympy): exact where sympy knows them (of a
    symbol, of pi/2, pi/6), numbers where the angle is a constant sympy does not (numeric_constant).
    A numeric one below QUARTER_TURN_TOLERANCE is 0 and the other +-1: a URDF's quarter turn
    written 1.57079632679 (cos 4.9e-12) or 1.570796327 (UR: cos -2e-10) turns as pi/2 does,
    which moves a point 1 m away by under 1 nm; kept, the tiny factor crossed every
    component into the other and a Kinova's order-1 derivation held 58 213 terms, not 832.
    A calibrated angle (a joint roll of 3.1408: sine 8e-4) keeps its value."""
    import sympy as sp
    s, c = numeric_constant(sp.sin(angle)), numeric_constant(sp.cos(angle))
    if s.is_Float and abs(s) < QUARTER_TURN_TOLERANCE:
        return sp.Integer(0), sp.Integer(1 if c > 0 else -1)
    if c.is_Float and abs(c) < QUARTER_TURN_TOLERANCE:
        return sp.Integer(1 if s > 0 else -1), sp.Integer(0)
    return s, c


class Expr:
    """A parsed expression: an immutable tree (see above), its source text for messages, and
    its sympy form once built (or given: an expression sympy rewrote, see from_sympy)."""

    __slots__ = ("node", "source", "_names", "_sympy", "terms")

    def __init__(self, node, source: str = "", sympy_form=None):
        self.node, self.source = node, source
        self.terms = 1   # parsed: the bound on the terms it could expand to (the parser's)
        self._names = None
        self._sympy = sympy_form   # a sympy expression, a function making one, or None

    def __eq__(self, other):
        return isinstance(other, Expr) and self.node == other.node

    def __hash__(self):
        return hash(self.node)

    def __repr__(self):
        return f"Expr({self.source or self.node!r})"

    @property
    def names(self) -> frozenset:
        """The names of the symbols it uses."""
        if self._names is None:
            self._names = frozenset(_names(self.node, set()))
        return self._names

    @property
    def is_zero(self) -> bool:
        return fold(self.node) == 0

    # New trees from this one; their sympy forms are made from this one's, by the same operation.
    def __neg__(self) -> "Expr":
        return Expr(("neg", self.node), self.source, lambda: -self.to_sympy())

    def plus(self, name: str) -> "Expr":
        """This + the symbol ``name`` (a dh parameter and its error)."""
        return Expr(("add", self.node, ("sym", name)), self.source,
                    lambda: self.to_sympy() + _real_symbols([name])[name])

    def scaled(self, k: int) -> "Expr":
        """k·this, for a rotation sense of ±1."""
        return Expr(("mul", ("num", Fraction(k)), self.node), self.source, lambda: k * self.to_sympy())

    def to_sympy(self, table: dict | None = None):
        """The sympy expression (symbols from ``table``, by default real symbols of the names)."""
        if table is not None and self._sympy is None:
            return _to_sympy(self.node, table, self.source)
        if callable(self._sympy):
            self._sympy = self._sympy()
        if self._sympy is None:
            self._sympy = _to_sympy(self.node, _real_symbols(self.names), self.source)
        return self._sympy

    def function(self, lib):
        """A function of a {name: value} mapping giving the value (numbers or arrays)."""
        return _compile(self.node, lib)

    def value(self, values: dict, lib=math):
        return _compile(self.node, lib)(values)

    def jet(self, values: dict, index: dict, k: int, lib) -> dict:
        """The Taylor series to degree ``k`` in the symbols of ``index`` (name -> position) at
        ``values`` of the others: {monomial: coefficient}, as chaincomp.series."""
        return _jet(self.node, values, index, k, lib)


def constant(value: float) -> Expr:
    """A number already computed (a normalised tool vector's component)."""
    return Expr(("num", float(value)), repr(value))


def from_sympy(expr, source: str = "") -> Expr:
    """The tree of a sympy expression (one sympy rewrote: the tree keeps that form exactly)."""
    import sympy as sp

    def node(e):
        if e.is_Rational:
            return ("num", Fraction(int(e.p), int(e.q)))
        if e.is_Float:   # a function of constants made a number (numeric_constant)
            return ("num", float(e))
        if e.is_Symbol:
            return ("sym", e.name)
        if e is sp.pi:
            return ("pi",)
        if e.is_Add or e.is_Mul:
            return _balanced("add" if e.is_Add else "mul", [node(a) for a in e.args])
        if e.is_Pow and e.exp.is_Rational:
            return ("pow", node(e.base), Fraction(int(e.exp.p), int(e.exp.q)))
        if isinstance(e, sp.Abs):   # sqrt(x^2) of a real x
            return ("pow", ("pow", node(e.args[0]), Fraction(2)), Fraction(1, 2))
        name = type(e).__name__
        if name in FUNCTIONS and name != "pi":
            return (name,) + tuple(node(a) for a in e.args)
        raise ExpressionError(f"{_shown(source)} becomes {e}, which chaincomp cannot evaluate")
    return Expr(node(expr), source, expr)


# ----------------------------------------------------------------------------- numbers

_FUNCTIONS_OF: dict = {}


def _lib_functions(lib) -> dict:
    """The grammar's functions in ``lib`` (math, numpy or mpmath), by the grammar's names."""
    if lib.__name__ not in _FUNCTIONS_OF:
        names = {"asin": "arcsin", "acos": "arccos", "atan": "arctan", "atan2": "arctan2"} \
            if lib.__name__ == "numpy" else {}
        _FUNCTIONS_OF[lib.__name__] = {f: getattr(lib, names.get(f, f)) for f in FUNCTIONS if f != "pi"}
    return _FUNCTIONS_OF[lib.__name__]


def _number(v, lib):
    """A tree's number for ``lib``: mpmath keeps its precision, the others take floats."""
    if lib.__name__ == "mpmath":
        return lib.mpf(v.numerator) / v.denominator if isinstance(v, Fraction) else lib.mpf(v)
    return float(v)


def _power(a, p: Fraction, lib):
    if p.denominator == 1:
        return a ** int(p)
    if p == Fraction(1, 2):
        return _lib_functions(lib)["sqrt"](a)
    return a ** _number(p, lib)


def _compile(node, lib):
    """Closures over the tree (no source text is generated and run)."""
    op = node[0]
    if op == "num":
        c = _number(node[1], lib)
        return lambda v: c
    if op == "sym":
        name = node[1]
        return lambda v: v[name]
    if op == "pi":
        c = lib.pi
        return lambda v: c
    if op == "neg":
        f = _compile(node[1], lib)
        return lambda v: -f(v)
    if op == "pow":
        f, p = _compile(node[1], lib), node[2]
        return lambda v: _power(f(v), p, lib)
    fs = [_compile(a, lib) for a in node[1:]]
    if op in ("add", "sub", "mul", "div"):
        f, g = fs
        return {"add": lambda v: f(v) + g(v), "sub": lambda v: f(v) - g(v),
                "mul": lambda v: f(v) * g(v), "div": lambda v: f(v) / g(v)}[op]
    fn = _lib_functions(lib)[op]
    if len(fs) == 2:
        f, g = fs
        return lambda v: fn(f(v), g(v))
    f = fs[0]
    return lambda v: fn(f(v))


# ----------------------------------------------------------------------------- jets

def _jet(node, values: dict, index: dict, k: int, lib) -> dict:
    op = node[0]
    if op == "num":
        return {(): _number(node[1], lib)}
    if op == "sym":
        return {(index[node[1]],): 1} if node[1] in index else {(): values[node[1]]}
    if op == "pi":
        return {(): lib.pi}
    if op == "neg":
        return {m: -c for m, c in _jet(node[1], values, index, k, lib).items()}
    args = [_jet(a, values, index, k, lib) for a in node[1:] if isinstance(a, tuple)]
    if op == "add":
        return J.lin(args[0], 1, args[1], 1)
    if op == "sub":
        return J.lin(args[0], 1, args[1], -1)
    if op == "mul":
        return J.mul_all(args[0], args[1], k)
    fn = _lib_functions(lib)
    if op == "div":
        return J.mul_all(args[0], J.power(args[1], -1, k, lambda a, p: _power(a, p, lib)), k)
    if op == "pow":
        return J.power(args[0], node[2], k, lambda a, p: _power(a, p, lib))
    if op == "sqrt":
        return J.power(args[0], Fraction(1, 2), k, lambda a, p: _power(a, p, lib))
    if op in ("sin", "cos", "tan"):
        s, c = J.sin_cos_at(args[0], k, fn["sin"], fn["cos"])
        return s if op == "sin" else c if op == "cos" else \
            J.mul_all(s, J.power(c, -1, k, lambda a, p: _power(a, p, lib)), k)
    if op in ("atan", "asin", "acos"):
        return J.inverse_trig(op, args[0], k, fn[op], lambda a, p: _power(a, p, lib))
    if op == "atan2":
        return J.atan2(args[0], args[1], k, fn["atan2"], lambda a, p: _power(a, p, lib))
    raise AssertionError(op)


# ----------------------------------------------------------------------------- load checks

class _Doubtful(Exception):
    pass


def plausible(e: Expr, values: dict, errors: set) -> bool:
    """Whether ``e`` is, beyond doubt, finite and real at ``values`` (floats, errors at zero),
    analytic in the ``errors`` there and free of numbers sympy would find too large. Cheap
    and numeric; where it doubts, the loader asks sympy (which has the last word and the
    messages): a division by something that vanishes at these values, a power, asin or acos,
    tan or atan2 near where it is not analytic, anything not finite or not real."""
    try:
        _screen(e.node, values, errors)
    except (_Doubtful, ArithmeticError, ValueError, TypeError):
        return False
    return True


_NEAR = 1e-9   # far below any value a machine means, far above rounding of a symbolic zero


def _screen(node, values, errors):
    """(value, whether it varies with an error, log10 of a bound on the height of any rational
    number sympy could fold out of it)."""
    op = node[0]
    if op == "num":
        v = node[1]
        h = math.log10(max(abs(v.numerator), v.denominator, 1)) if isinstance(v, Fraction) else 0.0
        return float(v), False, h
    if op == "sym":
        return float(values[node[1]]), node[1] in errors, 0.0
    if op == "pi":
        return math.pi, False, 0.0
    parts = [_screen(a, values, errors) for a in node[1:] if isinstance(a, tuple)]
    x = [p[0] for p in parts]
    err = any(p[1] for p in parts)
    h = sum(p[2] for p in parts) + math.log10(2) * (len(parts) - 1)
    if op == "neg":
        v = -x[0]
    elif op in ("add", "sub", "mul"):
        v = x[0] + x[1] if op == "add" else x[0] - x[1] if op == "sub" else x[0] * x[1]
        if op != "mul" and abs(v) <= 1e-12 * max(abs(x[0]), abs(x[1])):
            v = 0.0   # cancelled to rounding: perhaps a symbolic zero (1e15*sqrt(2)^2 - 2e15), doubted as one
    elif op == "div":
        if abs(x[1]) < _NEAR:
            raise _Doubtful
        v = x[0] / x[1]
    elif op in ("pow", "sqrt"):
        p = node[2] if op == "pow" else Fraction(1, 2)
        h = parts[0][2] * math.ceil(abs(p)) + math.log10(MAX_EXPONENT)
        natural = p.denominator == 1 and p >= 0
        if not natural and abs(x[0]) < _NEAR and (p < 0 or err):
            raise _Doubtful
        if not natural and x[0] < 0 and p.denominator != 1:
            raise _Doubtful
        v = x[0] ** (int(p) if p.denominator == 1 else float(p))
    elif op in ("asin", "acos"):
        if abs(x[0]) > 1 - _NEAR:
            raise _Doubtful
        v = getattr(math, op)(x[0])
    elif op == "tan":
        if abs(math.cos(x[0])) < _NEAR:
            raise _Doubtful
        v = math.tan(x[0])
    elif op == "atan2":
        if abs(x[0]) < _NEAR and (abs(x[1]) < _NEAR or x[1] < 0):
            raise _Doubtful
        v = math.atan2(x[0], x[1])
    else:
        v = getattr(math, op)(x[0])
        h += 2   # sympy folds constants of known values: sin(pi/6) = 1/2
    if isinstance(v, complex) or not math.isfinite(v) or abs(v) > MAX_MAGNITUDE or h > math.log10(MAX_MAGNITUDE):
        raise _Doubtful
    return v, err, h


# ----------------------------------------------------------------------------- parsing

class _Parser:
    def __init__(self, source: str, names):
        self.source = source
        self.names = names
        self.tokens = self._tokenize(source)
        self.pos = 0
        self.depth = 0
        self.inner = 0   # the terms of the parts expanded on their own: calls' arguments, divisors

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

    # Each rule returns (node, degree, terms): what expanding it could give, as sympy's expand
    # does for derive: its degree, and a bound on its terms. Products distribute (terms
    # multiply), a natural power is a multinomial (C(t+p-1, p) terms of a sum of t), sums add;
    # a call, a divisor and a power that is not natural are one term, their own expansion
    # bounded where they are read.
    def expr(self):
        self.enter()
        items = [(True, *self.term())]
        while self.peek() in ("+", "-"):
            op = self.take()[1]
            items.append((op == "+", *self.term()))
        self.depth -= 1
        node = _chain("add", "sub", [(up, n) for up, n, _, _ in items])
        return node, max(d for _, _, d, _ in items), self._terms(sum(t for _, _, _, t in items))

    def term(self):
        items = [(True, *self.unary())]
        degree, terms = items[0][2], items[0][3]
        while self.peek() in ("*", "/"):
            op = self.take()[1]
            f, g, t = self.unary()
            if op == "/" and fold(f) == 0:   # a divisor only sympy sees is zero: Expr.to_sympy
                raise ExpressionError(f"division by zero in {_shown(self.source)}")
            items.append((op == "*", f, g, t))
            if op == "/":
                self.inner += t
            degree = self._degree(degree + g)
            terms = self._terms(terms * t if op == "*" else terms)
        return _chain("mul", "div", [(up, n) for up, n, _, _ in items]), degree, terms

    def unary(self):
        if self.peek() in ("+", "-"):
            self.enter()
            op = self.take()[1]
            e, d, t = self.unary()
            self.depth -= 1
            return (e if op == "+" else ("neg", e)), d, t
        return self.power()

    def power(self):
        base, d, t = self.atom()
        if self.peek() not in ("^", "**"):
            return base, d, t
        self.enter()
        self.take()
        exp_node, _, _ = self.unary()
        self.depth -= 1
        exp = fold(exp_node)
        if exp is None:
            exp = self._sympy_exponent(exp_node)
        if abs(exp) > MAX_EXPONENT or exp.denominator > MAX_EXPONENT:
            raise ExpressionError(f"exponent {exp} in {_shown(self.source)} is larger than {MAX_EXPONENT}")
        b = fold(base)
        if b == 0 and exp < 0:
            raise ExpressionError(f"division by zero in {_shown(self.source)}")
        if b is not None and abs(exp) * math.log10(max(abs(b.numerator), b.denominator, 1)) > \
                math.log10(MAX_MAGNITUDE):
            raise ExpressionError(f"{_shown(self.source)} holds a number larger than {MAX_MAGNITUDE:g}")
        # (x+y)^(5/2) expands as (x+y)^2*sqrt(x+y), and a negative power its divisor
        whole = math.floor(abs(exp))
        expanded = self._terms(math.comb(t + whole - 1, whole) if whole else 1)
        if exp < 0:
            self.inner += expanded
        return ("pow", base, exp), self._degree(d * math.ceil(abs(exp))), expanded if exp > 0 else 1

    def _sympy_exponent(self, node) -> Fraction:
        """An exponent that is no plain fraction (2^(1/2)*2^(1/2), pi/pi): sympy says whether it
        is a constant rational number, as it always did."""
        exp = _to_sympy(node, _real_symbols(_names(node, set())), self.source)
        if exp.free_symbols or not exp.is_Rational:
            raise ExpressionError(f"exponent {exp} in {_shown(self.source)}: exponents must be constant "
                                  f"rational numbers (write a varying power with sqrt, sin, ...)")
        return Fraction(int(exp.p), int(exp.q))

    def atom(self):
        kind, text = self.take()
        if kind == "num":
            return self._number(text), 0, 1
        if kind == "name":
            if text in FUNCTIONS and text != "pi":
                return self._call(text)
            if self.peek() == "(":
                raise ExpressionError(f"unknown function {text!r} in {_shown(self.source)} "
                                      f"(known: {', '.join(sorted(k for k in FUNCTIONS if k != 'pi'))})")
            if text == "pi":
                return ("pi",), 0, 1
            if text not in self.names:
                raise ExpressionError(f"unknown symbol {text!r} in {_shown(self.source)} "
                                      f"(declare it under 'symbols')")
            return ("sym", text), 1, 1
        if text == "(":
            e = self.expr()
            self.take(")")
            return e
        raise self.fail(f"unexpected {text!r}")

    def _argument(self):
        node, _, terms = self.expr()
        self.inner += terms
        return node

    def _call(self, name: str):
        self.enter()
        self.take("(")
        args = [self._argument()]
        while self.peek() == ",":
            self.take()
            args.append(self._argument())
        self.take(")")
        self.depth -= 1
        want = _ARITY.get(name, 1)
        if len(args) != want:
            raise ExpressionError(f"{name} takes {want} argument{'s' if want > 1 else ''}, got {len(args)} "
                                  f"in {_shown(self.source)}")
        return (name, *args), 1, 1

    def _number(self, text: str):
        if len(text) > MAX_LITERAL_CHARS:
            raise ExpressionError(f"number {text[:20]}... in {_shown(self.source)} has more than "
                                  f"{MAX_LITERAL_CHARS} characters")
        value = float(text)
        if not abs(value) <= MAX_LITERAL:
            raise ExpressionError(f"number {text} in {_shown(self.source)} is larger than {MAX_LITERAL:g}")
        if value == 0:
            return ZERO
        if abs(value) < 1 / MAX_LITERAL**2:
            raise ExpressionError(f"number {text} in {_shown(self.source)} is smaller than "
                                  f"{1 / MAX_LITERAL**2:g} (write 0, or use a smaller unit)")
        return ("num", Fraction(text))

    def _degree(self, d: int) -> int:
        if d > MAX_DEGREE:
            raise ExpressionError(f"expression {_shown(self.source)} would expand to a polynomial of degree "
                                  f"over {MAX_DEGREE}")
        return d

    def _terms(self, t: int) -> int:
        if t > MAX_TERMS:
            raise ExpressionError(f"expression {_shown(self.source)} could expand to up to {float(t):.3g} terms "
                                  f"(at most {MAX_TERMS}; derive expands it): use fewer symbols in its powered "
                                  f"sums and products, or smaller powers")
        return t


def parse_tree(text: object, names) -> Expr:
    """Parse ``text`` (a string or number) using only the declared symbol ``names``.

    Decimal numbers become exact fractions. Raises ExpressionError, with the text, for
    anything outside the grammar or its bounds. What only sympy can tell (that a divisor
    is identically zero, that a constant is not real) Expr.to_sympy and check_sympy tell."""
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
    p = _Parser(source, names)
    node, _, terms = p.expr()
    if p.pos != len(p.tokens):
        raise p.fail(f"unexpected {p.tokens[p.pos][1]!r}")
    e = Expr(node, source)
    e.terms = terms + p.inner   # what expanding it all costs: the whole and its parts expanded alone
    return e


def check_sympy(expr, source: str) -> None:
    """What sympy's evaluation of a parsed expression may show: not finite, not real, or
    holding too large a number."""
    import sympy as sp
    if expr.has(sp.zoo, sp.oo, -sp.oo, sp.nan):
        raise ExpressionError(f"{_shown(source)} is not finite")
    # I itself, and constants sympy keeps unevaluated off the real line: (-8)^(1/3), acos(2)
    if expr.has(sp.I) or any(n.is_number and n.is_real is False for n in sp.preorder_traversal(expr)):
        raise ExpressionError(f"{_shown(source)} is not real")
    for n in expr.atoms(sp.Number):
        if abs(n) > MAX_MAGNITUDE:
            raise ExpressionError(f"{_shown(source)} holds a number larger than {MAX_MAGNITUDE:g}")


def parse(text: object, symbols: dict):
    """Parse ``text`` into a sympy expression with the declared ``symbols`` ({name: sympy
    symbol}): the formulas of check and tolerance files, symbolic by nature."""
    e = parse_tree(text, symbols)
    expr = e.to_sympy(symbols)
    check_sympy(expr, e.source)
    return expr
