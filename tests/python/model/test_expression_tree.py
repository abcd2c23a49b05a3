"""The expression tree (chaincomp.model.expressions.Expr) against sympy, its peer: the sympy form it
builds is the one a parser building sympy directly builds (written here, independently), its
numbers and Taylor jets are sympy's (N, series.taylor), and the load's numeric screen never
passes what sympy's checks refuse. Then the numeric models on every bundled machine and on
machines with unusual expressions against the chain multiplied in numpy from the sympy forms,
the UR5 against its published DH table in numpy, and eval importing no sympy at all."""

from __future__ import annotations

import glob
import math
import os
import subprocess
import sys

import mpmath
import numpy as np
import pytest
import sympy as sp
from hypothesis import HealthCheck, given, settings, strategies as st

from chaincomp.symbolic import series as S
from chaincomp.model.expressions import ExpressionError, check_sympy, parse_tree, plausible
from chaincomp.symbolic.jets import JetModel
from chaincomp.model.machine import ROT_PLANE, Rotation, _check_at_nominal, load_machine
from chaincomp.symbolic.numeric import ExactModel
from helpers import ROOT

MACHINES = sorted(glob.glob(os.path.join(ROOT, "configs", "machines", "*.yaml")))
LARGE, SMALL = ("x", "y"), ("e", "f")
SYMS = {n: sp.Symbol(n, real=True) for n in LARGE + SMALL}


# ----------------------------------------------------------------------------- an oracle parser
# The grammar read straight into sympy, the way chaincomp did before the tree: its result is
# what Expr.to_sympy must rebuild, operation for operation.

def oracle(text: str):
    import re
    toks = re.findall(r"\*\*|[0-9]*\.?[0-9]+(?:[eE][-+]?[0-9]+)?|[A-Za-z_]\w*|[-+*/^(),]", text)
    pos = [0]

    def peek():
        return toks[pos[0]] if pos[0] < len(toks) else None

    def take():
        pos[0] += 1
        return toks[pos[0] - 1]

    def expr():
        e = term()
        while peek() in ("+", "-"):
            e = e + term() if take() == "+" else e - term()
        return e

    def term():
        e = unary()
        while peek() in ("*", "/"):
            e = e * unary() if take() == "*" else e / unary()
        return e

    def unary():
        if peek() in ("+", "-"):
            return unary() if take() == "+" else -unary()
        return power()

    def power():
        b = atom()
        if peek() in ("^", "**"):
            take()
            return b ** unary()
        return b

    def atom():
        t = take()
        if t == "(":
            e = expr()
            take()
            return e
        if t == "pi":
            return sp.pi
        if t in SYMS:
            return SYMS[t]
        if t[0].isalpha():
            take()
            args = [expr()]
            while peek() == ",":
                take()
                args.append(expr())
            take()
            return getattr(sp, t)(*args)
        return sp.Rational(t)
    return expr()


# ----------------------------------------------------------------------------- random texts

NUMBERS = st.sampled_from(["2", "3", "0.5", "1.25", "0.1", "7", "1e-3", "0"])
EXPONENTS = st.sampled_from(["2", "3", "-1", "(1/2)", "(-1/2)", "(3/2)", "(1/3)", "-2"])


def texts():
    # leaves that mix large values and errors, so that most expressions vary with the errors
    leaves = st.one_of(NUMBERS, st.sampled_from(LARGE + SMALL + ("pi", "(x + e)", "(y - f)", "(0.5 + e)",
                                                                "(1 + f)", "(x*y + e*f)", "(0.5 - e)^2")))

    def grow(inner):
        return st.one_of(
            st.tuples(inner, st.sampled_from(["+", "-", "*", "/"]), inner).map(lambda t: f"({t[0]} {t[1]} {t[2]})"),
            inner.map(lambda a: f"-{a}"),
            st.tuples(inner, EXPONENTS).map(lambda t: f"({t[0]})^{t[1]}"),
            st.tuples(st.sampled_from(["sin", "cos", "tan", "asin", "acos", "atan", "sqrt"]), inner)
              .map(lambda t: f"{t[0]}({t[1]})"),
            st.tuples(inner, inner).map(lambda t: f"atan2({t[0]}, {t[1]})"))
    return st.recursive(leaves, grow, max_leaves=10)


def _parsed(text):
    try:
        return parse_tree(text, SYMS)
    except ExpressionError:
        return None


