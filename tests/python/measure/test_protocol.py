"""``chaincomp protocol`` on the paper's angle head (Freeman & Ford 2003, §5 and Table 4).

The reported equations are checked against the exact model, never against the paper's
strings: each test's two set-ups are substituted into the chain multiplied numerically
with random small errors, and the reported right-hand side must match the measured sum or
difference up to second-order terms.
"""

import json
import math

import numpy as np
import pytest
import sympy as sp

from chaincomp import load_machine
from chaincomp.symbolic.numeric import ExactModel

from helpers import cli, machine_path, run_cli

AXES = ("Ap", "Cp")
COORD = {"x": 0, "y": 1, "z": 2}


def protocol_json(*args: str) -> dict:
    return json.loads(run_cli("protocol", *args, "--format", "json").stdout)


def random_errors(m, rng, eps, zero=()):
    """Angles ~eps rad, offsets ~eps * 20 mm: errors of comparable effect at the tool tip."""
    return {s.name: 0.0 if s.name in zero else rng.uniform(-1, 1) * eps * (1 if s.unit.kind == "angle" else 20)
            for s in m.errors}


def measured(m, model, eq, errors):
    """The equation's left-hand side, from the exact model: coordinate at set-up 1 +/- set-up 2."""
    out = []
    for setup in eq["setups"]:
        values = m.nominal_values()
        values.update(errors)
        values.update({a: math.radians(setup[a]) for a in AXES})
        out.append(float(model.pose(values)[0][COORD[eq["coordinate"]]]))
    return out[0] + (1 if eq["operation"] == "sum" else -1) * out[1]


def reported(m, eq, errors):
    expr = sp.sympify(eq["equation"])
    values = m.nominal_values()
    values.update(errors)
    return float(expr.subs({s: values[s.name] for s in expr.free_symbols}))


@pytest.fixture(scope="module")
def angle_head():
    m = load_machine(machine_path("angle_head"))
    return m, ExactModel(m), protocol_json(machine_path("angle_head"), "--assume-zero", "DY")


def every_equation(doc):
    for t in doc["tests"]:
        for eq in t["equations"]:
            yield t, eq


@pytest.mark.slow
def test_every_equation_holds_to_first_order(angle_head):
    m, model, doc = angle_head
    rng = np.random.default_rng(20030901)
    for _ in range(5):
        base = random_errors(m, rng, 1.0, zero=("DY",))
        residuals = []
        for eps in (1e-4, 1e-5):
            errors = {k: v * eps for k, v in base.items()}
            residuals.append([measured(m, model, eq, errors) - reported(m, eq, errors)
                              for _, eq in every_equation(doc)])
        r1, r2 = np.abs(residuals)
        # second order: at most G * eps^2 in size, and a tenth of eps gives a hundredth of it
        assert r1.max() < 50 * 20 * 1e-8, r1
        assert np.all(r2 <= r1 / 50 + 1e-12), (r1, r2)


@pytest.mark.slow
def test_finds_a_test_for_each_error_and_the_theta_pair(angle_head):
    m, model, doc = angle_head
    assert doc["assumed_zero"] == ["DY"]
    errors = {s.name for s in m.errors}
    known = set()
    isolated = {}
    for t in doc["tests"]:
        for eq in t["equations"]:
            present = {s.name for s in sp.sympify(eq["error"]).free_symbols} & errors
            assert "DY" not in present
            # unknowns: every error in the equation that no earlier test identified
            assert set(eq["unknowns"]) == present - known, eq
        if t["kind"] == "test":
            (name,) = t["errors"]
            assert t["equations"][0]["unknowns"] == [name]
            isolated[name] = t["equations"][0]
        known |= set(t["errors"])
    assert {"Ocx", "Oas", "Ocy", "ThetaCh", "ThetaCv"} <= set(isolated)
    # the isolated error really moves the measured difference (its test is not vacuous)
    for name, eq in isolated.items():
        errors = {s.name: 0.0 for s in m.errors}
        bumped = dict(errors, **{name: 1e-6})
        assert abs(measured(m, model, eq, bumped) - measured(m, model, eq, errors)) > 1e-7
    pair = [t for t in doc["tests"] if set(t["errors"]) == {"ThetaAs", "ThetaAv"}]
    assert len(pair) == 1 and pair[0]["kind"] == "combination"
    assert set(doc["unidentifiable"]) == {"ThetaAs", "ThetaAv"}


