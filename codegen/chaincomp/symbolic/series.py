"""Truncated multivariate series in the small (error) symbols.

A series is a dict mapping a monomial of small symbols to its coefficient. A monomial is a
sorted tuple of small-symbol indices with repetition: () is the constant term, (3,) the
first power of small symbol 3, (3, 3) its square, (2, 5) a product. Degree = length.
Coefficients live in a polynomial ring over the rationals whose generators are the large
symbols and "atoms" (sin and cos of large angles, 1/tan(Yp), ...), so products are exact,
zero multipliers vanish at once and no general-purpose simplifier is needed.
"""

from __future__ import annotations

import math
from itertools import combinations_with_replacement

import sympy as sp
from sympy.polys.rings import ring as poly_ring
from sympy.polys.domains import QQ

from ..model.jetmath import mul_all  # the product of truncated series, numeric or symbolic: one place

Monomial = tuple[int, ...]


class Atoms:
    """Rewrites expressions in large symbols as polynomials in generators.

    Anything that is not a sum, product or natural power (a function application, a
    negative or fractional power, pi) becomes an atom with a placeholder generator.
    """

    def __init__(self, large: list[sp.Symbol]):
        self.large = list(large)
        self.atoms: dict[sp.Expr, sp.Symbol] = {}

    def atomize(self, expr: sp.Expr) -> sp.Expr:
        if expr.is_Number or expr.is_Symbol:   # a Float too: the ring's rationals take it
            return expr
        if expr.is_Add:
            return sp.Add(*[self.atomize(a) for a in expr.args])
        if expr.is_Mul:
            return sp.Mul(*[self.atomize(a) for a in expr.args])
        if expr.is_Pow and expr.exp.is_Integer and expr.exp > 0:
            return self.atomize(expr.base) ** expr.exp
        if expr not in self.atoms:
            self.atoms[expr] = sp.Symbol(f"_atom{len(self.atoms)}")
        return self.atoms[expr]

    def make_ring(self):
        gens = self.large + list(self.atoms.values())
        r, *_ = poly_ring(gens, QQ)
        return r

    def restore(self) -> dict[sp.Symbol, sp.Expr]:
        return {v: k for k, v in self.atoms.items()}


def mul(a: dict, b: dict, k: int) -> dict:
    """Product of two series, dropping monomials of degree above k (and zero coefficients)."""
    return {m: c for m, c in mul_all(a, b, k).items() if c}


def add(a: dict, b: dict, sign: int = 1) -> dict:
    out = dict(a)
    for m, c in b.items():
        out[m] = out[m] + sign * c if m in out else sign * c
    return {m: c for m, c in out.items() if c}


def taylor(expr: sp.Expr, small: list[sp.Symbol], k: int) -> dict[Monomial, sp.Expr]:
    """Taylor coefficients of ``expr`` in the small symbols up to total degree k (sympy Exprs)."""
    present = [i for i, s in enumerate(small) if s in expr.free_symbols]
    at_zero = {small[i]: 0 for i in present}
    out: dict[Monomial, sp.Expr] = {}
    for degree in range(k + 1):
        for mono in combinations_with_replacement(present, degree):
            d = expr
            for i in mono:
                d = sp.diff(d, small[i])
            c = d.xreplace(at_zero) if at_zero else d
            if c != 0:
                denom = math.prod(math.factorial(mono.count(i)) for i in set(mono))
                out[mono] = sp.expand(c / denom)
    return out


def sin_cos(delta: dict, k: int, one) -> tuple[dict, dict]:
    """Series of sin(delta) and cos(delta) for a series ``delta`` without constant term."""
    s: dict = {}
    c: dict = {(): one}
    power = {(): one}
    for j in range(1, k + 1):
        power = mul(power, delta, k)
        if not power:
            break
        term = {m: v * QQ(1, math.factorial(j)) for m, v in power.items()}
        if j % 2:
            s = add(s, term, -1 if (j // 2) % 2 else 1)
        else:
            c = add(c, term, -1 if (j // 2) % 2 else 1)
    return s, c


def pythagoras(ring, restore: dict):
    """A function reducing ring series modulo sin² + cos² = 1 (every sin(x)² of an atom
    pair sin(x), cos(x) as 1 − cos(x)²): a unique, usually much shorter, form of the same
    function. None when the ring has no such pair."""
    index = {restore.get(g, g): i for i, g in enumerate(ring.symbols)}
    pairs = [(i, index[sp.cos(v.args[0])]) for v, i in index.items()
             if isinstance(v, sp.sin) and sp.cos(v.args[0]) in index]
    if not pairs:
        return None

    def reduce_poly(p):
        out: dict = {}
        work = list(p.items())
        while work:
            exps, c = work.pop()
            for i_s, i_c in pairs:
                if exps[i_s] >= 2:
                    e = list(exps)
                    e[i_s] -= 2
                    work.append((tuple(e), c))
                    e[i_c] += 2
                    work.append((tuple(e), -c))
                    break
            else:
                out[exps] = out.get(exps, 0) + c
        return ring.from_dict({e: c for e, c in out.items() if c})

    def reduce_series(a: dict) -> dict:
        out = {}
        for m, c in a.items():
            r = reduce_poly(c)
            if r:
                out[m] = r
        return out
    return reduce_series
