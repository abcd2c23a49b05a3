"""The derived formulas printed straight from the coefficient ring, as sympy would print them.

``chaincomp derive`` shows each error term in the error symbols collected (sympy's
``collect(expand(e), errors)``: every term under the first error, in the machine's order, it
holds, with that error's power). Building those sympy expressions and printing them costs
minutes on an arm (the Panda's order 2: 35 000 terms; the collect alone 2 minutes), while the
series of chaincomp.derive already hold them expanded: a polynomial in the large symbols and
the atoms (sin, cos, 1/tan of large angles) per monomial of errors. Here those terms are
printed directly, with sympy's own rules for the shapes they take:

- the terms of a sum in sympy's order (``Expr.as_ordered_terms``: lexicographic in the
  exponents over the bases sorted by ``default_sort_key``, highest first; a positive number
  before a negated single factor in a sum of two);
- the factors of a product in ``as_ordered_factors`` order, the rational coefficient's
  numerator first and its denominator with the negative powers after a ``/`` (``str``), or
  ``\\frac{..}{..}`` (``latex``);
- a term that is a single base to a power below -1 with coefficient 1 is a Pow, not a Mul:
  ``str`` prints it ``tan(A)**(-2)`` (in a product ``1/tan(A)**2``), ``latex`` as a fraction;
- the strings of each base and power from sympy itself (``str(b**e)``, ``latex(b**e)``, once).

The same text, character for character, as ``str`` / ``sympy.latex`` of the collected sympy
expression (tests/python/symbolic/test_derive_fast.py holds it against sympy on every bundled machine,
tests/python/symbolic/test_polyprint_vs_sympy.py on generated series and random machine files).
Atoms it does not know (a number such as sqrt(2), a root of a symbol) make ``supported``
False, and the caller builds sympy expressions as before.
"""

from __future__ import annotations

from fractions import Fraction

import sympy as sp

Term = tuple[Fraction, tuple[int, ...]]     # coefficient, exponent of every base (dense)

# Functions whose powers and products sympy leaves as they are (exp(a)*exp(b) it merges,
# Abs(x)**2 of a real x it rewrites): atoms of other functions take the sympy path.
_FUNCTIONS = (sp.sin, sp.cos, sp.tan, sp.cot, sp.sec, sp.csc, sp.asin, sp.acos, sp.atan, sp.acot, sp.atan2)


def _plain_function(e) -> bool:
    return isinstance(e, _FUNCTIONS) and not e.is_number and all(a.is_Symbol for a in e.args)


