"""Numbers in YAML files: a YAML 1.1 exponent written as text says how to write the number; a quoted
number gets no spelling hint."""

from __future__ import annotations

import pytest

from helpers import VMC, refused


@pytest.mark.parametrize("written,hint", [
    ("1.0e300", "write 1.0e+300"), ("1e15", "write 1.0e+15"), ("1e+3", "write 1.0e+3"),
    (".5e3", "write .5e+3"), ("-2E5", "write -2.0e+5"),
])
def test_a_yaml11_text_exponent_says_how_to_write_the_number(capsys, tmp_path, written, hint):
    """PyYAML (YAML 1.1) reads an exponent number without a dot and a sign as text: the message
    said 'expected a number, got str ...' and no more. Each suggested spelling is read back here
    by PyYAML as a number."""
    import yaml
    suggested = hint.split()[-1]
    assert isinstance(yaml.safe_load(f"v: {suggested}")["v"], float)
    assert yaml.safe_load(f"v: {written}")["v"] == written
    p = tmp_path / "p.yaml"
    p.write_text(f"machine: vmc_xyz\nvalues:\n  EXX: {{axis: X, units: [mm, um], polynomial: [{written}, 2]}}\n")
    refused(capsys, "eval", VMC, "--params", p,
             match=f"p.yaml:3: values.EXX.polynomial[0]: expected a number, got str '{written}' "
                   f"(YAML reads {written} as text: {hint})")


def test_a_quoted_number_gets_no_spelling_hint(capsys, tmp_path):
    p = tmp_path / "p.yaml"
    p.write_text("machine: vmc_xyz\nvalues:\n  EXX: {axis: X, units: [mm, um], polynomial: ['1.0e+3', 2]}\n")
    err = refused(capsys, "eval", VMC, "--params", p, match="expected a number, got str '1.0e+3'")
    assert "YAML reads" not in err
