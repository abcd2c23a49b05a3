"""Bugs found in the second review of the session's changes, each pinned by a test that
failed before its fix."""

import os
import subprocess
import sys

import pytest

ROOT = os.path.abspath(os.path.join(os.path.dirname(__file__), "..", ".."))


def derive(tmp_path, text):
    path = tmp_path / "m.yaml"
    path.write_text(text)
    return subprocess.run([sys.executable, "-m", "chaincomp.cli.main", "derive", str(path)], capture_output=True,
                          text=True, cwd=ROOT, timeout=120)


def refused(proc, field, word):
    assert proc.returncode == 2 and "Traceback" not in proc.stderr, proc.stderr
    assert f" {field}: " in proc.stderr and word in proc.stderr, proc.stderr


def test_abs_of_an_error_is_not_analytic(tmp_path):
    # sqrt(e^2) is |e|: it has no derivative at zero error, so no Taylor series to truncate.
    proc = derive(tmp_path, "name: abs_test\nsymbols:\n"
                  "  - {name: x, role: axis, unit: mm, limits: [-100, 100]}\n"
                  "  - {name: e, role: error, unit: um}\n"
                  "chain:\n  - {translate: [x, 0, 0]}\n  - {translate: ['sqrt(e^2)', 0, 0]}\n"
                  "tool:\n  point: [0, 0, 0]\n")
    refused(proc, "chain[1].translate[0]", "absolute value")


def test_abs_away_from_zero_is_fine(tmp_path):
    proc = derive(tmp_path, "name: abs_ok\nsymbols:\n"
                  "  - {name: x, role: axis, unit: mm, limits: [-100, 100]}\n"
                  "  - {name: e, role: error, unit: um}\n"
                  "chain:\n  - {translate: [x, 0, 0]}\n  - {translate: ['sqrt((e + 1)^2)', 0, 0]}\n"
                  "tool:\n  point: [0, 0, 0]\n")
    assert proc.returncode == 0, proc.stderr


LOOP = """name: loop_test
symbols:
  - {name: q1, role: axis, unit: deg, limits: [-360, 360]}
  - {name: q2, role: axis, unit: deg, limits: [-360, 360]}
loop:
  tool:
    - {dh: {theta: q1, d: 10, a: 5, alpha: 0}, errors: auto}
  workpiece:
    - {dh: {theta: q2, d: 20, a: 7, alpha: 0}, errors: WORK}
tool:
  point: [0, 0, 0]
  direction: [0, 0, 1]
"""


def test_auto_errors_of_two_loop_branches_do_not_merge(tmp_path):
    # Joint 1 of each branch auto-named dtheta1, dd1, ...: two physical errors silently became
    # one symbol (and the loop's two dtheta1 rotations cancelled).
    refused(derive(tmp_path, LOOP.replace("WORK", "auto")), "loop.workpiece[0].errors.theta", "already")


def test_explicit_names_in_the_second_branch_load(tmp_path):
    proc = derive(tmp_path, LOOP.replace("WORK", "{theta: wt1, d: wd1}"))
    assert proc.returncode == 0, proc.stderr
    assert "wt1" in proc.stdout and "dtheta1" in proc.stdout


def test_two_betas_after_one_joint_do_not_share_an_error(tmp_path):
    proc = derive(tmp_path, "name: beta_test\nsymbols:\n"
                  "  - {name: q1, role: axis, unit: deg, limits: [-360, 360]}\n"
                  "chain:\n  - {dh: {theta: q1, d: 10, a: 5, alpha: 0}, errors: auto}\n"
                  "  - {beta: 0, errors: auto}\n  - {beta: 0, errors: auto}\n"
                  "tool:\n  point: [0, 0, 0]\n  direction: [0, 0, 1]\n")
    refused(proc, "chain[2].errors.beta", "already")


# --- the parallel-axes lint's advice, checked by the rank of an independent numpy model ---

import math  # noqa: E402
import re  # noqa: E402

import numpy as np  # noqa: E402

from arm_models import UR5_A, UR5_ALPHA, UR5_D, mod_link, ry, std_link  # noqa: E402

