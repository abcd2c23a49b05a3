"""chaincomp export against truth from outside the exporter: machines the test writes into
a temp dir with a tool point written out by hand below (own_model), the controllers' files
read back by independent readers written from the cited documents (linuxcnc_comp.py from
LinuxCNC's source, firmware_skew.py from Klipper's, Marlin's and RepRapFirmware's), the
correction replayed by them, and the tool error of the hand-written model. The bundled
machines: every positioning error is represented by the per-joint tables and every
squareness by the matrix (issue #29: <= 1 um where the format can represent the errors)."""

import json
import os
import re

import numpy as np
import pytest

import firmware_skew
import linuxcnc_comp
from helpers import machine_path, refused_one_line, run_main, write_file, PARAMS

ARCSEC = np.pi / 180 / 3600

OWN = """\
name: own_xyz
description: a gantry of the test's own, three slides with squareness errors
length_unit: mm
rotation_sense: right_hand
symbols:
  - {name: X, role: axis, unit: mm, limits: [0, 300], meaning: X}
  - {name: Y, role: axis, unit: mm, limits: [0, 200], meaning: Y}
  - {name: Z, role: axis, unit: mm, limits: [-100, 0], meaning: Z}
  - {name: EXX, role: error, unit: um, meaning: X positioning}
  - {name: EYY, role: error, unit: um, meaning: Y positioning}
  - {name: EZZ, role: error, unit: um, meaning: Z positioning}
  - {name: SXY, role: error, unit: arcsec, meaning: Y leaning towards +X}
  - {name: SXZ, role: error, unit: arcsec, meaning: Z leaning towards +X}
  - {name: SYZ, role: error, unit: arcsec, meaning: Z leaning towards +Y}
chain:
  - {translate: [X + EXX, 0, 0]}
  - {translate: [Y*sin(SXY), Y*cos(SXY) + EYY, 0]}
  - {translate: [Z*sin(SXZ), Z*sin(SYZ), Z + EZZ]}
tool:
  point: [0, 0, 0]
"""

# EXX and EYY vary along their axes (polynomials, um per mm^k), EZZ is a constant
POSITIONING = """\
machine: own_xyz
values:
  EXX: {axis: X, units: [mm, um], polynomial: [1.0, 0.05, -1.0e-4]}
  EYY: {axis: Y, units: [mm, um], polynomial: [-2.0, 0.0, 1.5e-4]}
  EZZ: 3 um
"""
SQUARENESS = """\
machine: own_xyz
values:
  SXY: 12 arcsec
  SXZ: -8 arcsec
  SYZ: 5 arcsec
"""


def own_model(x, y, z, exx=None, eyy=None, ezz=0.0, sxy=0.0, sxz=0.0, syz=0.0):
    """The tool point of OWN (mm), written out by hand; exx, eyy: functions of x, y (mm -> mm)."""
    ex = exx(x) if exx else 0.0
    ey = eyy(y) if eyy else 0.0
    return np.array([x + ex + y * np.sin(sxy) + z * np.sin(sxz),
                     y * np.cos(sxy) + ey + z * np.sin(syz),
                     z + ezz + 0 * x])


def exx(x):
    return np.polyval([-1.0e-4, 0.05, 1.0], x) * 1e-3


def eyy(y):
    return np.polyval([1.5e-4, 0.0, -2.0], y) * 1e-3


def random_points(n=4000, seed=3):
    rng = np.random.default_rng(seed)
    return rng.uniform(0, 300, n), rng.uniform(0, 200, n), rng.uniform(-100, 0, n)


def export(capsys, tmp_path, params_text, fmt, *extra):
    machine = write_file(tmp_path, "own_xyz.yaml", OWN)
    params = write_file(tmp_path, "own.yaml", params_text)
    out = tmp_path / ("comp" if fmt == "linuxcnc-comp" else "out.txt")
    code, stdout, err = run_main(capsys, "export", machine, "--params", params, "--format", fmt, "-o", out,
                                 "--report", "json", *extra)
    assert code == 0, err
    return json.loads(stdout), out


