"""chaincomp derive's printed formulas, printed straight from the series (chaincomp.symbolic.polyprint)
and, on the arms, the series themselves:

- on every bundled machine tool the text and LaTeX are sympy's own (str / sympy.latex of
  collect(expand(...)), trigsimp and diff as derive built them before: _report_sympy), and on
  the UR5 a sample of its formulas;
- the Panda's printed order-2 formulas (text and JSON, the same strings), evaluated as Python
  at a random pose and small random errors, differ from an independent numpy modified-DH chain
  (tests/python/arm_models.py: exact pose with errors minus without) by O(ε³), the order-1
  terms alone by O(ε²): point, direction and the orientation error ω against the exact
  rotation vector log(R·R₀ᵀ);
- the UR5's order 3 (ω by s·arcsin|s|/|s|, chaincomp.symbolic.orientation) by O(ε⁴), printed and as
  numeric jets.
"""

from __future__ import annotations

import json
import math
import random
import re

import numpy as np
import pytest
import sympy as sp

import arm_models as am
from chaincomp import load_machine
from chaincomp.cli import derive as cli_derive
from chaincomp.symbolic.derive import derive
from chaincomp.symbolic.jets import JetModel
from helpers import cli, machine_path

MACHINE_TOOLS = ["vmc_xyz", "me220_xz", "trunnion_ac", "five_axis_ac", "angle_head", "mori_seiki_nv1500"]


# ----------------------------------------------------------------------------- the printing

def _flat(rep: dict) -> dict:
    out = {}
    for key, value in rep.items():
        for comp, v in value.items():
            if isinstance(v, dict):
                for n, e in v.items():
                    out[(key, comp, n)] = e
            else:
                out[(key, comp)] = v
    return out


def assert_prints_as_sympy(d, where=()) -> None:
    """derive's report of the derivation `d` (polyprint) has sympy's own text, LaTeX and zeros
    (_report_sympy) for every formula; `where` goes into each failure's message."""
    fast, slow = _flat(cli_derive.report(d)), _flat(cli_derive._report_sympy(d))
    assert fast.keys() == slow.keys()
    for key in fast:
        assert str(fast[key]) == str(slow[key]), (*where, key)
        assert fast[key].latex() == slow[key].latex(), (*where, key)
        assert fast[key].is_zero == slow[key].is_zero, (*where, key)


@pytest.mark.slow
@pytest.mark.parametrize("name,order", [(n, 2) for n in MACHINE_TOOLS] + [("mori_seiki_nv1500", 3), ("me220_xz", 3)])
def test_machine_tools_print_as_sympy_prints_them(name, order):
    assert_prints_as_sympy(derive(load_machine(machine_path(name)), order))


@pytest.mark.slow
def test_ur5_sample_prints_as_sympy_prints_it():
    """A sample of the UR5's order-1 formulas against sympy's collect(expand(...)) and diff."""
    d = derive(load_machine(machine_path("ur5")), 1)
    rep = cli_derive.report(d)
    small = d.small
    for i, c in enumerate("xyz"):
        e = sp.collect(sp.expand(d.degree_part(d.point[i], 1)), small)
        assert str(rep["error"]["order1"][f"d{c}"]) == str(e)
        assert rep["error"]["order1"][f"d{c}"].latex() == sp.latex(e)
        assert str(rep["nominal"][c]) == str(d.nominal(d.point[i]))
        q = load_machine(machine_path("ur5")).axes[i + 1]
        assert str(rep["jacobian"][c][q.name]) == str(sp.diff(d.nominal(d.point[i]), q.sym))
    for row, s in (("dkz", d.direction[2]), ("wz", d.orientation[2])):
        for j in (0, 7, 23):
            e = d.expr(s.get((j,), 0)) if s.get((j,)) else sp.Integer(0)
            shown = rep["gain"][row][d.machine.errors[j].name]
            if sp.count_ops(e) > cli_derive.TRIGSIMP_MAX_OPS:
                assert str(shown) == str(e)
    w = sp.collect(sp.expand(d.degree_part(d.orientation[0], 1)), small)
    assert str(rep["orientation_error"]["order1"]["wx"]) == str(w)


# ----------------------------------------------------------------------------- evaluating the text

