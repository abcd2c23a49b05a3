"""Units where a symbol stands in a machine file a user writes: a translation reads mm, a rotation
rad; a symbol of the wrong kind, DH parameters of the wrong kind, an axis with a nominal and the
Greek mu are refused with file, line and field."""

from __future__ import annotations

import json
import math

import pytest

from helpers import DH, M4, cli, edited, line_holding, refused_one_line, run_cli, write_file


# A translation reads its expression in mm, a rotation in rad. Before the fix, each of these loaded
# and ran: EBB = 4 arcsec standing as dx moved the tool by 4 arcsec in rad read as mm (19 nm, not
# the user's lever arm), an axis in mm as an angle turned by X mm read as radians, ...
UNIT_MISMATCHES = [
    ("{errors: {dx: EXB, ey: EBB}}", "{errors: {dx: EBB, ey: EXB}}", "chain[7].errors.dx",
     "error 'EBB' is declared in arcsec (an angle) on line 16 but stands in a translation, which reads it as a "
     "length (mm)"),
    ("{errors: {dx: EXB, ey: EBB}}", "{errors: {dx: EXB, ey: -EXB}}", "chain[7].errors.ey",
     "error 'EXB' is declared in um (a length) on line 17 but stands in a rotation, which reads it as an angle "
     "(rad)"),
    ("{rotate: y, angle: B}", "{rotate: y, angle: 2*X}", "chain[6].angle",
     "axis 'X' is declared in mm (a length) on line 7 but stands in a rotation"),
    ("{translate: [X, 0, 0]}", "{translate: [X + B, 0, 0]}", "chain[0].translate[0]",
     "axis 'B' is declared in deg (an angle) on line 10 but stands in a translation"),
    ("{name: L, role: constant, unit: mm, nominal: 120}", "{name: L, role: constant, unit: deg, nominal: 120}",
     "chain[8].translate[2]", "constant 'L' is declared in deg (an angle) on line 11 but stands in a translation"),
    ("  point: [0, 0, 0]", "  point: [0, 0, B/2]", "tool.point[2]",
     "axis 'B' is declared in deg (an angle) on line 10 but stands in a translation"),
]


@pytest.mark.parametrize("old, new, field, message", UNIT_MISMATCHES, ids=[u[2] for u in UNIT_MISMATCHES])
def test_a_symbol_of_the_wrong_kind_where_it_stands_is_refused(tmp_path, old, new, field, message):
    text = edited(M4, old, new)
    path = write_file(tmp_path, "m.yaml", text)
    at = line_holding(text, new.splitlines()[0].strip()) if field != "chain[8].translate[2]" else line_holding(text, "-L]")
    for verb in ("lint", "eval"):
        err = refused_one_line(verb, path, match=f"m.yaml:{at}: {field}: {message}")
        assert err.startswith(f"chaincomp {verb}: error: ")


@pytest.mark.parametrize("old, new, field, message", [
    ("unit: deg, limits: [-180, 180]}", "unit: mm, limits: [-180, 180]}", "chain[0].dh.theta",
     "axis 'q1' is declared in mm (a length) on line 4 but stands in a rotation"),
    ("d: 300,", "d: q2,", "chain[0].dh.d", "axis 'q2' is declared in deg (an angle) on line 5 but stands in a "
                                          "translation"),
    ("{beta: 0, errors: auto}", "{beta: q1 - q2, errors: auto}", None, None),   # angles: fine
])
def test_dh_parameters_of_the_wrong_kind_are_refused(tmp_path, old, new, field, message):
    text = DH.replace(old, new, 1)
    path = write_file(tmp_path, "arm.yaml", text)
    if field is None:
        assert cli("lint", path).returncode == 0
        return
    refused_one_line("lint", path, match=f"arm.yaml:8: {field}: {message}")