@pytest.mark.parametrize("file_type", [0, 1])
def test_linuxcnc_tables_cancel_the_positioning_errors(capsys, tmp_path, file_type):
    doc, out = export(capsys, tmp_path, POSITIONING, "linuxcnc-comp", "--entries", "17", "--grid", "7",
                      "--comp-file-type", str(file_type))
    tables = [linuxcnc_comp.read((out / f"joint{n}_{a}.comp").read_text(), file_type)
              for n, a in enumerate("XYZ")]
    assert [len(t) for t in tables] == [17, 17, 17]
    ini = (out / "compensation.ini").read_text()
    assert f"[JOINT_1]\nCOMP_FILE = joint1_Y.comp\nCOMP_FILE_TYPE = {file_type}" in ini

    def residual(x, y, z):
        tx, ty, tz = (linuxcnc_comp.trim(t, v) for t, v in zip(tables, (x, y, z)))
        actual = own_model(x + tx, y + ty, z + tz, exx, eyy, 3e-3)
        return np.linalg.norm(actual - np.array([x, y, z]), axis=0) * 1e3

    x, y, z = random_points()
    before = np.linalg.norm(own_model(x, y, z, exx, eyy, 3e-3) - np.array([x, y, z]), axis=0) * 1e3
    assert before.max() > 5.0
    assert residual(x, y, z).max() < 0.05   # the curvature between 17 entries, float trims
    # the report's residual is the replay's on its own check grid (7 points per axis)
    g = np.meshgrid(np.linspace(0, 300, 7), np.linspace(0, 200, 7), np.linspace(-100, 0, 7), indexing="ij")
    assert doc["after"]["max_um"] == pytest.approx(residual(*g).max(), abs=1e-4)
    assert doc["before"]["max_um"] == pytest.approx(
        (np.linalg.norm(own_model(*g, exx, eyy, 3e-3) - np.array(g), axis=0) * 1e3).max(), rel=1e-9)
    assert {e["name"]: e["represented"] for e in doc["errors"]} == {"EXX": "yes", "EYY": "yes", "EZZ": "yes"}


def test_linuxcnc_tables_leave_out_squareness_and_say_so(capsys, tmp_path):
    doc, _ = export(capsys, tmp_path, SQUARENESS, "linuxcnc-comp", "--grid", "5")
    shares = {e["name"]: e for e in doc["errors"]}
    # Y leaning towards +X moves X by y.sin(SXY), y in [0, 200]: a function of Y, which no table
    # of X has; the best X trim is its mean over Y (100 sin SXY), which leaves +-100 sin SXY
    assert shares["SXY"]["represented"] == "partly"
    assert shares["SXY"]["before"]["max_um"] == pytest.approx(200 * np.sin(12 * ARCSEC) * 1e3, rel=1e-6)
    assert shares["SXY"]["after"]["max_um"] == pytest.approx(100 * np.sin(12 * ARCSEC) * 1e3, rel=1e-6)


def test_reversal_splits_forward_and_reverse(capsys, tmp_path):
    _, out = export(capsys, tmp_path, POSITIONING, "linuxcnc-comp", "--grid", "3", "--entries", "5",
                    "--no-breakdown", "--reversal", "X=4um")
    t = linuxcnc_comp.read((out / "joint0_X.comp").read_text(), 1)
    assert np.allclose(t[:, 2] - t[:, 1], 0.004, atol=1e-9)     # reverse - forward = B
    assert np.allclose(t[:, 1] + 0.002, -exx(t[:, 0]), atol=2e-7)  # forward = -(error + B/2)


