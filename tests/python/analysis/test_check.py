"""``chaincomp check`` on the bundled formula files, on deliberate mistakes and on bad input.

Every difference the checker reports is confirmed here without the checker or the series
derivation: the printed formula (read from the file with sympy) and the chain (multiplied
numerically, first-order parts by the complex step) are evaluated at random points, and
printed minus chain must equal the sum of the reported differences there; every formula
called equal must evaluate equal.

Sources of the bundled files (configs/checks/): Freeman & Ford, Proc. IMechE Part C 217(9),
2003, Table 2; ME220 notes "Error Budget Examples" (2008) eq. 17; ME220 homework "Error
Budgets" (Chien, Helu & Warren, 2008) §6, 5T6 and the error gain matrix.
"""

import json
import os
import random

import numpy as np
import pytest
import sympy as sp
import yaml
from sympy.parsing.sympy_parser import parse_expr

from chaincomp import load_machine
from chaincomp.model.machine import Rotation

from helpers import ROOT, cli, machine_path, run_cli

CHECKS = os.path.join(ROOT, "configs", "checks")
BUNDLED = [("angle_head", "paper_table2"), ("me220_xz", "me220_eq17"), ("mori_seiki_nv1500", "mori_seiki_5T6")]
H = 1e-30   # complex step


# ----------------------------------------------------------------------------- independent numerics

def _htm(elements, f):
    """Product of the elementary transforms, numerically (complex-safe); ``f`` evaluates an expression."""
    m = np.eye(4, dtype=complex)
    for el in elements:
        t = np.eye(4, dtype=complex)
        if isinstance(el, Rotation):
            a = f(el.angle)
            c, s = np.cos(a), np.sin(a)
            i, j = {"x": (1, 2), "y": (2, 0), "z": (0, 1)}[el.axis]
            t[i, i], t[i, j], t[j, i], t[j, j] = c, -s, s, c
        else:
            t[:3, 3] = [f(v) for v in el.vector]
        m = m @ t
    return m


def _chain_htm(machine, chain, f):
    t, w = _htm(machine.tool_chain, f), _htm(machine.workpiece_chain, f)
    inv = np.linalg.inv
    return {"inv(W)*T": lambda: inv(w) @ t, "inv(T)*W": lambda: inv(t) @ w,
            "W*inv(T)": lambda: w @ inv(t), "T*inv(W)": lambda: t @ inv(w)}[chain]()


class Point:
    """Random values of every symbol, the `where` definitions applied, errors scaled by a complex step."""

    def __init__(self, machine, table, subs, rng):
        self.base = {n: rng.uniform(0.3, 1.4) for n in table}
        self.err = {s.name: rng.uniform(-1, 1) for s in machine.errors}
        self.subs = subs

    def values(self, step):
        """step: None -> errors 0; 'real' -> errors as drawn; a name -> unit complex step on it;
        'complex' -> complex step along the drawn errors."""
        v = dict(self.base)
        for n, e in self.err.items():
            if step is None:
                v[n] = 0.0
            elif step == "real":
                v[n] = e
            elif step == "complex":
                v[n] = 1j * H * e
            else:
                v[n] = 1j * H * (1.0 if n == step else 0.0)
        for name, expr in self.subs:
            v[name] = self.eval(expr, v)
        return v

    def eval(self, expr, v):
        syms = sorted(expr.free_symbols, key=str)
        return complex(sp.lambdify(syms, expr, "numpy")(*[v[str(s)] for s in syms]))


def _first_order(fn, point, direction="complex"):
    """f(0) and the first-order part of f along ``direction`` (complex step)."""
    f0 = fn(point.values(None))
    f1 = fn(point.values(direction))
    return np.real(f0), np.imag(f1) / H


def _read(path, machine):
    """The formulas file read with yaml and sympy only."""
    doc = yaml.safe_load(open(path, encoding="utf-8"))
    table = {s.name: s.sym for s in machine.symbols}

    def subs_of(node, local):
        out = []
        for name, text in (node or {}).items():
            expr = parse_expr(str(text).replace("^", "**"), local_dict=dict(local))
            local.setdefault(name, sp.Symbol(name, real=True))
            out.append((name, expr))
        return out
    file_subs = subs_of(doc.get("where"), table)
    formulas = []
    for item in doc["formulas"]:
        local = dict(table)
        subs = file_subs + subs_of(item.get("where"), local)
        formulas.append((item, subs, local))
    return doc, formulas