def _sympy_value(expr, at: dict):
    """sympy's value at ``at`` (30 digits), or None where it is not a finite real number."""
    v = sp.N(expr.xreplace({SYMS[k]: sp.Rational(str(x)) for k, x in at.items()}), 30)
    if not v.is_number or v.has(sp.zoo, sp.nan, sp.oo, -sp.oo):
        return None
    c = complex(v)
    return c.real if abs(c.imag) <= 1e-25 * max(1.0, abs(c.real)) and math.isfinite(c.real) else None


def _close(a, b, rel=1e-12):
    return abs(a - b) <= rel * max(1.0, abs(b))


AT = st.fixed_dictionaries({"x": st.floats(0.3, 1.4), "y": st.floats(-1.4, -0.3)})


@pytest.mark.slow
@settings(max_examples=300, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(texts(), AT, st.floats(-0.2, 0.2), st.floats(-0.2, 0.2))
def test_the_tree_builds_the_sympy_expression_and_its_values(text, at, e, f):
    tree = _parsed(text)
    try:
        want = oracle(text)
    except (ZeroDivisionError, ValueError, TypeError):
        want = None
    if tree is None:
        return   # refused: the bounds and messages are the hostile-input tests' business
    try:
        got = tree.to_sympy(SYMS)
    except ExpressionError:   # a divisor sympy sees is zero (x/(e - e)): the oracle has zoo there
        assert want is None or want.has(sp.zoo, sp.nan)
        return
    values = {**at, "e": e, "f": f}
    if got != want:   # a function of constants is a number now (expressions.numeric_constant)
        assert want is not None and got.free_symbols <= want.free_symbols, (text, got, want)
        a, b = _sympy_value(got, values), _sympy_value(want, values)
        assert a is None or b is None or _close(a, b), (text, got, want, a, b)
    truth = _sympy_value(got, values)
    if truth is None:
        return
    with mpmath.workdps(40):
        try:
            mine = tree.value({k: mpmath.mpf(str(v)) for k, v in values.items()}, mpmath)
        except (ArithmeticError, ValueError, TypeError, AttributeError):
            return   # complex on the way (atan2(e, sqrt(-1))): sympy's complex semantics are not ours
        if isinstance(mine, mpmath.mpc):
            assert abs(mine.imag) < 1e-20 * max(1, abs(mine.real))
            mine = mine.real
        assert _close(float(mine), truth), (text, float(mine), truth)


def _check_jets(text, at):
    tree = _parsed(text)
    if tree is None or not plausible(tree, {**at, "e": 0.0, "f": 0.0}, set(SMALL)):
        return False
    expr = tree.to_sympy(SYMS)
    k = 3
    want = S.taylor(expr, [SYMS[n] for n in SMALL], k)
    with mpmath.workdps(40):
        jet = tree.jet({n: mpmath.mpf(str(v)) for n, v in at.items()}, {n: i for i, n in enumerate(SMALL)}, k, mpmath)
        for mono in set(want) | set(jet):
            truth = _sympy_value(want.get(mono, sp.Integer(0)), at)
            assert truth is not None
            assert _close(float(jet.get(mono, 0)), truth, 1e-12), (text, mono, jet.get(mono), truth)
    return True


@pytest.mark.slow
@settings(max_examples=400, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(texts(), AT)
def test_the_tree_jets_are_sympys_taylor_coefficients(text, at):
    _check_jets(text, at)


# Each function and power of an expression in the errors, where it is analytic.
ANALYTIC = ["acos(0.5 + e)", "asin(x/2 + e*f)", "acos(y/2 - e^2 + f)", "tan(x + e)", "atan(y + f^2 - e)",
            "atan2(y + e, x - f)", "atan2(e, 1 + f)", "atan2(x*e + 0.5, -y + f)", "atan2(y + e, -x)",
            "sqrt(x + e)", "(x + e)^(-3/2)", "1/(y + e*x)", "(0.5 + e)^(1/3)", "(x - e*f)^(5/2) / (y + f)^2",
            "sin(x*e + f) * cos(y - e)", "tan(atan2(e, x))", "sqrt(1 + e^2)", "(2 + e)^-2"]


@pytest.mark.parametrize("text", ANALYTIC)
def test_the_jets_of_every_function_are_sympys(text):
    assert _check_jets(text, {"x": 0.7, "y": -0.8})


# Where an expression is not analytic in the errors at zero, or not finite or real there.
SINGULAR = ["sqrt(e^2)", "sqrt(e)", "(e)^(1/3)", "1/e", "asin(cos(e))", "acos(1 + e)", "tan(pi/2 + e)",
            "atan2(e, 0)", "atan2(e, -1)", "atan2(e*f, 0*x)", "(e*f)^(-1)", "sqrt(-1 + e)", "1/(x - 0.7 + e)",
            "x/(e - e)", "asin(2 + e)", "sqrt((0.5 - e)^2 - 0.25)",
            # zero symbolically, 0.03 in floats (2.0000000000000004e14 - 2e14): cancellation is doubted
            "x/(1e14*sqrt(2)^2 - 2e14) + e"]


@pytest.mark.parametrize("text", SINGULAR)
def test_the_numeric_screen_doubts_what_sympy_refuses(text):
    """Each is refused by sympy's checks: the screen must doubt it (and leave the word to sympy)."""
    values = {"x": 0.7, "y": -0.8, "e": 0.0, "f": 0.0}
    tree = parse_tree(text, SYMS)
    assert not plausible(tree, values, set(SMALL))
    with pytest.raises(ExpressionError):
        expr = tree.to_sympy(SYMS)
        check_sympy(expr, text)
        _check_at_nominal(expr, {SYMS[n]: sp.Float(v) for n, v in values.items()}, {SYMS[n] for n in SMALL})


# ----------------------------------------------------------------------------- machines

UNUSUAL = """
name: unusual
rotation_sense: right_hand
symbols:
  - {name: X, role: axis, unit: mm, limits: [-100, 100]}
  - {name: A, role: axis, unit: deg, limits: [-90, 90]}
  - {name: L, role: constant, unit: mm, nominal: 150}
  - {name: R, role: constant, unit: mm, nominal: 40}
  - {name: ex, role: error, unit: um}
  - {name: ea, role: error, unit: arcsec}
  - {name: eb, role: error, unit: arcsec}
  - {name: el, role: error, unit: um}
chain:
  - {translate: [X / (1 + ex / L), sqrt(R^2 + X^2 + el) - R, (L + el)^(3/2) / L^(1/2)]}
  - {rotate: z, angle: "atan2(R * sin(A) + ex, R * cos(A) + el) + ea"}
  - {rotate: x, angle: asin(0.5 + ea) - pi/6 + tan(A / 3 + eb)}
  - {rotate: y, angle: acos(0.25 * cos(eb)) - acos(0.25) + atan(ea / (2 + eb))}
  - {translate: [L * cos(ea)^2, (R + ex)^(-1) * R^2, 1 / sqrt(L + el)]}
tool:
  point: [ex / 2, 0, L + el^2]
  direction: [1, 1, 1]
  reference: [0, 0, 1]
"""


def _machines(tmp_path):
    unusual = tmp_path / "unusual.yaml"
    unusual.write_text(UNUSUAL)
    return MACHINES + [str(unusual)]


def _random_values(machine, rng, scale=1.0):
    values = {s.name: s.to_internal(rng.uniform(*s.limits)) for s in machine.axes}
    values.update({s.name: scale * rng.normal() * (1e-2 if s.unit.kind == "length" else 1e-5)
                   for s in machine.errors})
    return values


def _sympy_chain(machine, values):
    """Point, direction and frame x axis by 4x4 matrices from the sympy forms, lambdified."""
    syms = [s.sym for s in machine.symbols]
    full = {s.name: values.get(s.name, s.to_internal(s.nominal) if s.role == "constant" else 0.0)
            for s in machine.symbols}
    args = [full[s.name] for s in machine.symbols]

    def num(e):
        return float(sp.lambdify(syms, e, "mpmath")(*[mpmath.mpf(a) for a in args]))

    total = np.eye(4)
    for el in machine.chain:
        m = np.eye(4)
        if isinstance(el, Rotation):
            i, j = ROT_PLANE[el.axis]
            a = num(el.angle)
            m[i, i], m[i, j], m[j, i], m[j, j] = math.cos(a), -math.sin(a), math.sin(a), math.cos(a)
        else:
            m[:3, 3] = [num(v) for v in el.vector]
        total = total @ m
    p = total[:3, :3] @ [num(v) for v in machine.tool_point] + total[:3, 3]
    d = total[:3, :3] @ [num(v) for v in machine.tool_direction] if machine.tool_direction else None
    x = total[:3, :3] @ [num(v) for v in machine.tool_reference] if machine.tool_reference else None
    return p, d, x


@pytest.mark.slow
def test_exact_model_is_the_sympy_chain_on_every_machine(tmp_path):
    rng = np.random.default_rng(7)
    for path in _machines(tmp_path):
        machine = load_machine(path)
        model = ExactModel(machine)
        for _ in range(2):
            values = _random_values(machine, rng)
            got = model.frame(values)
            want = _sympy_chain(machine, values)
            for g, w in zip(got, want):
                assert (g is None) == (w is None), path
                if w is not None:
                    np.testing.assert_allclose(np.array(g, float), w, rtol=1e-12, atol=1e-12 * max(1, np.abs(w).max()),
                                               err_msg=path)


def test_every_element_jet_is_sympys_taylor_series_on_every_machine(tmp_path):
    rng = np.random.default_rng(8)
    for path in _machines(tmp_path):
        machine = load_machine(path)
        small = [s.sym for s in machine.errors]
        index = {s.name: i for i, s in enumerate(machine.errors)}
        values = _random_values(machine, rng)
        at = {s.name: values.get(s.name, s.reference_value) for s in machine.symbols if s.role != "error"}
        subs = {machine.symbol(n).sym: sp.Float(v, 30) for n, v in at.items()}
        exprs = [(el.expr, el.angle) for el in machine.chain if isinstance(el, Rotation)]
        exprs += [(e, v) for el in machine.chain if not isinstance(el, Rotation) for e, v in zip(el.exprs, el.vector)]
        exprs += list(zip(machine.point, machine.tool_point))
        for tree, expr in exprs:
            want = {m: float(c.xreplace(subs)) for m, c in S.taylor(expr, small, 3).items()}
            got = tree.jet(at, index, 3, np)
            for mono in set(want) | set(got):
                w, g = want.get(mono, 0.0), float(got.get(mono, 0.0))
                assert abs(g - w) <= 1e-12 * max(1.0, abs(w)), (path, tree, mono, g, w)


@pytest.mark.slow
def test_jet_model_is_the_truncated_model_of_the_derivation(tmp_path):
    """Small machines: the jets through the chain against derive's formulas, lambdified."""
    from chaincomp.symbolic.derive import derive
    from chaincomp.symbolic.numeric import TruncatedModel
    rng = np.random.default_rng(9)
    for path in [os.path.join(ROOT, "configs", "machines", "vmc_xyz.yaml"), _machines(tmp_path)[-1]]:
        machine = load_machine(path)
        truncated, jets = TruncatedModel(derive(machine, 2)), JetModel(machine, 2)
        values = _random_values(machine, rng)
        for order in (1, 2):
            for g, w in zip(jets.error(values, order), truncated.error(values, order)):
                if w is not None:
                    np.testing.assert_allclose(np.array(g, float), np.array(w, float), rtol=1e-10, atol=1e-13)


# ----------------------------------------------------------------------------- the UR5 in numpy

UR5_D = [89.159, 0.0, 0.0, 109.15, 94.65, 82.3]      # UR's published DH table (mm, rad)
UR5_A = [0.0, -425.0, -392.25, 0.0, 0.0, 0.0]
UR5_ALPHA = [math.pi / 2, 0.0, 0.0, math.pi / 2, -math.pi / 2, 0.0]


def _rx(a):
    c, s = math.cos(a), math.sin(a)
    return np.array([[1, 0, 0, 0], [0, c, -s, 0], [0, s, c, 0], [0, 0, 0, 1.0]])


def _ry(a):
    c, s = math.cos(a), math.sin(a)
    return np.array([[c, 0, s, 0], [0, 1, 0, 0], [-s, 0, c, 0], [0, 0, 0, 1.0]])


def _rz(a):
    c, s = math.cos(a), math.sin(a)
    return np.array([[c, -s, 0, 0], [s, c, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1.0]])


def _t(x, y, z):
    m = np.eye(4)
    m[:3, 3] = [x, y, z]
    return m


def ur5_frame(values, point, direction, reference):
    """Standard DH Rz(theta)·Tz(d)·Tx(a)·Rx(alpha) per joint with its errors, Hayati's Ry(beta)
    after joints 2 and 3 (configs/machines/ur5.yaml's chain as its comments state it)."""
    g = lambda name: values.get(name, 0.0)  # noqa: E731
    total = np.eye(4)
    for j in range(1, 7):
        total = total @ _rz(values[f"q{j}"] + g(f"dtheta{j}")) @ _t(0, 0, UR5_D[j - 1] + g(f"dd{j}")) \
            @ _t(UR5_A[j - 1] + g(f"da{j}"), 0, 0) @ _rx(UR5_ALPHA[j - 1] + g(f"dalpha{j}"))
        if j in (2, 3):
            total = total @ _ry(g(f"dbeta{j}"))
    r = total[:3, :3]
    return r @ point + total[:3, 3], r @ direction, None if reference is None else r @ reference


def test_ur5_exact_and_jet_models_against_its_dh_table_in_numpy():
    machine = load_machine(os.path.join(ROOT, "configs", "machines", "ur5.yaml"))
    vec = lambda v: None if v is None else np.array([e.value({}) for e in v])  # noqa: E731
    point, direction, reference = vec(machine.point), vec(machine.direction), vec(machine.reference)
    exact, jets = ExactModel(machine), JetModel(machine, 2)
    rng = np.random.default_rng(5)
    for _ in range(5):
        values = _random_values(machine, rng)
        nominal = {k: v for k, v in values.items() if k.startswith("q")}
        want = ur5_frame(values, point, direction, reference)
        for g, w in zip(exact.frame(values), want):
            if w is not None:
                np.testing.assert_allclose(np.array(g, float), w, rtol=1e-12, atol=1e-9)
        # the jets: the truncated error against the numpy chain's, error terms scaled by t: the
        # order-k model misses by O(t^(k+1))
        base = ur5_frame(nominal, point, direction, reference)
        for t in (1.0, 0.1):
            scaled = {**nominal, **{k: t * v for k, v in values.items() if not k.startswith("q")}}
            true_dp = ur5_frame(scaled, point, direction, reference)[0] - base[0]
            dp1 = np.array(jets.error(scaled, 1)[0], float)
            dp2 = np.array(jets.error(scaled, 2)[0], float)
            both = jets.errors_by_order(scaled, (1, 2))   # eval's one pass for both orders
            np.testing.assert_array_equal(np.array(both[1][0], float), dp1)
            np.testing.assert_array_equal(np.array(both[2][0], float), dp2)
            assert np.abs(dp2 - true_dp).max() < 0.05 * np.abs(dp1 - true_dp).max() + 1e-12
            assert np.abs(dp2 - true_dp).max() < 1e-4 * t**3
        # first-order gains against central differences of the numpy chain
        gains = jets.gains(nominal)
        for i, s in enumerate(machine.errors):
            h = 1e-6
            plus = ur5_frame({**nominal, s.name: h}, point, direction, reference)[0]
            minus = ur5_frame({**nominal, s.name: -h}, point, direction, reference)[0]
            fd = (plus - minus) / (2 * h)
            got = [gains[c][i] for c in ("dx", "dy", "dz")]
            np.testing.assert_allclose(got, fd, rtol=1e-6, atol=1e-6)


# ----------------------------------------------------------------------------- no sympy in eval

def test_eval_on_the_ur5_never_imports_sympy():
    code = ("import sys\n"
            "from chaincomp.cli.main import main\n"
            "sys.argv = ['chaincomp', 'eval', sys.argv[1], '--params', sys.argv[2]]\n"
            "rc = main()\n"
            "print('SYMPY' if 'sympy' in sys.modules else 'NO SYMPY', rc)\n")
    out = subprocess.run([sys.executable, "-c", code, os.path.join(ROOT, "configs", "machines", "ur5.yaml"),
                          os.path.join(ROOT, "configs", "params", "ur5-demo.yaml")],
                         capture_output=True, text=True, cwd=ROOT)
    assert out.returncode == 0, out.stderr
    assert "tool point error" in out.stdout
    assert out.stdout.strip().splitlines()[-1] == "NO SYMPY 0"


def test_what_sympy_simplifies_away_loads_in_sympys_form(tmp_path):
    """e^2/e divides by an error that vanishes: the screen doubts it, sympy makes it e, and the
    machine keeps sympy's form: its models are those of A + e."""
    path = tmp_path / "m.yaml"
    path.write_text("name: m\nrotation_sense: right_hand\nsymbols:\n"
                    "  - {name: A, role: axis, unit: rad, limits: [-3, 3]}\n"
                    "  - {name: e, role: error, unit: rad}\n"
                    "chain:\n  - {rotate: z, angle: A + e^2/e}\n  - {translate: [100, 0, 0]}\n"
                    "tool:\n  point: [0, 0, 0]\n")
    m = load_machine(str(path))
    assert m.chain[0].angle == sp.Symbol("A", real=True) + sp.Symbol("e", real=True)
    values = {"A": 0.3, "e": 1e-3}
    p, _ = ExactModel(m).pose(values)
    np.testing.assert_allclose(np.array(p, float), [100 * math.cos(0.301), 100 * math.sin(0.301), 0], rtol=1e-14)
    dp = JetModel(m, 2).error(values, 2)[0]
    want = [100 * (-math.sin(0.3) * 1e-3 - math.cos(0.3) * 1e-6 / 2), 100 * (math.cos(0.3) * 1e-3 - math.sin(0.3) * 1e-6 / 2)]
    np.testing.assert_allclose(np.array(dp[:2], float), want, rtol=1e-12)