def matrixkins(text: str) -> np.ndarray:
    """C from the HAL lines (matrixkins.comp: parameters C_xx .. C_zz, joint = C . axis)."""
    c = np.full((3, 3), np.nan)
    for i, k, v in re.findall(r"^setp matrixkins\.C_([xyz])([xyz]) (\S+)$", text, re.M):
        c["xyz".index(i), "xyz".index(k)] = float(v)
    assert not np.isnan(c).any()
    return c


SQ = dict(sxy=12 * ARCSEC, sxz=-8 * ARCSEC, syz=5 * ARCSEC)


def test_matrixkins_cancels_squareness(capsys, tmp_path):
    doc, out = export(capsys, tmp_path, SQUARENESS, "linuxcnc-matrixkins", "--grid", "5")
    c = matrixkins(out.read_text())
    x, y, z = random_points()
    q = c @ np.array([x, y, z])
    err = own_model(*q, **SQ) - np.array([x, y, z])
    assert np.linalg.norm(own_model(x, y, z, **SQ) - np.array([x, y, z]), axis=0).max() * 1e3 > 10
    assert np.linalg.norm(err, axis=0).max() * 1e3 < 1e-3
    assert doc["after_offset"]["max_um"] < 1e-3
    assert all(e["represented"] == "yes" for e in doc["errors"])


@pytest.mark.parametrize("fmt", ["marlin", "klipper", "rrf"])
def test_printer_skew_cancels_squareness(capsys, tmp_path, fmt):
    doc, out = export(capsys, tmp_path, SQUARENESS, fmt, "--grid", "5", "--no-breakdown")
    line = out.read_text().strip()
    parse = {"marlin": firmware_skew.parse_marlin, "klipper": firmware_skew.parse_klipper,
             "rrf": firmware_skew.parse_rrf}[fmt]
    apply = {"marlin": firmware_skew.apply_marlin, "klipper": firmware_skew.apply_klipper,
             "rrf": firmware_skew.apply_rrf}[fmt]
    factors = parse(line)
    x, y, z = random_points()
    motor = apply(factors, np.array([x, y, z]))
    err = np.linalg.norm(own_model(*motor, **SQ) - np.array([x, y, z]), axis=0) * 1e3
    # what is left is second order in the tilts (RRF has no xy.yz cross term) and Y's cos
    assert err.max() < 0.01
    assert doc["after_offset"]["max_um"] < 0.01


def test_printer_skew_cannot_scale_and_says_so(tmp_path):
    machine = write_file(tmp_path, "own_xyz.yaml", OWN)
    params = write_file(tmp_path, "own.yaml", POSITIONING)
    nothing_written(tmp_path, "export", machine, "--params", params, "--format", "marlin", "-o", tmp_path / "m.g",
                    match="--format marlin represents none of the errors given for own_xyz")


# ----------------------------------------------------------------------------- bundled machines

@pytest.mark.parametrize("name", ["vmc_xyz", "five_axis_ac"])
def test_bundled_positioning_in_tables_squareness_in_the_matrix(capsys, tmp_path, name):
    machine, params = machine_path(name), os.path.join(PARAMS, f"{name}-demo.yaml")
    reports = {}
    for fmt, out in (("linuxcnc-comp", tmp_path / "comp"), ("linuxcnc-matrixkins", tmp_path / "m.hal")):
        code, stdout, err = run_main(capsys, "export", machine, "--params", params, "--format", fmt, "-o", out,
                                     "--grid", "5", "--report", "json")
        assert code == 0, err
        reports[fmt] = {e["name"]: e for e in json.loads(stdout)["errors"]}
    for e in ("EXX", "EYY", "EZZ"):
        assert reports["linuxcnc-comp"][e]["represented"] == "yes"
        assert reports["linuxcnc-comp"][e]["after"]["max_um"] <= 1.0
    for e in ("EC0Y", "EB0Z", "EA0Z"):
        assert reports["linuxcnc-comp"][e]["represented"] != "yes"
        assert reports["linuxcnc-matrixkins"][e]["represented"] == "yes"
        assert reports["linuxcnc-matrixkins"][e]["after"]["max_um"] <= 1.0