def _entries(machine, chain, item, local):
    """(entry label, printed expression, derived function of values) of one formula."""
    of = item["of"]
    p = lambda text: parse_expr(str(text).replace("^", "**"), local_dict=dict(local))  # noqa: E731
    tool = machine.tool_point

    def pose(v):
        def f(e):
            syms = sorted(e.free_symbols, key=str)
            return complex(sp.lambdify(syms, e, "numpy")(*[v[str(s)] for s in syms]))
        m = _chain_htm(machine, chain, f)
        return m, m @ np.array([f(c) for c in tool] + [1.0])
    out = []
    if of == "htm":
        for r, row in enumerate(item["formula"]):
            for c, text in enumerate(row):
                out.append((f"row {r + 1}, column {c + 1}", p(text), "full",
                            lambda v, r=r, c=c: pose(v)[0][r, c]))
    elif of == "gain":
        for e in machine.errors:
            row = item["formula"].get(e.name, [0, 0, 0])
            for i, comp in enumerate("xyz"):
                out.append((f"d{comp}/{e.name}", p(row[i]), ("gain", e.name), lambda v, i=i: pose(v)[1][i]))
    else:
        comp = "xyz".index(of.split("/")[0][-1])
        kind = "nominal" if not of.startswith("d") else ("gain", of.split("/")[1]) if "/" in of else "error"
        out.append((None, p(item["formula"]), kind, lambda v, comp=comp: pose(v)[1][comp]))
    return out


def _confirm(machine_name, path, report, points=3):
    machine = load_machine(machine_path(machine_name))
    doc, formulas = _read(path, machine)
    chain = doc.get("chain", "inv(W)*T")
    rng = random.Random(8)
    assert len(report["formulas"]) == len(formulas)
    for (item, subs, local), rep in zip(formulas, report["formulas"]):
        reported = {}
        for f in rep["findings"]:
            reported.setdefault(f["entry"], []).append(
                parse_expr(f["printed"], local_dict=dict(local)) - parse_expr(f["derived"], local_dict=dict(local)))
        for _ in range(points):
            pt = Point(machine, local, subs, rng)
            for entry, printed, kind, derived_fn in _entries(machine, chain, item, local):
                p0, p1 = _first_order(lambda v: pt.eval(printed, v), pt)
                printed_value = p0 + p1                     # printed, truncated to order 1
                if kind == "nominal":
                    derived_value = _first_order(derived_fn, pt)[0]
                elif kind == "error":
                    derived_value = _first_order(derived_fn, pt)[1]
                elif kind == "full":
                    derived_value = sum(_first_order(derived_fn, pt))
                else:                                       # gain: derivative along one error
                    derived_value = _first_order(derived_fn, pt, kind[1])[1]
                diff = printed_value - derived_value
                told = sum(np.real(pt.eval(t, pt.values("real"))) for t in reported.get(entry, []))
                scale = 1.0 + abs(printed_value) + abs(derived_value)
                assert abs(diff - told) < 1e-9 * scale, (rep["name"], entry, diff, told)
                if rep["equal"]:
                    assert abs(diff) < 1e-9 * scale, (rep["name"], entry, diff)
    return True


def _check_json(machine_name, check_file, *extra):
    proc = run_cli("check", machine_path(machine_name), check_file, "--json", *extra, check=False)
    assert proc.returncode in (0, 1), proc.stderr
    return proc.returncode, json.loads(proc.stdout)


# ----------------------------------------------------------------------------- bundled checks

@pytest.mark.slow
@pytest.mark.parametrize("machine_name, check_name", BUNDLED)
def test_bundled_findings_confirmed_numerically(machine_name, check_name):
    path = os.path.join(CHECKS, check_name + ".yaml")
    code, report = _check_json(machine_name, path)
    assert code == 1 and not report["equal"]
    assert _confirm(machine_name, path, report)


def _summary(report):
    return {f["name"]: [(x["entry"], x["monomial"], x["kind"], x["whole"]) for x in f["findings"]]
            for f in report["formulas"]}


