"""chaincomp.symbolic.polyprint against sympy's own printers, on generated series.

``chaincomp derive`` prints its formulas straight from the series' ring terms
(chaincomp.symbolic.polyprint), imitating ``str`` and ``sympy.latex`` of the expressions it used to
build: ``collect(expand(...), errors)`` of each error term, the nominal sums, their ``diff``
in each axis, the gain matrix's coefficients (cli/derive.py's ``_report_sympy``). Here
hypothesis builds series of the kind a derivation holds: monomials in error symbols (names
sympy sorts and typesets in non-obvious ways: digits, underscores, Greek names, uppercase
before lowercase) of degree 0 to 4, each with a coefficient that is a polynomial over the
rationals in large symbols and atoms (sin, cos, 1/tan, 1/cos of angles), and compares
polyprint's text and LaTeX, through the entry points cli/derive.py calls, with sympy's
printing of the same series turned into sympy expressions the old way (Derivation.expr,
degree_part, collect(expand(..)), sp.diff). sympy is the truth: nothing here comes from
polyprint's own output.
"""

from __future__ import annotations

from fractions import Fraction

import pytest
import sympy as sp
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from sympy.polys.domains import QQ
from sympy.polys.rings import ring as poly_ring

from chaincomp.symbolic.derive import Derivation
from chaincomp.symbolic.polyprint import RingPrinter, shown_collected, shown_plain
from test_derive_fast import assert_prints_as_sympy

# Error names: digits (dx1 < dx10 < dx2), underscores (sorted between upper and lower case),
# Greek names sympy typesets (\alpha, \Delta), names sympy's LaTeX splits (e_b2 -> e_{b2},
# dalpha6 -> dalpha_{6}, x__1 a superscript), modifiers (xdot, vhat), ISO-style EX0A.
ERROR_NAMES = ["dx1", "dx10", "dx2", "dx_1", "EX0A", "EXX", "EX1", "E_X", "e_b2", "eb", "dalpha6",
               "alpha", "Delta1", "beta_2", "dtheta", "theta0", "omega", "phi1", "psi", "epsilon",
               "ex", "ey", "ez", "a_0", "Z_", "zz", "mu", "x__1", "xdot", "vhat", "ThetaAs", "Oas",
               "DY", "lamda", "Gamma", "d_x", "dA", "da"]
# Large symbols (lengths, constants) and axis angles
LARGE_NAMES = ["L", "a2", "d4", "G", "e", "b", "Lz", "alpha2", "X", "Y", "Z", "Ap", "Cp", "A", "C",
               "q1", "q2", "q10", "Yp", "theta1", "r_1", "aa"]

COEFFS = [Fraction(1), Fraction(-1), Fraction(2), Fraction(-2), Fraction(1, 2), Fraction(-1, 2),
          Fraction(3, 7), Fraction(-3, 7), Fraction(10 ** 6), Fraction(-10 ** 6),
          Fraction(123456789012345), Fraction(1, 10 ** 6), Fraction(-1000000, 3), Fraction(5, 4),
          Fraction(7), Fraction(-1, 3), Fraction(1, 180), Fraction(254, 10), Fraction(10 ** 15), Fraction(-7, 10 ** 15),
          Fraction(2 ** 70 + 1, 3)]

# atoms: what chaincomp.symbolic.series.Atoms makes of functions of large symbols
ATOM_KINDS = ["sin", "cos", "sin", "cos", "tan", "1/tan", "1/cos", "1/sin", "1/tan**2", "atan", "asin",
              "acos", "atan2"]


def _atom(kind: str, x: sp.Symbol) -> sp.Expr:
    if kind == "1/tan**2":
        return sp.tan(x) ** -2
    if kind == "atan2":
        return sp.atan2(x, sp.Symbol("L", real=True))
    if kind.startswith("1/"):
        return getattr(sp, kind[2:])(x) ** -1
    return getattr(sp, kind)(x)