# ----------------------------------------------------------------------------- bad input

def nothing_written(tmp_path, *argv, match):
    before = sorted(os.listdir(tmp_path))
    refused_one_line(*map(str, argv), match=match)
    assert sorted(os.listdir(tmp_path)) == before


def test_refusals_write_nothing(tmp_path):
    vmc, params = machine_path("vmc_xyz"), os.path.join(PARAMS, "vmc_xyz-demo.yaml")
    me220 = machine_path("me220_xz")
    fa = machine_path("five_axis_ac")
    out = tmp_path / "out"
    nothing_written(tmp_path, "export", vmc, "--params", params, "--format", "siemens", "-o", out,
                    match="invalid choice: 'siemens'")
    nothing_written(tmp_path, "export", me220, "--set", "dx1=1um", "--format", "linuxcnc-matrixkins", "-o", out,
                    match="needs three linear axes")
    nothing_written(tmp_path, "export", vmc, "--params", params, "--format", "linuxcnc-comp", "-o", out,
                    "--entries", "257", match="must be between 2 and 256")
    nothing_written(tmp_path, "export", fa, "--params", os.path.join(PARAMS, "five_axis_ac-demo.yaml"),
                    "--format", "linuxcnc-comp", "-o", out, "--grid", "60", match="the check grid would hold")
    nothing_written(tmp_path, "export", vmc, "--format", "marlin", "-o", out, match="nothing to compensate")
    nothing_written(tmp_path, "export", vmc, "--set", "EXX=3um", "--format", "marlin", "-o", out,
                    match="--format marlin represents none of the errors given for vmc_xyz")
    nothing_written(tmp_path, "export", vmc, "--params", params, "--format", "linuxcnc-comp", "-o", out,
                    "--reversal", "Q=1um", match="--reversal Q: not an axis")
    nothing_written(tmp_path, "export", vmc, "--params", params, "--format", "marlin", "-o", out,
                    "--reversal", "X=1um", match="only linuxcnc-comp")
    nothing_written(tmp_path, "export", vmc, "--params", params, "--format", "linuxcnc-comp", "-o", out,
                    "--joints", "X,Y", match="--joints expects every axis")
    (tmp_path / "file").write_text("x")
    nothing_written(tmp_path, "export", vmc, "--params", params, "--format", "linuxcnc-comp", "-o",
                    tmp_path / "file", match="is a file")


def test_a_rejecting_table_must_cover_the_axis_and_is_held_past_its_ends(capsys, tmp_path):
    """The trims drive X a few um past a table's ends at the limits: there it is held (the
    machine's error there is the end's), not NaN; a table short of the limits is refused."""
    table = """\
machine: own_xyz
values:
  EXX:
    axis: X
    units: [mm, um]
    interpolation: linear
    outside: reject
    table:
      - [{first}, 5]
      - [150, -3]
      - [300, 8]
"""
    doc, out = export(capsys, tmp_path, table.format(first=0), "linuxcnc-comp", "--entries", "33", "--grid", "5")
    t = linuxcnc_comp.read((out / "joint0_X.comp").read_text(), 1)

    def truth(x):   # the table, read by hand: linear between its rows, held past its ends
        return np.interp(x, [0, 150, 300], [5e-3, -3e-3, 8e-3])
    x = np.linspace(0, 300, 1001)
    assert np.abs(x + linuxcnc_comp.trim(t, x) + truth(x + linuxcnc_comp.trim(t, x)) - x).max() < 1e-5
    assert doc["after"]["max_um"] < 0.01
    machine = write_file(tmp_path, "own_xyz.yaml", OWN)
    params = write_file(tmp_path, "short.yaml", table.format(first=1))
    nothing_written(tmp_path, "export", machine, "--params", params, "--format", "linuxcnc-comp",
                    "-o", tmp_path / "c", match="short.yaml:3: values.EXX: X = 0 mm lies outside the table")