# A UR5 in both conventions (joints 2, 3, 4 parallel), and the same arm written in Craig's
# (each link's a and alpha moved to the next link).
ARM = {"dh": {"d": UR5_D, "a": UR5_A, "alpha": UR5_ALPHA},
       "mdh": {"d": UR5_D, "a": [0.0] + UR5_A[:-1], "alpha": [0.0] + UR5_ALPHA[:-1]}}


def arm_text(kind, no_d=(), betas=()):
    p = ARM[kind]
    s = "name: arm\nsymbols:\n" + "".join(f"  - {{name: q{j}, role: axis, unit: deg, limits: [-360, 360]}}\n"
                                        for j in range(1, 7)) + "chain:\n"
    for i in range(6):
        j = i + 1
        err = "{theta: auto, a: auto, alpha: auto}" if j in no_d else "auto"
        body = (f"theta: q{j}, d: {p['d'][i]}, a: {p['a'][i]}, alpha: {p['alpha'][i]!r}" if kind == "dh" else
                f"alpha: {p['alpha'][i]!r}, a: {p['a'][i]}, theta: q{j}, d: {p['d'][i]}")
        s += f"  - {{{kind}: {{{body}}}, errors: {err}}}\n" + ("  - {beta: 0, errors: auto}\n" if j in betas else "")
    return s + "  - {translate: [10, 0, 50]}\ntool:\n  point: [0, 0, 0]\n  direction: [0, 0, 1]\n"


def numpy_rank(kind, no_d, betas):
    """Rank of d(point, direction)/d(errors) over random poses, by central differences of the
    textbook link product (theta, d, a, alpha errors per joint, less the dropped d; betas)."""
    p = ARM[kind]
    cols = [(j, k) for j in range(1, 7) for k in ("theta", "d", "a", "alpha") if not (k == "d" and j in no_d)]
    cols += [(j, "beta") for j in betas]

    def pose(q, e):
        T = np.eye(4)
        for i in range(6):
            j = i + 1
            th, d, a, al = (q[i] + e.get((j, "theta"), 0), p["d"][i] + e.get((j, "d"), 0),
                            p["a"][i] + e.get((j, "a"), 0), p["alpha"][i] + e.get((j, "alpha"), 0))
            T = T @ (std_link(th, d, a, al) if kind == "dh" else mod_link(al, a, th, d))
            if j in betas:
                T = T @ ry(e.get((j, "beta"), 0))
        T = T @ np.array([[1, 0, 0, 10], [0, 1, 0, 0], [0, 0, 1, 50], [0, 0, 0, 1.0]])
        return np.concatenate([T[:3, 3], T[:3, 2]])

    rng = np.random.default_rng(7)
    rows = []
    for _ in range(30):
        q = rng.uniform(-math.pi, math.pi, 6)
        rows.append(np.array([(pose(q, {c: 1e-6}) - pose(q, {c: -1e-6})) / 2e-6 for c in cols]).T)
    s = np.linalg.svd(np.vstack(rows), compute_uv=False)
    return int((s > 1e-7 * s[0]).sum())


@pytest.mark.parametrize("kind", ["dh", "mdh"])
def test_following_the_parallel_axes_advice_adds_a_freedom_per_beta(tmp_path, kind):
    from chaincomp import load_machine
    from chaincomp.analysis.lint import lint
    path = tmp_path / "arm.yaml"
    path.write_text(arm_text(kind))
    advice = [f.message for f in lint(load_machine(str(path))) if "parallel" in f.message]
    assert len(advice) == 2, advice
    no_d = [int(re.search(r"d error dd(\d+)", a).group(1)) for a in advice]
    betas = [int(re.search(r"after joint (\d+)", a).group(1)) for a in advice]
    # each beta must describe the missing tilt (a beta where none is missing is redundant)
    assert numpy_rank(kind, no_d, betas) == numpy_rank(kind, (), ()) + 2, (no_d, betas)


def test_no_parallel_warning_against_the_base_frame(tmp_path):
    # mdh joint 1's alpha is the twist from the base frame, not from a joint: d1 is defined.
    from chaincomp import load_machine
    from chaincomp.analysis.lint import lint
    path = tmp_path / "arm.yaml"
    path.write_text(arm_text("mdh"))
    assert not [f for f in lint(load_machine(str(path))) if f.field == "symbols.dd1"]


# --- the expression parser ---

