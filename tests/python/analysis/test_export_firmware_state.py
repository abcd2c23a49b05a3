"""The printers' skew commands in the G-code state they meet (issue #42 item 4), replayed by the
tests' readers of the firmwares (firmware_skew.py: Marlin M852.cpp, G20_G21, planner.h skew();
RepRapFirmware GCodes2.cpp case 556, Move.cpp AxisTransform) on the tests' own gantry
(test_export.OWN, its tool point written out by hand)."""

import numpy as np
import pytest

import firmware_skew
from test_export import SQ, SQUARENESS, export, own_model, random_points


OWN_BOUNDS = (0.0, 300.0, 0.0, 200.0)   # OWN's X and Y limits: the printer's X/Y MIN_POS and MAX_POS


def tool_error_mm(apply, factors, points):
    motor = apply(factors, np.array(points))
    return own_model(*motor, **SQ) - np.array(points)


def grid(n=5):
    """The report's check points of the matrix formats: n per axis over OWN's limits."""
    axes = [np.linspace(0, 300, n), np.linspace(0, 200, n), np.linspace(-100, 0, n)]
    return [v.ravel() for v in np.meshgrid(*axes, indexing="ij")]


def test_marlin_sets_millimetres_before_m852_and_says_what_i_alone_leaves(capsys, tmp_path):
    doc, out = export(capsys, tmp_path, SQUARENESS, "marlin", "--grid", "5", "--no-breakdown")
    program = out.read_text()
    # a printer left in inches by an earlier program: the factors still land as written in mm
    inch = firmware_skew.replay_marlin(program, inch=True)
    assert inch == pytest.approx(firmware_skew.replay_marlin(program), abs=1e-12)
    x, y, z = random_points()
    assert np.linalg.norm(tool_error_mm(firmware_skew.apply_marlin, inch, (x, y, z)), axis=0).max() * 1e3 < 0.01
    # the M852 line alone in G20 would be 25.4 times too large (or refused beyond 1)
    m852 = [line for line in program.splitlines() if line.startswith("M852")]
    alone = firmware_skew.replay_marlin("\n".join(m852), inch=True)
    assert alone["xy"] == pytest.approx(25.4 * firmware_skew.replay_marlin(program)["xy"])
    # a Marlin without SKEW_CORRECTION_FOR_Z: I alone; the report gives its residual once touched off
    assert "SKEW_CORRECTION_FOR_Z" in program
    only_i = firmware_skew.replay_marlin(program, for_z=False)
    assert only_i["xz"] == only_i["yz"] == 0.0
    g = np.array(grid())   # over the points skew() corrects (planner.h), each touched off by its mean there
    corrected = np.any(firmware_skew.apply_marlin(only_i, g, OWN_BOUNDS) != g, axis=0)
    err = tool_error_mm(firmware_skew.apply_marlin, only_i, g)[:, corrected]
    left = np.linalg.norm(err - err.mean(axis=1, keepdims=True), axis=0).max() * 1e3
    assert left > 1.0   # the tilts of Z are left: a real difference to report
    assert doc["without_skew_correction_for_z"]["max_um"] == pytest.approx(left, abs=0.01)


def test_rrf_replaces_an_earlier_p1(capsys, tmp_path):
    doc, out = export(capsys, tmp_path, SQUARENESS, "rrf", "--grid", "5", "--no-breakdown")
    program = out.read_text()
    earlier = firmware_skew.replay_rrf("M556 S100 X0.5 Y-0.2 Z0.3 P1")
    assert earlier["compensateXY"] is False
    after = firmware_skew.replay_rrf(program, earlier)
    assert after == firmware_skew.replay_rrf(program)   # nothing of the earlier setting is left
    x, y, z = random_points()
    assert np.linalg.norm(tool_error_mm(firmware_skew.apply_rrf, after, (x, y, z)), axis=0).max() * 1e3 < 0.01
    # without P the earlier P1 would stay: the XY term on Y, several um off on this gantry
    no_p = firmware_skew.replay_rrf(program.replace(" P0", ""), earlier)
    assert np.linalg.norm(tool_error_mm(firmware_skew.apply_rrf, no_p, (x, y, z)), axis=0).max() * 1e3 > 1.0


def test_marlin_reports_the_points_its_skew_corrects_and_those_it_leaves(capsys, tmp_path):
    """Marlin's skew() (planner.h) corrects a point only 1 mm or more above X and Y min with the
    skewed X, Y inside the bounds; the others pass uncorrected. The report's residual is over the
    corrected points, and it gives what the others keep."""
    doc, out = export(capsys, tmp_path, SQUARENESS, "marlin", "--grid", "5", "--no-breakdown", "--json")
    factors = firmware_skew.replay_marlin(out.read_text())
    g = np.array(grid())
    motor = firmware_skew.apply_marlin(factors, g, OWN_BOUNDS)
    corrected = np.any(motor != g, axis=0)
    offset = np.array(doc["offset_um"]).reshape(3, 1) * 1e-3
    err = own_model(*motor, **SQ) - g - offset
    norm = np.linalg.norm(err, axis=0) * 1e3
    u = doc["uncorrected"]
    assert u["of"] == 125 and u["points"] == np.count_nonzero(~corrected) > 0
    assert doc["after_offset"]["max_um"] == pytest.approx(norm[corrected].max(), abs=0.01)
    assert u["left"]["max_um"] == pytest.approx(norm[~corrected].max(), abs=0.01)
    assert u["left"]["max_um"] > 10 * doc["after_offset"]["max_um"]   # the edges keep the squareness


def test_klipper_reports_the_moves_it_refuses(capsys, tmp_path):
    doc, out = export(capsys, tmp_path, SQUARENESS, "klipper", "--grid", "5", "--no-breakdown", "--json")
    factors = firmware_skew.parse_klipper(out.read_text())
    g = np.array(grid())
    refused = firmware_skew.klipper_refuses(factors, g, OWN_BOUNDS)
    offset = np.array(doc["offset_um"]).reshape(3, 1) * 1e-3
    norm = np.linalg.norm(own_model(*firmware_skew.apply_klipper(factors, g), **SQ) - g - offset, axis=0) * 1e3
    assert doc["uncorrected"]["points"] == np.count_nonzero(refused) > 0 and doc["uncorrected"]["left"] is None
    assert doc["after_offset"]["max_um"] == pytest.approx(norm[~refused].max(), abs=0.01)
