"""Compare hand-derived formulas with the ones the chain gives (``chaincomp check``).

Both sides are expanded into polynomials in the error symbols, truncated to the order of
the check, and compared coefficient by coefficient. A coefficient is an expression in the
large symbols; it is brought to a trig-canonical form (tan as sin/cos, sums of angles
expanded, over one monomial denominator, sin^2 = 1 - cos^2), so formulas written
differently but equal are equal. Where a coefficient differs, the difference is told
term by term: missing, extra, wrong sign, wrong coefficient.
"""

from __future__ import annotations

import dataclasses
import random
import re
from dataclasses import dataclass, field

import mpmath
import sympy as sp

from ..errors import ChaincompError
from ..model.expressions import NAME, RESERVED, ExpressionError, parse
from ..model.machine import Machine
from ..model.yamlsource import LineDict, LineList, load_yaml
from ..symbolic import series
from ..symbolic.derive import COMPONENTS, Derivation, derive

# Which product of the branches the formulas describe. T: reference -> tool, W: reference ->
# workpiece (identity for a serial chain). The machine's own model is inv(W)*T.
CHAINS = ("inv(W)*T", "inv(T)*W", "W*inv(T)", "T*inv(W)")
_OF = re.compile(r"(d?)(k?)([xyz])(?:/([A-Za-z][A-Za-z0-9_]*))?\Z")


# ----------------------------------------------------------------------------- the file

@dataclass
class Substitution:
    symbol: sp.Symbol
    value: sp.Expr
    line: int
    new: bool              # the name is not a symbol of the machine: the file defines it


@dataclass
class Formula:
    name: str
    of: str                      # x y z | dx dy dz | kx.. | dkx.. | dx/ERROR .. | htm | gain
    printed: object              # an expression; htm: rows of expressions; gain: {error: [dx, dy, dz]}
    line: int
    where: list[Substitution] = field(default_factory=list)


@dataclass
class FormulaFile:
    path: str
    chain: str
    where: list[Substitution]
    formulas: list[Formula]


def _line(node, key=None, default=None):
    if key is not None and isinstance(node, (LineDict, LineList)):
        try:
            return node.lines[key]
        except (KeyError, IndexError):
            pass
    return getattr(node, "line", default)


def _parse_where(path, node, fld, line, table: dict) -> list[Substitution]:
    if not isinstance(node, dict):
        raise ChaincompError("expected a mapping NAME: EXPRESSION", path, line, fld)
    out = []
    for key, value in node.items():
        kline = _line(node, key, line)
        if not isinstance(key, str) or not NAME.match(key) or key in RESERVED:
            raise ChaincompError(f"{key!r} is not a usable name", path, kline, f"{fld}.{key}")
        expr = _expr(path, value, table, kline, f"{fld}.{key}")
        new = key not in table
        if new:
            table[key] = sp.Symbol(key, real=True)
        out.append(Substitution(table[key], expr, kline, new))
    return out


def _expr(path, text, table, line, fld) -> sp.Expr:
    try:
        return parse(text, table)
    except ExpressionError as exc:
        msg = str(exc).replace("(declare it under 'symbols')",
                               "(not a symbol of the machine; define it under 'where')")
        name = re.match(r"unknown (?:symbol|function) '(\w+)'", msg)
        raise ChaincompError(msg, path, _line_of_name(path, line, name.group(1)) if name else line,
                             fld) from None


def _line_of_name(path: str, line: int, name: str) -> int:
    """The line, from ``line`` on, where ``name`` is written (a formula may span lines)."""
    with open(path, encoding="utf-8") as f:
        lines = f.read().splitlines()
    for i in range(line - 1, min(len(lines), line + 100)):
        if re.search(rf"\b{re.escape(name)}\b", lines[i]):
            return i + 1
    return line