def _split(text: str) -> list[tuple[int, str]]:
    """The terms of a printed sum at parenthesis depth 0, with their signs."""
    out, depth, start, sign = [], 0, 0, 1
    i = 0
    if text.startswith("-"):
        sign, start, i = -1, 1, 1
    while i < len(text):
        ch = text[i]
        if ch == "(":
            depth += 1
        elif ch == ")":
            depth -= 1
        elif depth == 0 and text.startswith((" + ", " - "), i):
            out.append((sign, text[start:i]))
            sign = 1 if text[i + 1] == "+" else -1
            start = i = i + 3
            continue
        i += 1
    out.append((sign, text[start:]))
    return out


def value(text: str, names: dict) -> float:
    """A printed formula (Python syntax: sin, cos, **, rationals as p/q) at the values ``names``.
    Sums inside parentheses are evaluated on their own (one eval of 50 000 terms would nest
    too deep for the compiler)."""
    ns = {"sin": math.sin, "cos": math.cos, "tan": math.tan, "pi": math.pi, "__builtins__": {}}
    ns.update(names)
    total = 0.0
    for sign, term in _split(text):
        pieces, depth, k, start = [], 0, 0, None
        for i, ch in enumerate(term):
            if ch == "(":
                if depth == 0:
                    start = i
                depth += 1
            elif ch == ")":
                depth -= 1
                if depth == 0:
                    inner = term[start + 1:i]
                    if " + " in inner or " - " in inner:
                        name = f"_v{k}"
                        k += 1
                        ns[name] = value(inner, names)
                        pieces.append((start, i + 1, name))
        for a, b, name in reversed(pieces):
            term = term[:a] + name + term[b:]
        total += sign * eval(term, ns)
    return total


def rotation_vector(m: np.ndarray) -> np.ndarray:
    """log of a rotation matrix near I, as a vector (numpy, independent of chaincomp)."""
    s = 0.5 * np.array([m[2, 1] - m[1, 2], m[0, 2] - m[2, 0], m[1, 0] - m[0, 1]])
    theta = math.atan2(np.linalg.norm(s), (np.trace(m) - 1) / 2)
    return s * (theta / math.sin(theta) if theta > 1e-12 else 1.0)


def _errors(names, scale, rng):
    return {n: scale * rng.uniform(-1, 1) for n in names}


def _exact(kind, q, e, point):
    if kind == "panda":
        t0, t = am.panda(q), am.panda(q, e)
    else:
        t0, t = am.ur5(q, betas=(2, 3)), am.ur5(q, e, betas=(2, 3))
    p = np.append(point, 1.0)
    return {"point": (t @ p)[:3] - (t0 @ p)[:3], "direction": t[:3, 2] - t0[:3, 2],
            "w": rotation_vector(t[:3, :3] @ t0[:3, :3].T)}


def _residuals(doc, kind, point, order, scales, rng, q):
    """max |series − exact| over the components, per error scale, for degrees 1..order."""
    names = [s["name"] for s in doc["symbols"] if s["role"] == "error"]
    u = _errors(names, 1.0, rng)
    qv = {f"q{i + 1}": v for i, v in enumerate(q)}
    out = []
    for t in scales:
        e = {n: t * v for n, v in u.items()}
        want = _exact(kind, q, e, point)
        got = {"point": [], "direction": [], "w": []}
        for key, prefix, part in (("error", "d", "point"), ("direction_error", "dk", "direction"),
                                  ("orientation_error", "w", "w")):
            for c in "xyz":
                got[part].append(sum(value(doc[key][f"order{k}"][f"{prefix}{c}"], {**qv, **e})
                                     for k in range(1, order + 1)))
        out.append({part: float(np.max(np.abs(np.array(got[part]) - want[part]))) for part in got})
    return out


@pytest.fixture(scope="module")
def panda2():
    path = machine_path("panda")
    doc = json.loads(cli("derive", path, "--order", "2", "--format", "json").stdout)
    text = cli("derive", path, "--order", "2").stdout
    return doc, text


