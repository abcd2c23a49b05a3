"""The expressions of a machine file at the edges: the wrong shape named plainly, abs and atan2 where
they have no Taylor series, only ASCII digits, complex constants refused, exponent numbers read
as numbers."""

import pytest

from helpers import arm_file, derive_text, one_error_line, refused_field, run_in_process


def test_an_expression_of_the_wrong_shape_is_named_plainly(tmp_path):
    # the loader's own class name leaked: "expected a number or an expression, got LineList"
    p = arm_file(tmp_path, "shape", "", "  - {dh: {theta: q1, d: 0, a: 1, alpha: 0}}\n  - {beta: [1], errors: auto}\n")
    line = one_error_line(run_in_process("lint", str(p)), "lint", "shape.yaml:7:", "chain[1].beta", "a list")
    assert "LineList" not in line


@pytest.mark.slow
def test_abs_of_an_error_is_not_analytic(tmp_path):
    # sqrt(e^2) is |e|: it has no derivative at zero error, so no Taylor series to truncate.
    proc = derive_text(tmp_path, "name: abs_test\nsymbols:\n"
                  "  - {name: x, role: axis, unit: mm, limits: [-100, 100]}\n"
                  "  - {name: e, role: error, unit: um}\n"
                  "chain:\n  - {translate: [x, 0, 0]}\n  - {translate: ['sqrt(e^2)', 0, 0]}\n"
                  "tool:\n  point: [0, 0, 0]\n")
    refused_field(proc, "chain[1].translate[0]", "absolute value")


@pytest.mark.slow
def test_abs_away_from_zero_is_fine(tmp_path):
    proc = derive_text(tmp_path, "name: abs_ok\nsymbols:\n"
                  "  - {name: x, role: axis, unit: mm, limits: [-100, 100]}\n"
                  "  - {name: e, role: error, unit: um}\n"
                  "chain:\n  - {translate: [x, 0, 0]}\n  - {translate: ['sqrt((e + 1)^2)', 0, 0]}\n"
                  "tool:\n  point: [0, 0, 0]\n")
    assert proc.returncode == 0, proc.stderr


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


@pytest.mark.slow
def test_atan2_on_its_branch_cut_is_not_analytic(tmp_path):
    # atan2(e, -1) is pi for e >= 0 and -pi for e < 0: a jump of 2 pi mm at zero error
    machine = ("name: cut_test\nsymbols:\n  - {name: x, role: axis, unit: mm, limits: [-100, 100]}\n"
               "  - {name: e, role: error, unit: um}\n"
               "chain:\n  - {translate: [x, 0, 0]}\n  - {translate: ['atan2(e, X)', 0, 0]}\ntool:\n  point: [0, 0, 0]\n")
    refused_field(derive_text(tmp_path, machine.replace("X", "-1")), "chain[1].translate[0]", "branch cut")
    assert derive_text(tmp_path, machine.replace("X", "1")).returncode == 0