def _printed(path, of, text, table, line, fld, errors):
    """The printed side: an expression, rows of an HTM, or rows of a gain matrix."""
    def row_of(node, n, r_line, r_fld):
        if not isinstance(node, list) or len(node) != n:
            raise ChaincompError(f"expected a list of {n} expressions", path, r_line, r_fld)
        return [_expr(path, v, table, _line(node, c, r_line), f"{r_fld}[{c}]") for c, v in enumerate(node)]
    if of == "htm":
        if not isinstance(text, list) or len(text) not in (3, 4):
            raise ChaincompError("an htm is a list of 3 or 4 rows of 4 expressions", path, line, fld)
        return [row_of(row, 4, _line(text, r, line), f"{fld}[{r}]") for r, row in enumerate(text)]
    if of == "gain":
        if not isinstance(text, dict):
            raise ChaincompError("a gain matrix is a mapping ERROR: [dx, dy, dz]", path, line, fld)
        for name in text:
            if name not in errors:
                raise ChaincompError(f"{name!r} is not an error symbol (errors: {', '.join(errors)})", path,
                                     _line(text, name, line), f"{fld}.{name}")
        return {name: row_of(row, 3, _line(text, name, line), f"{fld}.{name}") for name, row in text.items()}
    return _expr(path, text, table, line, fld)


def load_formulas(path: str, machine: Machine) -> FormulaFile:
    """Read and validate a formulas file; every problem names file, line and field."""
    doc = load_yaml(path)
    if not isinstance(doc, dict):
        raise ChaincompError("expected a mapping with 'formulas'", path, _line(doc, default=1))
    allowed = {"machine", "chain", "where", "formulas", "source"}
    for key in doc:
        if key not in allowed:
            raise ChaincompError(f"unknown field (allowed: {', '.join(sorted(allowed))})", path,
                                 _line(doc, key), str(key))
    if "machine" in doc and doc["machine"] != machine.name:
        raise ChaincompError(f"this file checks machine {doc['machine']!r}, not {machine.name!r}", path,
                             _line(doc, "machine"), "machine")
    chain = str(doc.get("chain", "inv(W)*T")).replace(" ", "").replace("·", "*")
    if chain not in CHAINS:
        raise ChaincompError(f"chain must be one of {', '.join(CHAINS)}, got {doc['chain']!r}", path,
                             _line(doc, "chain"), "chain")
    table = {s.name: s.sym for s in machine.symbols}
    where = _parse_where(path, doc["where"], "where", _line(doc, "where"), table) if "where" in doc else []
    items = doc.get("formulas")
    if not isinstance(items, list) or not items:
        raise ChaincompError("'formulas' must be a non-empty list", path,
                             _line(doc, "formulas", _line(doc, default=1)), "formulas")
    errors = [s.name for s in machine.errors]
    formulas = []
    for i, item in enumerate(items):
        fld, line = f"formulas[{i}]", _line(items, i)
        if not isinstance(item, dict):
            raise ChaincompError("expected a mapping with 'of' and 'formula'", path, line, fld)
        for key in item:
            if key not in ("name", "of", "formula", "where"):
                raise ChaincompError("unknown field (allowed: formula, name, of, where)", path,
                                     _line(item, key, line), f"{fld}.{key}")
        for key in ("of", "formula"):
            if key not in item:
                raise ChaincompError(f"missing required field {key!r}", path, line, fld)
        of, of_line = str(item["of"]), _line(item, "of", line)
        m = _OF.match(of)
        if of not in ("htm", "gain") and not m:
            raise ChaincompError(f"'of' must be x, y, z, dx, dy, dz, kx.., dkx.., dx/ERROR, gain or htm, "
                                 f"got {of!r}", path, of_line, f"{fld}.of")
        if m and m.group(2) and machine.tool_direction is None:
            raise ChaincompError(f"machine {machine.name} defines no tool direction", path, of_line, f"{fld}.of")
        if m and m.group(4) and (not m.group(1) or m.group(4) not in errors):
            raise ChaincompError(f"a gain entry is dx/ERROR with ERROR one of {', '.join(errors)}, "
                                 f"got {of!r}", path, of_line, f"{fld}.of")
        local = dict(table)
        sub = _parse_where(path, item["where"], f"{fld}.where", _line(item, "where", line), local) \
            if "where" in item else []
        f_line = _line(item, "formula", line)
        printed = _printed(path, of, item["formula"], local, f_line, f"{fld}.formula", errors)
        formulas.append(Formula(str(item.get("name", of)), of, printed, f_line, sub))
    return FormulaFile(path, chain, where, formulas)