def test_theta_pair_is_truly_inseparable(angle_head):
    """ThetaAs with ThetaAv = ThetaAs / cos(Yp) moves no tool point at any set-up, to first order."""
    m, model, doc = angle_head
    combo = sp.sympify(next(t for t in doc["tests"] if t["kind"] == "combination")["combination"])
    yp = m.nominal_values()["Yp"]
    a = 1e-5
    move = {"ThetaAs": a, "ThetaAv": a / math.cos(yp)}
    assert abs(float(combo.subs({sp.Symbol("ThetaAs"): move["ThetaAs"], sp.Symbol("ThetaAv"): move["ThetaAv"],
                                 sp.Symbol("Yp"): yp}))) < 1e-15
    grid = np.radians([0.0, 90.0, 180.0, 270.0])
    A, C = np.meshgrid(grid, grid)
    values = m.nominal_values()
    values.update(Ap=A.ravel(), Cp=C.ravel())
    p0 = np.array(model.pose(values)[0])
    values.update(move)
    p1 = np.array(model.pose(values)[0])
    assert np.abs(p1 - p0).max() < 20 * a * a * 10     # second order only
    values.update(ThetaAv=0.0)
    assert np.abs(np.array(model.pose(values)[0]) - p0).max() > 20 * a * 0.5   # ThetaAs alone is seen


@pytest.mark.slow
def test_without_dy_oas_pairs_with_dy():
    doc = protocol_json(machine_path("angle_head"))
    assert set(doc["unidentifiable"]) == {"ThetaAs", "ThetaAv", "Oas", "DY"}
    kinds = {tuple(sorted(t["errors"])): t["kind"] for t in doc["tests"]}
    assert kinds[("DY", "Oas")] == "combination"


@pytest.mark.slow
def test_text_report(angle_head):
    out = run_cli("protocol", machine_path("angle_head"), "--assume-zero", "DY").stdout
    assert "Parameters assumed zero: DY" in out
    assert "Test 1   Ocx from Xdiff (90,0) - (270,180) = 2*Ocx" in out
    assert "Not identifiable:" in out and "ThetaAs: cannot be told apart from ThetaAv" in out


@pytest.mark.slow
def test_prefer_steers_the_order():
    doc = protocol_json(machine_path("angle_head"), "--assume-zero", "DY", "--prefer", "Oas,Ocy")
    assert [t["errors"] for t in doc["tests"][:2]] == [["Oas"], ["Ocy"]]


def extended_head(tmp_path):
    """The angle head plus Ocz (C offset along its own axis) and Rs (spindle turned about its axis)."""
    text = open(machine_path("angle_head")).read()
    for old, new in (
            ("  - {name: ThetaCv,", "  - {name: Ocz, role: error, unit: um, meaning: Offset of C along z}\n"
                                   "  - {name: Rs, role: error, unit: arcsec, meaning: Spindle about its axis}\n"
                                   "  - {name: ThetaCv,"),
            ("[Ocx, Ocy, 0]", "[Ocx, Ocy, Ocz]"),
            ("  - {translate: [0, 0, -G],", "  - {rotate: z, angle: Rs}\n  - {translate: [0, 0, -G],")):
        assert text.count(old) == 1
        text = text.replace(old, new)
    path = tmp_path / "head_plus.yaml"
    path.write_text(text)
    return str(path)


@pytest.mark.slow
def test_unidentifiable_errors_with_reasons(tmp_path):
    path = extended_head(tmp_path)
    doc = protocol_json(path, "--assume-zero", "DY", "--measure", "x,y")
    assert "does not move the tool point" in doc["unidentifiable"]["Rs"]
    assert "moves only Z, which is not measured" in doc["unidentifiable"]["Ocz"]
    assert not any({"Rs", "Ocz"} & set(t["errors"]) for t in doc["tests"])
    # measuring z, Ocz has a test (a sum: it shifts z equally at every set-up)
    doc = protocol_json(path, "--assume-zero", "DY")
    ocz = [t for t in doc["tests"] if t["errors"] == ["Ocz"]]
    assert ocz and ocz[0]["equations"][0]["operation"] == "sum"
    assert "Rs" in doc["unidentifiable"]


@pytest.mark.parametrize("args, word", [
    (("--assume-zero", "DY,Dz"), "--assume-zero: unknown error 'Dz' for machine 'angle_head'"),
    (("--assume-zero", "G"), "--assume-zero: 'G' is a constant, not an error"),
    (("--prefer", "Ap"), "--prefer: 'Ap' is an axis, not an error"),
    (("--angles", "0,ninety"), "--angles: expected a number, got 'ninety'"),
    (("--measure", "x,q"), "--measure: unknown coordinate 'q'"),
    (("--order", "2"), "--order 2: protocol equations are first order"),
])
def test_bad_options_exit_2(args, word):
    proc = cli("protocol", machine_path("angle_head"), *args, check=False)   # in this process
    assert proc.returncode == 2, proc.stderr
    assert "Traceback" not in proc.stderr
    assert proc.stderr.strip() == f"chaincomp protocol: error: {word}" or word in proc.stderr, proc.stderr
    assert len(proc.stderr.strip().splitlines()) == 1
