"""dh, mdh and beta chain elements against the textbook matrices written here (standard DH:
Rz(theta) Tz(d) Tx(a) Rx(alpha), one 4x4 per link; Craig's modified DH: Rx(alpha) Tx(a)
Rz(theta) Tz(d); Hayati's beta: Ry(beta)), on Universal Robots' published UR5 table and
Franka's published Panda table; auto-named errors; the parallel-axes lint; bad elements."""

import math
import subprocess
import sys

import numpy as np
import pytest

from chaincomp import ChaincompError, ExactModel, load_machine
from chaincomp.symbolic.jets import JetModel
from chaincomp.analysis.lint import lint

from arm_models import PANDA_A, PANDA_ALPHA, PANDA_D, PANDA_FLANGE, UR5_A, UR5_ALPHA, UR5_D, panda, ur5
from helpers import ROOT

UR5 = {"d": UR5_D, "a": UR5_A, "alpha": UR5_ALPHA}
PANDA = {"a": PANDA_A, "d": PANDA_D, "alpha": PANDA_ALPHA}
FLANGE = PANDA_FLANGE


def num(x):
    """A table number as the YAML is written: integral values without a decimal point."""
    return str(int(x)) if float(x).is_integer() else repr(x)


def axes_yaml(n):
    return "".join(f"  - {{name: q{i}, role: axis, unit: deg, limits: [-360, 360]}}\n" for i in range(1, n + 1))


def write(tmp_path, name, text):
    path = tmp_path / f"{name}.yaml"
    path.write_text(text)
    return str(path)


def ur5_text(errors="auto", extra=""):
    chain = "".join(f"  - {{dh: {{theta: q{i + 1}, d: {num(UR5['d'][i])}, a: {num(UR5['a'][i])}, "
                    f"alpha: {num(UR5['alpha'][i])}}}, errors: {errors}}}\n" for i in range(6))
    return (f"name: ur5_test\nsymbols:\n{axes_yaml(6)}{extra}chain:\n{chain}"
            "tool:\n  point: [0, 0, 0]\n  direction: [0, 0, 1]\n")


def panda_text():
    chain = "".join(f"  - {{mdh: {{alpha: {num(PANDA['alpha'][i])}, a: {num(PANDA['a'][i])}, theta: q{i + 1}, "
                    f"d: {num(PANDA['d'][i])}}}, errors: auto}}\n" for i in range(7))
    return (f"name: panda_test\nsymbols:\n{axes_yaml(7)}chain:\n{chain}  - {{translate: [0, 0, {FLANGE}]}}\n"
            "tool:\n  point: [0, 0, 0]\n  direction: [0, 0, 1]\n")


def random_errors(m, rng):
    return {s.name: 1e-3 * rng.normal() for s in m.errors}


def test_ur5_dh_against_the_textbook_product(tmp_path):
    m = load_machine(write(tmp_path, "ur5", ur5_text()))
    assert [s.name for s in m.errors][:4] == ["dtheta1", "dd1", "da1", "dalpha1"] and len(m.errors) == 24
    assert m.symbol("dd1").unit.name == "um" and m.symbol("dtheta1").unit.name == "arcsec"
    rng = np.random.default_rng(1)
    exact = ExactModel(m)
    for _ in range(50):
        q = rng.uniform(-math.pi, math.pi, 6)
        e = random_errors(m, rng)
        T = ur5(q, e)
        p, d = exact.pose({f"q{i + 1}": q[i] for i in range(6)} | e)
        assert np.allclose(p, T[:3, 3], atol=1e-9) and np.allclose(d, T[:3, 2], atol=1e-12)


def test_panda_mdh_against_the_textbook_product(tmp_path):
    m = load_machine(write(tmp_path, "panda", panda_text()))
    rng = np.random.default_rng(2)
    exact = ExactModel(m)
    for _ in range(50):
        q = rng.uniform(-math.pi, math.pi, 7)
        e = random_errors(m, rng)
        T = panda(q, e)
        p, d = exact.pose({f"q{i + 1}": q[i] for i in range(7)} | e)
        assert np.allclose(p, T[:3, 3], atol=1e-9) and np.allclose(d, T[:3, 2], atol=1e-12)