# ----------------------------------------------------------------------------- comparison

@dataclass
class Finding:
    entry: str | None               # HTM entry "row 1, column 2" or gain entry "dx/ERROR"
    monomial: sp.Expr               # the error monomial whose coefficient differs (1: error-free part)
    kind: str                       # missing | extra | sign | coefficient
    whole: bool                     # about the whole coefficient of the monomial, not one term
    printed: sp.Expr                # the printed part, monomial included
    derived: sp.Expr                # what the chain gives for that part

    def message(self) -> str:
        what = "the part free of errors" if self.monomial == 1 else f"the coefficient of {self.monomial}"
        if self.whole:
            p, d = _show_whole(self.printed, self.monomial), _show_whole(self.derived, self.monomial)
            if self.kind == "sign":
                return f"{what} has the wrong sign: printed {p}, chain {d}"
            if self.kind == "missing":
                return f"{what} is missing: chain {d}"
            if self.kind == "extra":
                return f"{what} should be zero: printed {p}"
            return f"{what} is {_ratio(self.printed, self.derived)} times the chain's: printed {p}, chain {d}"
        p, d = _signed(self.printed), _signed(self.derived)
        if self.kind == "missing":
            return f"missing term {d}"
        if self.kind == "extra":
            return f"extra term {p}"
        if self.kind == "sign":
            return f"term {p} has the wrong sign (chain {d})"
        return f"term {p} has the wrong coefficient (chain {d})"


@dataclass
class Result:
    formula: Formula
    findings: list[Finding]
    ignored: list[sp.Expr]      # printed terms of degree above the order, not compared

    @property
    def equal(self) -> bool:
        return not self.findings


def _signed(e: sp.Expr) -> str:
    s = str(e)
    return s if s.startswith("-") else "+" + s


def _show_whole(part: sp.Expr, mono: sp.Expr) -> str:
    coeff = sp.expand(part / mono)
    return str(coeff) if mono == 1 else f"{mono}*({coeff})"


def _prep(e: sp.Expr) -> sp.Expr:
    """tan/cot/sec/csc as sin and cos, sums and multiples of angles expanded, products expanded."""
    e = e.replace(sp.tan, lambda a: sp.sin(a) / sp.cos(a)).replace(sp.cot, lambda a: sp.cos(a) / sp.sin(a))
    e = e.replace(sp.sec, lambda a: 1 / sp.cos(a)).replace(sp.csc, lambda a: 1 / sp.sin(a))
    return sp.expand(sp.expand_trig(e))


def _terms(e: sp.Expr) -> dict:
    """An expanded expression as {product of factors: rational coefficient}."""
    out: dict = {}
    for t in sp.Add.make_args(e):
        c, rest = t.as_coeff_Mul()
        out[rest] = out.get(rest, 0) + c
    return {k: v for k, v in out.items() if v != 0}


def _denominator(*term_dicts) -> sp.Expr:
    """Least monomial clearing every negative power in the terms."""
    need: dict = {}
    for terms in term_dicts:
        for key in terms:
            for f in sp.Mul.make_args(key):
                base, exp = f.as_base_exp()
                if exp.is_Integer and exp < 0:
                    need[base] = max(need.get(base, 0), -int(exp))
    return sp.Mul(*[b**n for b, n in need.items()])