@pytest.mark.slow
def test_paper_table2_findings():
    """Table 2: X, Y, Z and DX as the chain; DY and DZ with ThetaCv of the wrong sign, DZ
    without +Oas*sin(Yp)*cos(Yp)."""
    _, report = _check_json("angle_head", os.path.join(CHECKS, "paper_table2.yaml"))
    assert _summary(report) == {
        "X": [], "Y": [], "Z": [], "DX": [],
        "DY": [(None, "ThetaCv", "sign", True)],
        "DZ": [(None, "Oas", "missing", False), (None, "ThetaCv", "sign", True)],
    }
    dz = report["formulas"][5]["findings"][0]
    Oas, Yp = sp.symbols("Oas Yp", real=True)
    assert sp.sympify(dz["derived"], locals={"Oas": Oas, "Yp": Yp}) - Oas * sp.sin(Yp) * sp.cos(Yp) == 0
    assert dz["printed"] == "0"


@pytest.mark.slow
def test_me220_eq17_findings():
    """Eq. 17's first component has -ey2*tz where eq. 12 gives +ey2*tz; the products of two
    errors are left out at first order and listed."""
    _, report = _check_json("me220_xz", os.path.join(CHECKS, "me220_eq17.yaml"))
    assert _summary(report) == {"delta_xT": [(None, "ey2", "sign", False)], "delta_yT": [], "delta_zT": []}
    first = report["formulas"][0]
    assert (first["findings"][0]["printed"], first["findings"][0]["derived"]) == ("-ey2*tz", "ey2*tz")
    assert sorted(first["not_compared"]) == sorted(["dz2*ey1", "-ey1*ey2*tx"])


@pytest.mark.slow
def test_mori_seiki_5T6_findings():
    """The notes' 0T6·inv(0T5): the printed rotation part lacks ez4 (which the printed
    translation part keeps); "d_z^12" is defined as d_x^12; the gain matrix agrees."""
    _, report = _check_json("mori_seiki_nv1500", os.path.join(CHECKS, "mori_seiki_5T6.yaml"))
    assert report["chain"] == "W*inv(T)"
    missing = [("row 1, column 2", "ez4", "missing", False), ("row 2, column 1", "ez4", "missing", False)]
    assert list(_summary(report).values()) == [missing, missing, []]
    assert [(f["printed"], f["derived"]) for f in report["formulas"][0]["findings"]] == [("0", "ez4"), ("0", "-ez4")]
    assert report["formulas"][0]["defined"] == [{"name": "dz12", "as": "dx12", "line": 25}]


@pytest.mark.slow
def test_other_conventions_do_not_match_the_print(tmp_path):
    """Only 0T6·inv(0T5) reproduces the printed 5T6: the machine's own inv(0T6)·0T5 and the
    inverse of it differ in many more terms."""
    text = open(os.path.join(CHECKS, "mori_seiki_5T6.yaml"), encoding="utf-8").read()
    counts = {}
    for chain in ("W*inv(T)", "inv(W)*T", "inv(T)*W"):
        path = tmp_path / "c.yaml"
        path.write_text(text.replace("chain: W*inv(T)", f"chain: {chain}"))
        _, report = _check_json("mori_seiki_nv1500", str(path))
        counts[chain] = len(report["formulas"][0]["findings"])
    assert counts["W*inv(T)"] == 2 and counts["inv(W)*T"] > 2 and counts["inv(T)*W"] > 2


@pytest.mark.slow
def test_text_output_and_exit_codes():
    proc = run_cli("check", machine_path("angle_head"), os.path.join(CHECKS, "paper_table2.yaml"), check=False)
    assert proc.returncode == 1
    assert "DZ (line 46): DIFFERENT" in proc.stdout
    assert "missing term +Oas*sin(Yp)*cos(Yp)" in proc.stdout
    assert "the coefficient of ThetaCv has the wrong sign" in proc.stdout
    assert proc.stdout.rstrip().endswith("6 formulas: 4 equal, 2 different")


# ----------------------------------------------------------------------------- deliberate mistakes