@pytest.mark.slow
def test_panda_order2_text_and_json_agree(panda2):
    doc, text = panda2
    heading = {"Tool point error": "error", "Tool direction error": "direction_error",
               "Tool frame orientation error": "orientation_error"}
    seen = 0
    section = None
    for line in text.splitlines():
        m = re.match(r"(Tool point error|Tool direction error|Tool frame orientation error).*"
                     r"terms of degree (\d+) in the errors", line)
        if m:
            section = (heading[m.group(1)], f"order{m.group(2)}")
            continue
        if section and line.startswith("  "):
            comp, formula = line.strip().split(" = ", 1)
            assert doc[section[0]][section[1]][comp] == formula, (section, comp)
            seen += 1
        else:
            section = None
    assert seen == 2 * 9   # orders 1, 2 of the point, direction and ω
    for line in text.splitlines():
        m = re.match(r"  (d[xyz]|dk[xyz]|w[xyz]) / (\w+): (.*)", line)
        if m:
            assert doc["gain"][m.group(1)][m.group(2)] == m.group(3)


@pytest.mark.slow
def test_panda_order2_against_an_independent_chain(panda2):
    """The printed series at ε and ε/10: exact − nominal minus the series falls as ε³ (as ε²
    with the order-1 terms alone), for the point, the direction and ω."""
    doc, _ = panda2
    rng = random.Random(11)
    for _ in range(2):
        q = [rng.uniform(-2.5, 2.5) for _ in range(7)]
        qv = {f"q{i + 1}": v for i, v in enumerate(q)}
        nominal = [value(doc["nominal"][c], qv) for c in "xyz"]
        want = (am.panda(q) @ np.array([40.0, 0.0, 103.4, 1.0]))[:3]
        assert np.max(np.abs(np.array(nominal) - want)) < 1e-9
        seed = rng.random()
        r2 = _residuals(doc, "panda", [40.0, 0.0, 103.4], 2, (1e-2, 1e-3), random.Random(seed), q)
        r1 = _residuals(doc, "panda", [40.0, 0.0, 103.4], 1, (1e-2, 1e-3), random.Random(seed), q)
        for part in ("point", "direction", "w"):
            assert 300 < r2[0][part] / r2[1][part] < 3000, (part, r2)    # ε³
            assert 30 < r1[0][part] / r1[1][part] < 300, (part, r1)      # ε²
            assert r2[1][part] < 1e-2 * r1[1][part], (part, r1, r2)


@pytest.mark.slow
def test_ur5_order3_printed_against_an_independent_chain():
    d = derive(load_machine(machine_path("ur5")), 3)
    rep = cli_derive.report(d)
    doc = {"symbols": [{"name": s.name, "role": s.role} for s in d.machine.symbols]}
    for key, value_ in rep.items():
        doc[key] = {k: ({c: str(e) for c, e in v.items()} if isinstance(v, dict) else str(v))
                    for k, v in value_.items()}
    rng = random.Random(5)
    q = [rng.uniform(-2.5, 2.5) for _ in range(6)]
    r3 = _residuals(doc, "ur5", [40.0, 0.0, 100.0], 3, (1e-2, 1e-3), random.Random(3), q)
    r2 = _residuals(doc, "ur5", [40.0, 0.0, 100.0], 2, (1e-2, 1e-3), random.Random(3), q)
    for part in ("point", "direction", "w"):
        assert 3000 < r3[0][part] / r3[1][part] < 30000, (part, r3)    # ε⁴
        assert r3[1][part] < 1e-2 * r2[1][part], (part, r2, r3)


@pytest.mark.slow
@pytest.mark.parametrize("name,order", [("ur5", 3), ("panda", 3), ("ur5", 4)])
def test_jets_orientation_to_order_k(name, order):
    """The numeric jets' ω (the same series by floats) against the exact rotation vector."""
    m = load_machine(machine_path(name))
    model = JetModel(m, order)
    rng = random.Random(order)
    q = [rng.uniform(-2.5, 2.5) for _ in m.axes]
    u = _errors([s.name for s in m.errors], 1.0, rng)
    res = []
    for t in (3e-2, 3e-3):
        e = {n: t * v for n, v in u.items()}
        values = {**{a.name: v for a, v in zip(m.axes, q)}, **e}     # internal units: rad, mm
        got = np.array(model.orientation_error(values), float)
        want = _exact(name, q, e, [0.0, 0.0, 0.0])["w"]
        res.append(float(np.max(np.abs(got - want))))
    assert 10 ** (order + 1) / 3 < res[0] / res[1] < 10 ** (order + 1) * 3, res