def _pythagoras(n: sp.Expr) -> sp.Expr:
    """Reduce a polynomial in sin and cos with sin^2 = 1 - cos^2: a unique form."""
    def is_sin_power(e):
        return e.is_Pow and isinstance(e.base, sp.sin) and e.exp.is_Integer and e.exp >= 2

    def reduce(e):
        a, k = e.base.args[0], int(e.exp)
        return sp.sin(a) ** (k % 2) * (1 - sp.cos(a) ** 2) ** (k // 2)
    return sp.expand(n.replace(is_sin_power, reduce))


def _canonical_terms(e: sp.Expr, denominator: sp.Expr) -> dict:
    return {k / denominator: v for k, v in _terms(_pythagoras(sp.expand(e * denominator))).items()}


def _numerically_zero(e: sp.Expr) -> bool:
    """Cross-check for identities the canonical form misses: 30 digits at three random points."""
    syms = sorted(e.free_symbols, key=str)
    f = sp.lambdify(syms, e, modules="mpmath")
    rng = random.Random(2003)
    with mpmath.workdps(30):
        for _ in range(3):
            try:
                v = f(*[mpmath.mpf(rng.uniform(0.2, 1.3)) for _ in syms])
            except (ZeroDivisionError, ValueError, TypeError):
                return False
            if abs(v) > mpmath.mpf(10) ** -20:
                return False
    return True


def is_zero(e: sp.Expr) -> bool:
    e = _prep(e)
    if e == 0:
        return True
    terms = _terms(e)
    if not _canonical_terms(e, _denominator(terms)):
        return True
    return _numerically_zero(e)


def _term_diff(p: dict, d: dict) -> list[tuple[sp.Expr, object, object]]:
    return [(k, p.get(k, 0), d.get(k, 0)) for k in sorted(set(p) | set(d), key=sp.default_sort_key)
            if p.get(k, 0) != d.get(k, 0)]


def compare_coefficient(p: sp.Expr, d: sp.Expr, mono: sp.Expr, entry=None) -> list[Finding]:
    """Findings for one coefficient: printed ``p`` against derived ``d`` of the monomial ``mono``."""
    if is_zero(p - d):
        return []
    p_raw, d_raw = _terms(_prep(p)), _terms(_prep(d))
    p_zero, d_zero = is_zero(p), is_zero(d)
    whole = None
    if p_zero and len(d_raw) > 1:
        whole = "missing"
    elif d_zero and len(p_raw) > 1:
        whole = "extra"
    elif not p_zero and not d_zero and len(d_raw) > 1 and is_zero(p + d):
        whole = "sign"
    elif not p_zero and not d_zero and len(d_raw) > 1:
        ratio = _ratio(p, d)
        if ratio is not None and is_zero(p - ratio * d):
            whole = "coefficient"
    if whole:
        return [Finding(entry, mono, whole, True, p * mono, d * mono)]
    # Term by term: as written, or in the canonical form where that tells it in fewer items.
    diff = _term_diff(p_raw, d_raw)
    den = _denominator(p_raw, d_raw)
    canonical = _term_diff(_canonical_terms(_prep(p), den), _canonical_terms(_prep(d), den))
    if len(canonical) < len(diff):
        diff = canonical
    out = []
    for key, pc, dc in diff:
        kind = "missing" if pc == 0 else "extra" if dc == 0 else "sign" if pc == -dc else "coefficient"
        out.append(Finding(entry, mono, kind, False, pc * key * mono, dc * key * mono))
    return out


def _ratio(p: sp.Expr, d: sp.Expr):
    """p/d as a small rational when it is a constant, else None."""
    syms = sorted((p.free_symbols | d.free_symbols), key=str)
    rng = random.Random(7)
    vals = {s: sp.Rational(rng.randint(2, 13), 10) for s in syms}
    try:
        dv = float(d.xreplace(vals).evalf(30))
        if dv == 0:
            return None
        r = sp.nsimplify(float(p.xreplace(vals).evalf(30)) / dv, rational=True, tolerance=1e-12)
    except (TypeError, ValueError, ZeroDivisionError):
        return None
    return r if r.q <= 1000 else None


def by_monomial(expr: sp.Expr, errors: list[sp.Symbol], order: int) -> tuple[dict, list]:
    """{monomial (sorted error indices): coefficient} up to ``order``, and the terms above it."""
    expr = sp.expand(expr)
    index = {s: i for i, s in enumerate(errors)}
    out: dict = {}
    higher = []
    for term in sp.Add.make_args(expr):
        if term == 0:
            continue
        mono, rest = [], []
        for f in sp.Mul.make_args(term):
            base, exp = f.as_base_exp()
            if base in index and exp.is_Integer and exp > 0:
                mono += [index[base]] * int(exp)
            elif f.free_symbols & set(index):
                # an error inside a function: take the Taylor series instead
                return {m: c for m, c in series.taylor(expr, errors, order).items()}, []
            else:
                rest.append(f)
        if len(mono) > order:
            higher.append(term)
        else:
            key = tuple(sorted(mono))
            out[key] = out.get(key, 0) + sp.Mul(*rest)
    return out, higher


def _substitute(e: sp.Expr, subs: list[Substitution]) -> sp.Expr:
    for s in subs:
        e = e.xreplace({s.symbol: s.value})
    return e


def chain_variant(machine: Machine, chain: str) -> Machine:
    """The machine whose serial chain is the product ``chain`` of its branches."""
    def inv(elements):
        return tuple(e.inverse() for e in reversed(elements))
    t, w = machine.tool_chain, machine.workpiece_chain
    elements = {"inv(W)*T": inv(w) + t, "inv(T)*W": inv(t) + w, "W*inv(T)": w + inv(t),
                "T*inv(W)": t + inv(w)}[chain]
    return dataclasses.replace(machine, tool_chain=elements, workpiece_chain=())


def _derived(d: Derivation, of: str, order: int) -> sp.Expr:
    m = _OF.match(of)
    err, k, comp, _gain = m.groups()
    vec = (d.direction if k else d.point)[COMPONENTS.index(comp)]
    return d.error(vec, order if not _gain else 1) if err else d.nominal(vec)


def _compare(printed: sp.Expr, derived: sp.Expr, errors, order, subs, entry=None, gain=None):
    p, higher = by_monomial(_substitute(printed, subs), errors, order)
    dpoly, _ = by_monomial(_substitute(derived, subs), errors, order)
    if gain is not None:
        dpoly = {(): dpoly.get((gain,), sp.Integer(0))}
    findings = []
    for mono in sorted(set(p) | set(dpoly), key=lambda m: (len(m), m)):
        sym = sp.Mul(*[errors[i] for i in mono])
        findings += compare_coefficient(p.get(mono, sp.Integer(0)), dpoly.get(mono, sp.Integer(0)), sym, entry)
    return findings, higher


def check(machine: Machine, formulas: FormulaFile, order: int = 1, progress: bool = False) -> list[Result]:
    """Compare every formula of the file with the chain, to ``order`` in the errors."""
    variant = chain_variant(machine, formulas.chain)
    htm = any(f.of == "htm" for f in formulas.formulas)
    d = derive(variant, order, htm=htm, progress=progress)
    errors = [s.sym for s in machine.errors]
    results = []
    for f in formulas.formulas:
        subs = formulas.where + f.where
        pairs = []    # (entry label, printed, derived, gain index)
        if f.of == "htm":
            for r, row in enumerate(f.printed):
                for c, printed in enumerate(row):
                    if r == 3:
                        derived = sp.Integer(1 if c == 3 else 0)
                    else:
                        derived = d.nominal(d.columns[c][r]) + d.error(d.columns[c][r], order)
                    pairs.append((f"row {r + 1}, column {c + 1}", printed, derived, None))
        elif f.of == "gain":
            # A gain matrix is complete: an error it leaves out has printed gains 0.
            for j, e in enumerate(machine.errors):
                row = f.printed.get(e.name, [sp.Integer(0)] * 3)
                for i, comp in enumerate(COMPONENTS):
                    pairs.append((f"d{comp}/{e.name}", row[i], d.error(d.point[i], 1), j))
        else:
            m = _OF.match(f.of)
            gain = errors.index(machine.symbol(m.group(4)).sym) if m.group(4) else None
            pairs.append((None, f.printed, _derived(d, f.of, order), gain))
        findings, ignored = [], []
        for entry, printed, derived, gain in pairs:
            fi, hi = _compare(printed, derived, errors, order, subs, entry, gain)
            findings += fi
            ignored += hi
        results.append(Result(f, findings, ignored))
    return results