class RingPrinter:
    """Prints series coefficients (ring elements) of one derivation."""

    def __init__(self, ring, restore: dict, small: list[sp.Symbol]):
        self.small = list(small)
        self.supported = True
        gens = []                                  # per ring generator: (base, multiplicity)
        for sym in ring.symbols:
            value = restore.get(sym, sym)
            if value.is_Symbol:
                gens.append((value, 1))
            elif _plain_function(value):
                gens.append((value, 1))
            elif value.is_Pow and value.exp.is_Integer and _plain_function(value.base):
                gens.append((value.base, int(value.exp)))
            else:
                self.supported = False
                return
        bases = list(dict.fromkeys([b for b, _ in gens] + self.small))
        bases.sort(key=sp.default_sort_key)
        self.bases = bases
        self.n = len(bases)
        pos = {b: i for i, b in enumerate(bases)}
        self._gen = [(pos[b], mult) for b, mult in gens]
        self._small_pos = [pos[s] for s in self.small]
        # the machine's order of the errors (collect takes the first one a term holds)
        self._small_rank = {p: r for r, p in enumerate(self._small_pos)}
        self._function_pos = [p for p, b in enumerate(bases) if not b.is_Symbol]
        self._str: dict = {}
        self._tex: dict = {}

    # ------------------------------------------------------------------ terms
    def terms(self, poly, mono: tuple = ()) -> list[Term]:
        """The terms of ``poly`` times the error monomial ``mono``, like bases merged."""
        out: dict = {}
        small = [0] * self.n
        for i in mono:
            small[self._small_pos[i]] += 1
        for exps, c in poly.items():
            v = list(small)
            for g, e in enumerate(exps):
                if e:
                    p, mult = self._gen[g]
                    v[p] += mult * e
            key = tuple(v)
            q = Fraction(int(c.numerator), int(c.denominator))
            out[key] = out.get(key, 0) + q
        return [(c, v) for v, c in out.items() if c]

    def series_terms(self, s: dict, degree: int) -> list[Term]:
        """The terms of exactly ``degree`` in the errors of a series."""
        out: dict = {}
        for mono, c in s.items():
            if len(mono) == degree:
                for coeff, v in self.terms(c, mono):
                    out[v] = out.get(v, 0) + coeff
        return [(c, v) for v, c in out.items() if c]

    def op_lower_bound(self, terms: list[Term]) -> int:
        """At most sympy.count_ops of the expanded sum of ``terms``: one ADD or SUB between
        terms and one operation per function in each."""
        return len(terms) - 1 + sum(1 for _c, v in terms for p in self._function_pos if v[p])

    def derivative(self, terms: list[Term], sym: sp.Symbol) -> list[Term] | None:
        """d/d``sym`` of the sum of ``terms`` where every base holding ``sym`` is sym, sin(sym)
        or cos(sym) (else None): the expanded sum sympy.diff gives."""
        at = {}
        for p, b in enumerate(self.bases):
            if sym in b.free_symbols:
                kind = "x" if b == sym else "sin" if b == sp.sin(sym) else "cos" if b == sp.cos(sym) else None
                if kind is None:
                    return None
                at[kind] = p
        out: dict = {}

        def add(c, v, p, e, q=None):
            w = list(v)
            w[p] -= 1
            if q is not None:
                w[q] += 1
            key = tuple(w)
            out[key] = out.get(key, 0) + c * e
        for c, v in terms:
            if "x" in at and v[at["x"]]:
                add(c, v, at["x"], v[at["x"]])
            if "sin" in at and v[at["sin"]]:
                p = at["sin"]
                if "cos" not in at:
                    return None
                add(c, v, p, v[p], at["cos"])
            if "cos" in at and v[at["cos"]]:
                p = at["cos"]
                if "sin" not in at:
                    return None
                add(-c, v, p, v[p], at["sin"])
        return [(c, v) for v, c in out.items() if c]

    # ------------------------------------------------------------------ sympy's order
    @staticmethod
    def _ordered(terms: list[Term]) -> list[Term]:
        if len(terms) == 2:
            # Expr.as_ordered_terms: Add(Number, Mul(Number, x)), the first positive and the
            # second negative, keeps the number first (1 - x)
            num = [t for t in terms if not any(t[1])]
            if num:
                other = terms[1] if terms[0] is num[0] else terms[0]
                # a negative coefficient is a Number arg of the Mul: two args = one factor
                if num[0][0] > 0 and other[0] < 0 and sum(1 for e in other[1] if e) == 1:
                    return [num[0], other]
        return sorted(terms, key=lambda t: tuple(-e for e in t[1]))

    def _factor(self, cache, fn, p: int, e: int) -> str:
        key = (p, e)
        if key not in cache:
            cache[key] = fn(self.bases[p] ** e)
        return cache[key]

    # ------------------------------------------------------------------ str
    def _mul_str(self, c: Fraction, v: tuple) -> str:
        if not any(v):
            return str(sp.Rational(c.numerator, c.denominator))
        if c == 1 and sum(1 for e in v if e) == 1 and min(v) < -1:
            # a lone Pow, not a Mul: sympy's str prints tan(A)**(-2), not 1/tan(A)**2
            p = next(p for p, e in enumerate(v) if e)
            return self._factor(self._str, str, p, v[p])
        sign = "-" if c < 0 else ""
        c = abs(c)
        num = [str(c.numerator)] if c.numerator != 1 else []
        den = [str(c.denominator)] if c.denominator != 1 else []
        for p, e in enumerate(v):
            if e > 0:
                num.append(self._factor(self._str, str, p, e))
            elif e < 0:
                den.append(self._factor(self._str, str, p, -e))
        text = sign + ("*".join(num) if num else "1")
        if len(den) == 1:
            return text + "/" + den[0]
        return text + "/(" + "*".join(den) + ")" if den else text

    def _add_str(self, terms: list[Term]) -> str:
        if not terms:
            return "0"
        out = []
        for c, v in self._ordered(terms):
            t = self._mul_str(c, v)
            if t.startswith("-"):
                out += ["-", t[1:]]
            else:
                out += ["+", t]
        sign = out.pop(0)
        return ("" if sign == "+" else sign) + " ".join(out)

    # ------------------------------------------------------------------ latex
    def _mul_tex(self, c: Fraction, v: tuple) -> str:
        if not any(v):
            return sp.latex(sp.Rational(c.numerator, c.denominator))
        sign = "- " if c < 0 else ""
        c = abs(c)
        num = [str(c.numerator)] if c.numerator != 1 else []
        den = [str(c.denominator)] if c.denominator != 1 else []
        for p, e in enumerate(v):
            if e > 0:
                num.append(self._factor(self._tex, sp.latex, p, e))
            elif e < 0:
                den.append(self._factor(self._tex, sp.latex, p, -e))
        n = " ".join(num) if num else "1"
        return sign + (r"\frac{%s}{%s}" % (n, " ".join(den)) if den else n)

    def _add_tex(self, terms: list[Term]) -> str:
        if not terms:
            return "0"
        tex = ""
        for i, (c, v) in enumerate(self._ordered(terms)):
            if i == 0:
                tex += self._mul_tex(c, v)
            elif c < 0:
                tex += " - " + self._mul_tex(-c, v)
            else:
                tex += " + " + self._mul_tex(c, v)
        return tex

    # ------------------------------------------------------------------ collected
    def _groups(self, terms: list[Term]) -> list[tuple[int, int, list[Term]]]:
        """collect(e, errors): (position of the key error, its power, the terms under it)."""
        groups: dict = {}
        for c, v in terms:
            first = min((self._small_rank[p] for p in self._small_pos if v[p]), default=None)
            if first is None:
                raise ValueError("a collected term without an error")
            p = self._small_pos[first]
            rest = list(v)
            rest[p] = 0
            groups.setdefault((p, v[p]), []).append((c, tuple(rest)))
        return [(p, e, ts) for (p, e), ts in groups.items()]

    def _outer(self, terms: list[Term]):
        """The collected sum's terms in sympy's order: (single term or None, key, inner terms)."""
        items = []
        for p, e, inner in self._groups(terms):
            if len(inner) == 1:
                c, rest = inner[0]
                v = list(rest)
                v[p] = e
                items.append((tuple(v), (c, tuple(v)), p, e, None))
            else:
                v = [0] * self.n
                v[p] = e     # the inner sum is a base after every symbol: the key decides
                items.append((tuple(v), None, p, e, inner))
        if len(items) == 1:
            return items
        # the symbols decide (no two keys agree on them); the inner sums sort after symbols
        return sorted(items, key=lambda it: tuple(-x for x in it[0]))

    def collected_str(self, terms: list[Term]) -> str:
        if not terms:
            return "0"
        parts = []
        for _v, single, p, e, inner in self._outer(terms):
            if single is not None:
                parts.append(self._mul_str(*single))
            else:
                key = self._factor(self._str, str, p, e)
                parts.append(f"{key}*({self._add_str(inner)})")
        out = []
        for t in parts:
            out += ["-", t[1:]] if t.startswith("-") else ["+", t]
        sign = out.pop(0)
        return ("" if sign == "+" else sign) + " ".join(out)

    def collected_tex(self, terms: list[Term]) -> str:
        if not terms:
            return "0"
        tex = ""
        for i, (_v, single, p, e, inner) in enumerate(self._outer(terms)):
            if single is not None:
                c, v = single
                if i == 0:
                    tex += self._mul_tex(c, v)
                else:
                    tex += (" - " + self._mul_tex(-c, v)) if c < 0 else (" + " + self._mul_tex(c, v))
            else:
                key = self._factor(self._tex, sp.latex, p, e)
                tex += ("" if i == 0 else " + ") + rf"{key} \left({self._add_tex(inner)}\right)"
        return tex

    def plain_str(self, terms: list[Term]) -> str:
        return self._add_str(terms)

    def plain_tex(self, terms: list[Term]) -> str:
        return self._add_tex(terms)


class Shown:
    """A formula of the report: its text (str) and LaTeX, and whether it is zero."""

    def __init__(self, text, tex, zero: bool):
        self._text, self._tex, self.is_zero = text, tex, zero

    def __str__(self) -> str:
        if callable(self._text):
            self._text = self._text()
        return self._text

    def latex(self) -> str:
        if callable(self._tex):
            self._tex = self._tex()
        return self._tex


def shown_sympy(e: sp.Expr) -> Shown:
    return Shown(lambda: str(e), lambda: sp.latex(e), e == 0)


def shown_plain(pr: RingPrinter, terms: list[Term]) -> Shown:
    return Shown(lambda: pr.plain_str(terms), lambda: pr.plain_tex(terms), not terms)


def shown_collected(pr: RingPrinter, terms: list[Term]) -> Shown:
    return Shown(lambda: pr.collected_str(terms), lambda: pr.collected_tex(terms), not terms)