# Table 2's DX, which agrees with the chain, typed in with three changes: +Ocx*cos(Cp) with
# its sign changed, the term +G*sin(Yp)*DY*sin(Yp)*sin(Cp) left out, and a factor 3 on
# G*ThetaAs*cos(Ap)*cos(Cp).
MISTAKES = """\
machine: angle_head
formulas:
  - name: DX with three slips
    of: dx
    formula: >-
      3*G*ThetaAs*cos(Ap)*cos(Cp) - G*cos(Yp)*ThetaAv*cos(Ap)*cos(Cp) + Oas*cos(Yp)*sin(Ap)*cos(Cp)
      - G*cos(Yp)*DY*sin(Ap)*cos(Cp) - Ocx*cos(Cp) + G*ThetaAs*sin(Ap)*cos(Yp)*sin(Cp)
      - G*cos(Yp)*ThetaAv*sin(Ap)*cos(Yp)*sin(Cp) - Oas*cos(Yp)*cos(Ap)*cos(Yp)*sin(Cp)
      + G*cos(Yp)*DY*cos(Ap)*cos(Yp)*sin(Cp) - Oas*sin(Yp)*sin(Yp)*sin(Cp)
      - Ocy*sin(Cp) - G*sin(Yp)*cos(Ap)*sin(Yp)*ThetaCh - G*cos(Yp)*cos(Yp)*ThetaCh - e/tan(Yp)*ThetaCh
"""


@pytest.mark.slow
def test_three_deliberate_slips_exactly(tmp_path):
    path = tmp_path / "slips.yaml"
    path.write_text(MISTAKES)
    code, report = _check_json("angle_head", str(path))
    assert code == 1
    findings = report["formulas"][0]["findings"]
    syms = {n: sp.Symbol(n, real=True) for n in ("G", "Yp", "Ap", "Cp", "ThetaAs", "DY", "Ocx")}
    got = {(f["kind"], f["monomial"]): (sp.sympify(f["printed"], locals=syms), sp.sympify(f["derived"], locals=syms))
           for f in findings}
    G, Yp, Ap, Cp, As, DY, Ocx = syms.values()
    assert len(findings) == 3
    assert got == {
        ("coefficient", "ThetaAs"): (3 * G * As * sp.cos(Ap) * sp.cos(Cp), G * As * sp.cos(Ap) * sp.cos(Cp)),
        ("missing", "DY"): (0, G * DY * sp.sin(Yp) ** 2 * sp.sin(Cp)),
        ("sign", "Ocx"): (-Ocx * sp.cos(Cp), Ocx * sp.cos(Cp)),
    }
    text = run_cli("check", machine_path("angle_head"), str(path), check=False).stdout
    assert "term +3*G*ThetaAs*cos(Ap)*cos(Cp) has the wrong coefficient (chain +G*ThetaAs*cos(Ap)*cos(Cp))" in text
    assert "missing term +DY*G*sin(Cp)*sin(Yp)**2" in text
    assert "term -Ocx*cos(Cp) has the wrong sign (chain +Ocx*cos(Cp))" in text
    assert _confirm("angle_head", str(path), report)


@pytest.mark.slow
def test_equal_in_other_forms(tmp_path):
    """Trig identities, other groupings, tan written as sin/cos and substitutions: equal."""
    path = tmp_path / "forms.yaml"
    path.write_text("""\
machine: angle_head
formulas:
  - {name: Z, of: z, formula: "-G*(1 - cos(Yp)^2)*cos(Ap) - G*cos(Yp)^2 - e*cos(Yp)/sin(Yp)"}
  - {name: X, of: x, formula: "G*sin(Yp)*sin(Ap)*cos(Cp) + G*sin(2*Yp)/2*sin(Cp)*(1 - cos(Ap)) + e*sin(Cp)"}
  - {name: dz/DY, of: dz/DY, formula: "-G*sin(2*Yp)*(1 - cos(Ap))/2"}
  - {name: Z at Yp = 45 deg, of: z, formula: "-G*cos(Ap)/2 - G/2 - e", where: {Yp: pi/4}}
  - {name: part of DX, of: dx, formula: "Ocx*cos(Cp) - Ocy*sin(Cp)"}
""")
    code, report = _check_json("angle_head", str(path))
    assert code == 1
    assert [f["equal"] for f in report["formulas"]] == [True, True, True, True, False]
    assert {f["kind"] for f in report["formulas"][4]["findings"]} == {"missing"}
    assert _confirm("angle_head", str(path), report)