@st.composite
def problems(draw):
    errors = draw(st.lists(st.sampled_from(ERROR_NAMES), min_size=1, max_size=5, unique=True))  # machine order
    n_err = len(errors)
    large_names = draw(st.lists(st.sampled_from([n for n in LARGE_NAMES if n not in errors]),
                                max_size=7, unique=True))
    n_large = draw(st.integers(0, min(4, len(large_names))))
    large = [sp.Symbol(n, real=True) for n in large_names[:n_large]]
    angles = large_names[n_large:n_large + 3]
    atoms = []
    for a in angles:
        x = sp.Symbol(a, real=True)
        kinds = draw(st.lists(st.sampled_from(ATOM_KINDS), min_size=1, max_size=3, unique=True))
        atoms += [_atom(k, x) for k in kinds]
        if draw(st.booleans()):
            large.append(x)                 # the angle also as a factor (a Jacobian's A*cos(A))
    small = [sp.Symbol(n, real=True) for n in errors]
    placeholders = [sp.Symbol(f"_atom{i}") for i in range(len(atoms))]
    gens = large + placeholders
    if not gens:
        gens = [sp.Symbol("L", real=True)]
        large = list(gens)
    R, *_ = poly_ring(gens, QQ)
    restore = dict(zip(placeholders, atoms))
    max_exp = draw(st.integers(1, 4))

    def poly():
        n = draw(st.integers(1, 8))
        out = R.zero
        for _ in range(n):
            c = draw(st.sampled_from(COEFFS))
            exps = tuple(draw(st.integers(0, max_exp)) if draw(st.integers(0, 2)) == 0 else 0
                         for _ in gens)
            out += R.from_dict({exps: QQ(c.numerator, c.denominator)})
        return out

    series = {}
    n_monos = draw(st.integers(0, 6))
    for _ in range(n_monos):
        degree = draw(st.integers(0, 4))
        mono = tuple(sorted(draw(st.lists(st.integers(0, n_err - 1), min_size=degree, max_size=degree))))
        p = poly()
        if draw(st.integers(0, 3)) == 0 and mono in series:
            p = -series[mono]                 # a cancellation: zero terms
        series[mono] = series.get(mono, R.zero) + p
    series = {m: c for m, c in series.items() if c}
    return R, restore, small, large, series


def _derivation(small, restore, series, order):
    return Derivation(machine=None, order=order, small=small, point=[series], direction=None,
                      columns=None, _restore=restore)


def _same(shown, expr, what):
    assert str(shown) == str(expr), (what, expr)
    assert shown.latex() == sp.latex(expr), (what, expr)
    assert shown.is_zero == (expr == 0), (what, expr)