def test_hayati_beta_and_the_parallel_axes_lint(tmp_path):
    m = load_machine(write(tmp_path, "ur5", ur5_text()))
    warned = {f.field for f in lint(m) if "parallel" in f.message}
    assert warned == {"symbols.dd3", "symbols.dd4"}     # joints 2, 3, 4 of the UR5 are parallel
    # joint 3 as Hayati writes it: no d error, a beta after it
    text = ur5_text().replace("  - {dh: {theta: q3, d: 0, a: -392.25, alpha: 0}, errors: auto}\n",
                              "  - {dh: {theta: q3, d: 0, a: -392.25, alpha: 0}, errors: {theta: auto, a: auto, "
                              "alpha: auto}}\n  - {beta: 0, errors: auto}\n")
    m = load_machine(write(tmp_path, "hayati", text))
    assert "dbeta3" in [s.name for s in m.errors] and "dd3" not in [s.name for s in m.errors]
    assert {f.field for f in lint(m) if "parallel" in f.message} == {"symbols.dd4"}
    rng = np.random.default_rng(3)
    q = rng.uniform(-math.pi, math.pi, 6)
    e = random_errors(m, rng)
    T = ur5(q, e, betas=(3,))
    p, _ = ExactModel(m).pose({f"q{i + 1}": q[i] for i in range(6)} | e)
    assert np.allclose(p, T[:3, 3], atol=1e-9)


def test_named_errors_and_truncation(tmp_path):
    extra = "  - {name: dq1, role: error, unit: arcsec}\n"
    text = ur5_text(errors="{}", extra=extra).replace("errors: {}", "errors: {theta: dq1}", 1)
    m = load_machine(write(tmp_path, "named", text))
    assert [s.name for s in m.errors] == ["dq1"]
    # residual of the first-order jets against the exact model falls as eps^2
    rng = np.random.default_rng(4)
    v = {f"q{i}": rng.uniform(-3, 3) for i in range(1, 7)}
    res = [abs(np.array(JetModel(m, 1).error(v | {"dq1": h})[0]) - np.array(ExactModel(m).error(v | {"dq1": h})[0])).max()
           for h in (1e-3, 1e-4)]
    assert abs(math.log10(res[0] / res[1]) - 2) < 0.2


@pytest.mark.parametrize("old,new,field,word", [
    ("{theta: q1, d: 89.159, a: 0, alpha: 1.5707963267948966}", "{theta: q1, d: 89.159, a: 0}", "chain[0].dh",
     "missing required field 'alpha'"),
    ("{theta: q1, d: 89.159, a: 0, alpha: 1.5707963267948966}", "{theta: q1, d: 89.159, a: 0, alpha: 0, r: 1}",
     "chain[0].dh.r", "unknown field 'r'"),
    ("errors: auto}\n", "errors: 5}\n", "chain[0].errors", "expected 'auto' or a mapping"),
    ("errors: auto}\n", "errors: {theta: q2}}\n", "chain[0].errors.theta", "declared as an axis"),
    ("errors: auto}\n", "errors: {theta: int}}\n", "chain[0].errors.theta", "reserved"),
    ("errors: auto}\n", "errors: {theta: 'a b'}}\n", "chain[0].errors.theta", "an error name or 'auto'"),
    ("alpha: 1.5707963267948966}", "alpha: Q}", "chain[0].dh.alpha", "unknown symbol 'Q'"),
])
@pytest.mark.slow
def test_bad_joint_elements(tmp_path, old, new, field, word):
    text = ur5_text()
    assert old in text
    text = text.replace(old, new, 1)
    path = write(tmp_path, "bad", text)
    proc = subprocess.run([sys.executable, "-m", "chaincomp.cli.main", "derive", path], capture_output=True,
                          text=True, cwd=ROOT, timeout=120)
    assert proc.returncode == 2 and "Traceback" not in proc.stderr, proc.stderr
    assert f" {field}: " in proc.stderr and word in proc.stderr, proc.stderr


@pytest.mark.parametrize("unit,param,kind", [("um", "theta", "an angle"), ("arcsec", "d", "a length")])
def test_named_error_of_the_wrong_kind(tmp_path, unit, param, kind):
    # a twist error declared in um would otherwise be read as radians (1 um -> 1e-3 rad)
    extra = f"  - {{name: e1, role: error, unit: {unit}}}\n"
    text = ur5_text(errors="{}", extra=extra).replace("errors: {}", f"errors: {{{param}: e1}}", 1)
    with pytest.raises(ChaincompError) as err:
        load_machine(write(tmp_path, "kind", text))
    msg = str(err.value)
    assert f"chain[0].errors.{param}" in msg and f"declared in {unit}" in msg and kind in msg, msg