def test_products_and_ratios_where_they_belong_still_load(tmp_path):
    """A lever arm times an angle is a length (L*EBB as dx); a squareness in um/m (ppm) is an angle
    to first order; a symbol inside a function is not checked (sin(B)^2 is a number). With
    EBB = 1 arcsec the block translates the tool by dx = L*EBB = 120 mm x 1 arcsec in rad (by
    hand), exactly: a translation has no higher-order part."""
    text = edited(M4, "{errors: {dx: EXB, ey: EBB}}", "{errors: {dx: EXB + L*EBB, ey: EC0}}")
    text = edited(text, "  - {name: EXB, role: error, unit: um}",
                   "  - {name: EXB, role: error, unit: um}\n  - {name: EC0, role: error, unit: ppm}")
    text = edited(text, "{translate: [0, 0, -L]}", "{translate: [0, 0, -L*cos(B)^2 - L*sin(B)^2]}")
    path = write_file(tmp_path, "m.yaml", text)
    assert cli("lint", path).returncode == 0
    error = json.loads(cli("eval", path, "--set", "EBB=1 arcsec", "--json").stdout)["error"]
    assert error["exact"] == pytest.approx([120 * math.radians(1 / 3600), 0, 0], rel=1e-12, abs=1e-15)
    # EC0 = 1 ppm turns the tool's 120 mm about y: dx = -120 mm x 1e-6 to first order
    error = json.loads(cli("eval", path, "--set", "EC0=1 ppm", "--json").stdout)["error"]
    assert error["first"] == pytest.approx([-120e-6, 0, 0], rel=1e-12, abs=1e-15)


# ----------------------------------------------------------------------------- an axis' nominal

def test_an_axis_with_a_nominal_is_refused(tmp_path):
    """Nothing read it: eval, identify and the rest put the axis at 0 (or mid-range)."""
    text = edited(M4, "{name: B, role: axis, unit: deg, limits: [-90, 90]}",
                   "{name: B, role: axis, unit: deg, limits: [-90, 90], nominal: 45}")
    path = write_file(tmp_path, "m.yaml", text)
    refused_one_line("eval", path, match="m.yaml:10: symbols.B.nominal: an axis has no nominal value: it stands at 0 "
                                 "(or mid-range where 0 is outside its limits) unless a verb sets it")


# ----------------------------------------------------------------------------- one real process

def test_a_unit_mismatch_exits_2_from_a_process(tmp_path):
    text = edited(M4, "{errors: {dx: EXB, ey: EBB}}", "{errors: {dx: EBB, ey: EXB}}")
    path = write_file(tmp_path, "m.yaml", text)
    proc = run_cli("eval", path, check=False)
    assert proc.returncode == 2
    assert "Traceback" not in proc.stderr
    assert proc.stderr.startswith(f"chaincomp eval: error: {path}:{line_holding(text, 'dx: EBB')}: chain[7].errors.dx: ")


# ----------------------------------------------------------------------------- units: the Greek mu

@pytest.mark.parametrize("where", ["params", "set", "machine"])
def test_a_unit_written_with_the_greek_mu_says_which_letter_to_use(tmp_path, where):
    """'μm' (U+03BC) and 'µm' (U+00B5) look the same; the refusal listed 'µm' among the units it
    expected, which read as nonsense."""
    machine = write_file(tmp_path, "m.yaml", M4 if where != "machine" else
                     edited(M4, "{name: EXX, role: error, unit: um}", "{name: EXX, role: error, unit: \u03bcm}"))
    argv = {"params": ("--params", write_file(tmp_path, "p.yaml", "machine: m4\nvalues:\n  EXX: 5 \u03bcm\n")),
            "set": ("--set", "EXX=5 \u03bcm"), "machine": ()}[where]
    refused_one_line("eval", machine, *argv, match="unknown unit '\u03bcm' (expected one of: mm, m, um, \u00b5m, nm, in, rad, "
             "deg, mrad, urad, \u00b5rad, arcsec, 1, ppm); it is written with the Greek letter mu (U+03BC): write "
             "the micro sign \u00b5 (U+00B5) or u, e.g. 'um'")
