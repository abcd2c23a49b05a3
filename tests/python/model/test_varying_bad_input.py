"""Errors that vary along an axis: a polynomial beyond the value bound is refused."""

from __future__ import annotations

from helpers import VMC, refused, run_main


def test_eval_refuses_a_polynomial_beyond_the_value_bound(capsys, tmp_path):
    """Each coefficient within bounds, the value not: 1 + 1e300 * 100 = 1e302 um at X = 100 mm was
    printed as a 300-digit error."""
    p = tmp_path / "p.yaml"
    p.write_text("machine: vmc_xyz\nvalues:\n  EXX:\n    axis: X\n    units: [mm, um]\n"
                 "    polynomial: [1, 1.0e+300]\n    range: [-400, 400]\n    outside: hold\n")
    refused(capsys, "eval", VMC, "--params", p, "--set", "X=100",
             match=f"{p}:3: values.EXX: EXX = 1e+302 um at X = 100 mm: beyond 1e+15 (mm, rad) in magnitude")
    code, _, err = run_main(capsys, "eval", VMC, "--params", p, "--set", "X=0")   # 1 um there
    assert code == 0, err