@pytest.mark.slow
@settings(max_examples=400, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(problems())
def test_polyprint_prints_as_sympy(problem):
    R, restore, small, large, series = problem
    pr = RingPrinter(R, restore, small)
    assert pr.supported
    d = _derivation(small, restore, series, 4)
    # the error terms of each degree: collect(expand(...), errors), as cli/derive.py built them
    for k in range(1, 5):
        want = sp.collect(sp.expand(d.degree_part(series, k)), small)
        _same(shown_collected(pr, pr.series_terms(series, k)), want, ("collected", k))
    # the nominal sum and its derivative in each large symbol
    nominal = d.nominal(series)
    terms = pr.terms(series[()]) if () in series else []
    _same(shown_plain(pr, terms), nominal, "nominal")
    for sym in large + sorted({a for e in restore.values() for a in e.free_symbols}, key=str):
        dt = pr.derivative(terms, sym)
        if dt is not None:
            _same(shown_plain(pr, dt), sp.diff(nominal, sym), ("diff", sym))
    # the gain matrix's entries: the coefficient of each error alone
    for j in range(len(small)):
        c = series.get((j,))
        _same(shown_plain(pr, pr.terms(c) if c else []), d.expr(c) if c else sp.Integer(0), ("gain", j))


# ----------------------------------------------------------------------------- machine files

# A machine a user could write whose formulas hold lone negative powers (1 + 1/tan(Yp)^2 under
# an error, 1/cos(A)^2 as a gain): sympy's str prints a lone Pow as tan(Yp)**(-2), not as
# the 1/tan(Yp)**2 it prints inside a product. Odd names, 1/sin, tan and 1/tan of one angle.
LONE_POWERS = """\
name: lone_powers
length_unit: mm
rotation_sense: right_hand
symbols:
  - {name: A, role: axis, unit: deg, limits: [-90, 90], meaning: table}
  - {name: q10, role: axis, unit: deg, limits: [-90, 90], meaning: head}
  - {name: Yp, role: constant, unit: deg, nominal: 50, meaning: head angle}
  - {name: e, role: constant, unit: mm, nominal: 10, meaning: offset}
  - {name: L, role: constant, unit: mm, nominal: 100, meaning: arm}
  - {name: dx1, role: error, unit: um, meaning: offset error}
  - {name: e_b2, role: error, unit: um, meaning: another}
  - {name: dalpha6, role: error, unit: arcsec, meaning: tilt}
  - {name: EX0A, role: error, unit: arcsec, meaning: head tilt}
  - {name: Delta1, role: error, unit: um, meaning: head offset}
chain:
  - {translate: [dx1*(1 + 1/tan(Yp)^2), e_b2/cos(A)^2, e/tan(Yp) - 3/7*Delta1/sin(Yp)], label: offsets}
  - {rotate: z, angle: A + dalpha6, label: table}
  - {translate: [L*tan(Yp), 0, 1000000*EX0A/cos(q10)^3], label: arm}
  - {rotate: x, angle: q10 - EX0A/2, label: head}
tool:
  point: [L, 0, -e/2]
  direction: [0, 0, 1]
"""


@pytest.mark.parametrize("order", [1, 2])
def test_machine_file_prints_as_sympy(tmp_path, order):
    from chaincomp import load_machine
    from chaincomp.cli import derive as cli_derive
    from chaincomp.symbolic.derive import derive

    path = tmp_path / "lone_powers.yaml"
    path.write_text(LONE_POWERS)
    d = derive(load_machine(str(path)), order)
    assert RingPrinter(cli_derive._ring(d), d._restore, d.small).supported   # polyprint prints it
    assert_prints_as_sympy(d)
    # the case itself: sympy's own text of the gain 1/cos(A)^2
    assert str(cli_derive.report(d)["gain"]["dy"]["e_b2"]) == str(sp.cos(sp.Symbol("A", real=True)) ** -2) == "cos(A)**(-2)"


# Random machine files: chains of translations (sums of products of numbers, lengths, sin, cos,
# tan, 1/tan^k, 1/cos^k of the angles and errors) and rotations (an axis, its negative, plus or
# minus an error, pi/2 + an axis, an error alone), tool point, direction and frame.
_ERRS = ["dx1", "dx10", "e_b2", "EX0A", "dalpha6", "Delta1", "alpha", "x__1", "theta0", "dA", "da", "EXX"]
_AXES = ["A", "C", "q1", "q10"]
_CONSTS = [("L", "mm", 100), ("a2", "mm", 250), ("d4", "mm", 12.5), ("Yp", "deg", 50), ("e", "mm", 10)]
_NUMS = ["1", "2", "3/7", "-1/2", "1000000", "0.1", "25.4"]


def _random_machine(rng) -> str:
    import re
    errs = rng.sample(_ERRS, rng.randint(1, 4))
    axes = rng.sample(_AXES, rng.randint(1, 2))
    consts = rng.sample(_CONSTS, rng.randint(1, 3))
    angles = axes + [n for n, u, _ in consts if u == "deg"]
    lengths = [n for n, u, _ in consts if u == "mm"]

    def term():
        parts = [] if (c := rng.choice(_NUMS)) == "1" else [c]
        for _ in range(rng.randint(0, 2)):
            k, a = rng.random(), rng.choice(angles)
            parts.append(rng.choice(lengths) if k < 0.3 and lengths else f"{rng.choice(['sin', 'cos'])}({a})"
                         if k < 0.6 else f"1/tan({a})^{rng.randint(1, 2)}" if k < 0.75
                         else f"1/cos({a})^{rng.randint(1, 3)}" if k < 0.85 else f"tan({a})")
        parts += [rng.choice(errs) for _ in range((rng.random() < 0.6) + (rng.random() < 0.2))]
        return "*".join(parts) if parts else "0"

    chain = []
    for _ in range(rng.randint(1, 4)):
        if rng.random() < 0.5:
            v = [" + ".join(term() for _ in range(rng.randint(0, 3))) or "0" for _ in range(3)]
            chain.append(f"  - {{translate: [{', '.join(v)}], label: t}}")
        else:
            a, err = rng.choice(axes), rng.choice(errs)
            angle = rng.choice([a, f"-{a}", f"{a} + {err}", f"{a} - {err}/2", err, f"pi/2 + {a}"])
            chain.append(f"  - {{rotate: {rng.choice('xyz')}, angle: {angle}, label: r}}")
    point = [rng.choice(["0", "-3/7", *lengths]) for _ in range(3)]
    tool = ["tool:", f"  point: [{', '.join(point)}]"]
    if rng.random() < 0.7:
        tool.append("  direction: [0, 0, 1]")
        if rng.random() < 0.6:
            tool.append("  reference: [1, 0, 0]")
    body = "\n".join(["chain:", *chain, *tool])
    used = set(re.findall(r"[A-Za-z_][A-Za-z0-9_]*", body))
    symbols = [f"  - {{name: {a}, role: axis, unit: deg, limits: [10, 80], meaning: m}}" for a in axes if a in used]
    symbols += [f"  - {{name: {n}, role: constant, unit: {u}, nominal: {v}, meaning: m}}"
                for n, u, v in consts if n in used]
    symbols += [f"  - {{name: {e}, role: error, unit: um, meaning: m}}" for e in errs if e in used]
    return "\n".join(["name: rnd", "length_unit: mm", "rotation_sense: right_hand", "symbols:", *symbols, body]) + "\n"


@pytest.mark.slow
def test_random_machine_files_print_as_sympy(tmp_path):
    import contextlib
    import io
    import random

    from chaincomp import load_machine
    from chaincomp.cli import derive as cli_derive
    from chaincomp.symbolic.derive import derive
    from chaincomp.errors import ChaincompError

    compared = 0
    for seed in range(120):
        rng = random.Random(seed)
        path = tmp_path / f"rnd{seed}.yaml"
        path.write_text(_random_machine(rng))
        try:
            with contextlib.redirect_stderr(io.StringIO()):
                m = load_machine(str(path))
        except ChaincompError:
            continue          # not finite at the nominal values, an unused error, ...
        d = derive(m, rng.randint(1, 2))
        if not RingPrinter(cli_derive._ring(d), d._restore, d.small).supported:
            continue
        assert_prints_as_sympy(d, (seed, path.read_text()))
        compared += 1
    print(f"{compared} machines compared")
    assert compared >= 40, compared