@pytest.mark.parametrize("text", ["\u0663", "1\u0663", "\u0663.5"])   # Arabic-Indic three
def test_only_ascii_digits_are_numbers(text):
    # float('\u0663') is 3.0, but the grammar (and the C++ side, and parse_number) know 0-9 only
    from chaincomp.model.expressions import ExpressionError, parse
    with pytest.raises(ExpressionError):
        parse(text, {})


@pytest.mark.parametrize("text", ["(-8)^(1/3)", "acos(2)", "asin(3/2)", "2 + (-1)^(1/2)"])
def test_complex_constants_are_not_real(text):
    # (-8)^(1/3) is 1 + 1.732i in sympy's principal branch; acos(2) is 1.317i
    from chaincomp.model.expressions import ExpressionError, parse
    with pytest.raises(ExpressionError, match="not real"):
        parse(text, {})


def test_real_constants_still_parse():
    import sympy as sp
    from chaincomp.model.expressions import parse
    assert parse("8^(1/3)", {}) == 2 and parse("acos(1/2)", {}) == sp.pi / 3 and parse("(-2)^2", {}) == 4


# --- YAML numbers ---

@pytest.mark.parametrize("written,value", [("1.5e3", 1500.0), ("1e3", 1000.0), ("-2.5E-1", -0.25), ("1.5e+3", 1500.0)])
def test_exponent_numbers_are_numbers(tmp_path, written, value):
    # YAML 1.1 (PyYAML) reads 1e3 and 1.5e3 as text, YAML 1.2 (yaml-cpp, the runtime) as
    # numbers: 'expected a number, got str' for a number as written was the message.
    from chaincomp import load_machine
    path = tmp_path / "m.yaml"
    path.write_text("name: num_test\nsymbols:\n  - {name: x, role: axis, unit: mm, limits: [-100, 100]}\n"
                    f"  - {{name: L, role: constant, unit: mm, nominal: {written}}}\n"
                    "  - {name: e, role: error, unit: um}\nchain:\n  - {translate: [x + L + e, 0, 0]}\n"
                    "tool:\n  point: [0, 0, 0]\n")
    assert load_machine(str(path)).symbol("L").nominal == value


def test_parallel_axes_lint_keeps_loop_branches_apart(tmp_path):
    # joints are numbered per branch: the workpiece's joint 2 is not the tool's
    from chaincomp import load_machine
    from chaincomp.analysis.lint import lint
    path = tmp_path / "loop.yaml"
    path.write_text("name: loop_dh\nsymbols:\n" + "".join(
        f"  - {{name: q{j}, role: axis, unit: deg, limits: [-360, 360]}}\n" for j in range(1, 5)) +
        "  - {name: td2, role: error, unit: um}\n  - {name: wd2, role: error, unit: um}\n"
        "loop:\n  tool:\n"
        "    - {dh: {theta: q1, d: 10, a: 300, alpha: 0}}\n"
        "    - {dh: {theta: q2, d: 20, a: 200, alpha: 0}, errors: {d: td2}}\n"
        "  workpiece:\n"
        "    - {dh: {theta: q3, d: 30, a: 100, alpha: 1.5707963267948966}}\n"
        "    - {dh: {theta: q4, d: 40, a: 50, alpha: 1.5707963267948966}, errors: {d: wd2}}\n"
        "tool:\n  point: [0, 0, 0]\n  direction: [0, 0, 1]\n")
    warned = {f.field for f in lint(load_machine(str(path))) if "parallel" in f.message}
    assert warned == {"symbols.td2"}


def test_atan2_on_its_branch_cut_is_not_analytic(tmp_path):
    # atan2(e, -1) is pi for e >= 0 and -pi for e < 0: a jump of 2 pi mm at zero error
    machine = ("name: cut_test\nsymbols:\n  - {name: x, role: axis, unit: mm, limits: [-100, 100]}\n"
               "  - {name: e, role: error, unit: um}\n"
               "chain:\n  - {translate: [x, 0, 0]}\n  - {translate: ['atan2(e, X)', 0, 0]}\ntool:\n  point: [0, 0, 0]\n")
    refused(derive(tmp_path, machine.replace("X", "-1")), "chain[1].translate[0]", "branch cut")
    assert derive(tmp_path, machine.replace("X", "1")).returncode == 0