@pytest.mark.slow
def test_whole_coefficients(tmp_path):
    """A coefficient of several terms that is wholly of the wrong sign, extra, missing or a
    multiple of the chain's is told as one finding; a one-term slip as a term."""
    path = tmp_path / "whole.yaml"
    path.write_text("""\
machine: angle_head
formulas:
  - name: DZ, with the ThetaCh terms left out
    of: dz
    formula: >-
      -2*G*ThetaAs*sin(Ap)*sin(Yp) + Ocx*(G + e)
      + Oas*(sin(Yp)*cos(Ap)*cos(Yp) - sin(Yp)*cos(Yp))
      - G*ThetaAv*sin(Ap)*sin(Yp)*cos(Yp)
      + DY*(G*sin(Yp)*cos(Ap)*cos(Yp) - G*sin(Yp)*cos(Yp))
      + 3*ThetaCv*(G*sin(Ap)*sin(Cp)*sin(Yp) + G*sin(Yp)*cos(Ap)*cos(Cp)*cos(Yp) - G*sin(Yp)*cos(Cp)*cos(Yp)
                   - e*cos(Cp))
""")
    code, report = _check_json("angle_head", str(path))
    findings = report["formulas"][0]["findings"]
    assert [(f["monomial"], f["kind"], f["whole"]) for f in findings] == [
        ("ThetaAs", "coefficient", False), ("Oas", "sign", True), ("Ocx", "extra", True),
        ("ThetaCh", "missing", True), ("ThetaCv", "coefficient", True)]
    assert findings[4]["message"].startswith("the coefficient of ThetaCv is 3 times the chain's")
    assert findings[3]["printed"] == "0"
    assert _confirm("angle_head", str(path), report)


@pytest.mark.slow
def test_order_two_compares_products(tmp_path):
    """At --order 2 the products of two errors in eq. 17 are compared: the -ey2 slip shows in
    them too (eq. 17 used -ey2 in both off-diagonal places of 1T2)."""
    code, report = _check_json("me220_xz", os.path.join(CHECKS, "me220_eq17.yaml"), "--order", "2")
    y = report["formulas"][1]
    assert ("ey2*ez1", "sign") in [(f["monomial"], f["kind"]) for f in y["findings"]]
    assert not report["formulas"][0]["not_compared"]


# ----------------------------------------------------------------------------- bad input

@pytest.mark.parametrize("text, line, fragment", [
    ("formulas:\n  - {name: X, of: x, formula: \"G*sin(Yp\"}\n", 2, "'G*sin(Yp'"),
    ("formulas:\n  - name: DX\n    of: dx\n    formula: >-\n      Ocx*cos(Cp)\n      + Foo*sin(Cp)\n", 6,
     "unknown symbol 'Foo' in 'Ocx*cos(Cp) + Foo*sin(Cp)'"),
    ("formulas:\n  - of: htm\n    formula:\n      - [1, 0, 0, Ocx]\n      - [0, 1, 0, Ocy +]\n      - [0, 0, 1, 0]\n",
     5, "'Ocy +'"),
    ("formulas:\n  - {of: dq, formula: \"1\"}\n", 2, "got 'dq'"),
    ("machine: me220_xz\nformulas:\n  - {of: dx, formula: \"1\"}\n", 1, "not 'angle_head'"),
    ("formulas:\n  - {of: dx/G, formula: \"1\"}\n", 2, "got 'dx/G'"),
    ("where: {sin: 1}\nformulas:\n  - {of: x, formula: \"1\"}\n", 1, "'sin' is not a usable name"),
    ("formulas:\n  - {of: x}\n", 2, "missing required field 'formula'"),
    ("formulas: [\n", 2, "YAML syntax error"),
])
def test_bad_formula_files_exit_2(tmp_path, text, line, fragment):
    path = tmp_path / "bad.yaml"
    path.write_text(text)
    proc = cli("check", machine_path("angle_head"), str(path), check=False)   # in this process
    assert proc.returncode == 2, proc.stdout + proc.stderr
    assert proc.stdout == ""
    assert proc.stderr.startswith(f"chaincomp check: error: {path}:{line}: "), proc.stderr
    assert fragment in proc.stderr
