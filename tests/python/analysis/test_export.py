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
from chaincomp.analysis import export as X
from chaincomp.errors import ChaincompError
from chaincomp.model.machine import load_machine
from helpers import cli, machine_path, refused_one_line, run_main, write_file, PARAMS

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


def check_points(limits, grid, entries):
    """The points the exporter's report promises for tables (docs/guide/export.md): a grid
    of ``grid`` per axis, and along each joint the midpoints between its ``entries``."""
    axes = [np.linspace(lo, hi, grid) for lo, hi in limits]
    sets = [np.meshgrid(*axes, indexing="ij")]
    for j, (lo, hi) in enumerate(limits):
        nominal = np.linspace(lo, hi, entries)
        sets.append(np.meshgrid(*[(nominal[1:] + nominal[:-1]) / 2 if k == j else v for k, v in enumerate(axes)],
                                indexing="ij"))
    return [np.concatenate([s[k].ravel() for s in sets]) for k in range(len(limits))]


def export(capsys, tmp_path, params_text, fmt, *extra):
    machine = write_file(tmp_path, "own_xyz.yaml", OWN)
    params = write_file(tmp_path, "own.yaml", params_text)
    out = tmp_path / ("comp" if fmt == "linuxcnc-comp" else "out.txt")
    code, stdout, err = run_main(capsys, "export", machine, "--params", params, "--controller", fmt, "-o", out,
                                 "--format", "json", *extra)
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
    # the report's residual is the replay's on its check points: 7 per axis, and along each
    # joint the midpoints of its 17 entries (7 of the others' each)
    g = check_points([(0, 300), (0, 200), (-100, 0)], 7, 17)
    assert doc["check_points"] == len(g[0])
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
                    "--no-breakdown", "--mean-reversal", "X=4um")
    t = linuxcnc_comp.read((out / "joint0_X.comp").read_text(), 1)
    assert np.allclose(t[:, 2] - t[:, 1], 0.004, atol=1e-9)     # reverse - forward = B̄
    assert np.allclose(t[:, 1] + 0.002, -exx(t[:, 0]), atol=2e-7)  # forward = -(error + B̄/2)


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
    program = out.read_text()
    replay = {"marlin": firmware_skew.replay_marlin, "klipper": firmware_skew.parse_klipper,
              "rrf": firmware_skew.replay_rrf}[fmt]
    apply = {"marlin": firmware_skew.apply_marlin, "klipper": firmware_skew.apply_klipper,
             "rrf": firmware_skew.apply_rrf}[fmt]
    factors = replay(program)
    x, y, z = random_points()
    motor = apply(factors, np.array([x, y, z]))
    err = np.linalg.norm(own_model(*motor, **SQ) - np.array([x, y, z]), axis=0) * 1e3
    # what is left is second order in the tilts (RRF has no xy.yz cross term) and Y's cos
    assert err.max() < 0.01
    assert doc["after_offset"]["max_um"] < 0.01


def test_printer_skew_cannot_scale_and_says_so(tmp_path):
    machine = write_file(tmp_path, "own_xyz.yaml", OWN)
    params = write_file(tmp_path, "own.yaml", POSITIONING)
    nothing_written(tmp_path, "export", machine, "--params", params, "--controller", "marlin", "-o", tmp_path / "m.g",
                    match="--controller marlin represents none of the errors given for own_xyz")


# ----------------------------------------------------------------------------- bundled machines

@pytest.mark.parametrize("name", ["vmc_xyz", "five_axis_ac"])
def test_bundled_positioning_in_tables_squareness_in_the_matrix(capsys, tmp_path, name):
    machine, params = machine_path(name), os.path.join(PARAMS, f"{name}-demo.yaml")
    reports = {}
    for fmt, out in (("linuxcnc-comp", tmp_path / "comp"), ("linuxcnc-matrixkins", tmp_path / "m.hal")):
        code, stdout, err = run_main(capsys, "export", machine, "--params", params, "--controller", fmt, "-o", out,
                                     "--grid", "5", "--format", "json")
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
    nothing_written(tmp_path, "export", vmc, "--params", params, "--controller", "siemens", "-o", out,
                    match="invalid choice: 'siemens'")
    nothing_written(tmp_path, "export", me220, "--set", "dx1=1um", "--controller", "linuxcnc-matrixkins", "-o", out,
                    match="needs three linear axes")
    nothing_written(tmp_path, "export", vmc, "--params", params, "--controller", "linuxcnc-comp", "-o", out,
                    "--entries", "257", match="must be between 2 and 256")
    nothing_written(tmp_path, "export", fa, "--params", os.path.join(PARAMS, "five_axis_ac-demo.yaml"),
                    "--controller", "linuxcnc-comp", "-o", out, "--grid", "60", match="the check grid would hold")
    nothing_written(tmp_path, "export", vmc, "--controller", "marlin", "-o", out, match="nothing to compensate")
    nothing_written(tmp_path, "export", vmc, "--set", "EXX=3um", "--controller", "marlin", "-o", out,
                    match="--controller marlin represents none of the errors given for vmc_xyz")
    nothing_written(tmp_path, "export", vmc, "--params", params, "--controller", "linuxcnc-comp", "-o", out,
                    "--mean-reversal", "Q=1um", match="--mean-reversal Q: not an axis")
    nothing_written(tmp_path, "export", vmc, "--params", params, "--controller", "marlin", "-o", out,
                    "--mean-reversal", "X=1um", match="--mean-reversal: only linuxcnc-comp")
    nothing_written(tmp_path, "export", machine_path("trunnion_ac"), "--params",
                    os.path.join(PARAMS, "trunnion_ac-demo.yaml"), "--controller", "linuxcnc-comp", "-o", out,
                    "--grid", "3", "--entries", "9", match="leaves more tool error than no compensation for trunnion_ac")
    nothing_written(tmp_path, "export", vmc, "--params", params, "--controller", "linuxcnc-comp", "-o", out,
                    "--mean-reversal", "X=1um", "--mean-reversal", "X=2um", match="--mean-reversal: X given twice")
    nothing_written(tmp_path, "export", vmc, "--params", params, "--set", "X=100", "--controller", "linuxcnc-comp",
                    "-o", out, match="--set X=100: X is an axis")
    nothing_written(tmp_path, "export", vmc, "--params", params, "--controller", "linuxcnc-comp", "-o", "",
                    match="-o: an empty value")
    # bounded work: the breakdown fits every error alone on every point
    nothing_written(tmp_path, "export", machine_path("panda"), "--params", os.path.join(PARAMS, "panda-demo.yaml"),
                    "--controller", "linuxcnc-comp", "-o", out, "--grid", "6", match="the breakdown would fit each of")


def test_a_folder_in_the_way_or_an_input_inside_it_writes_nothing(tmp_path):
    """Every file linuxcnc-comp writes is checked before the work: a folder where a file
    goes, or the machine file itself among the files, loses nothing."""
    folder = tmp_path / "comp"
    folder.mkdir()
    (folder / "compensation.ini").mkdir()
    vmc, params = machine_path("vmc_xyz"), os.path.join(PARAMS, "vmc_xyz-demo.yaml")
    nothing_written(folder, "export", vmc, "--params", params, "--controller", "linuxcnc-comp", "-o", folder,
                    match="compensation.ini: is a folder")
    (folder / "compensation.ini").rmdir()
    machine = write_file(folder, "joint0_X.comp", OWN)   # a user's machine file, by an unlucky name
    pos = write_file(tmp_path, "pos.yaml", POSITIONING)
    nothing_written(folder, "export", machine, "--params", pos, "--controller", "linuxcnc-comp", "-o", folder,
                    match="is also an input")
    assert (folder / "joint0_X.comp").read_text() == OWN


def test_a_model_undefined_inside_the_limits_is_named(tmp_path):
    """sqrt(X) on X in [-10, 300]: NaN at negative X, which would read as a residual of nan (lint,
    as the machine loads, names the expression at X = -10 mm first)."""
    machine = write_file(tmp_path, "root.yaml", OWN.replace("name: own_xyz", "name: root_xyz").replace(
        "limits: [0, 300]", "limits: [-10, 300]").replace("translate: [X + EXX, 0, 0]", "translate: [X + EXX*sqrt(X), 0, 0]"))
    before = sorted(os.listdir(tmp_path))
    proc = cli("export", machine, "--set", "EXX=1um", "--controller", "linuxcnc-comp", "-o", tmp_path / "c", check=False)
    assert proc.returncode == 2 and "Traceback" not in proc.stderr, proc.stderr
    warning, error = proc.stderr.splitlines()
    assert "'X + EXX*sqrt(X)' is not real (or not finite) at X = -10 mm" in warning, warning
    assert "root_xyz: the tool point with the errors given is not finite at X = -10 mm" in error, error
    assert sorted(os.listdir(tmp_path)) == before


def test_a_table_the_file_cannot_carry_is_refused(tmp_path):
    """The writer's guard, on tables built here: at 1e10 mm a double's spacing is 1.9e-6 mm,
    so type 0's nominal - trim cannot carry a trim of 3.3 um to 0.1 nm (type 1 writes the
    trims themselves), and 33 entries over 300 mm at 1e17 mm fall on equal doubles."""
    axis = load_machine(str(write_file(tmp_path, "own_xyz.yaml", OWN))).symbol("X")
    far = np.linspace(1e10, 1e10 + 300, 33)
    table = X.JointTable(axis, far, np.full(33, 3.3e-3), np.full(33, 3.3e-3))
    with pytest.raises(ChaincompError, match="COMP_FILE_TYPE 0 loses up to"):
        X.linuxcnc_comp_text(table, 0)
    assert linuxcnc_comp.read(X.linuxcnc_comp_text(table, 1), 1)[:, 1] == pytest.approx(3.3e-3, rel=1e-7)
    further = np.linspace(1e17, 1e17 + 300, 33)
    with pytest.raises(ChaincompError, match="33 entries over .* cannot be told apart"):
        X.linuxcnc_comp_text(X.JointTable(axis, further, np.zeros(33), np.zeros(33)), 1)


def test_a_pitch_cycle_between_the_entries_is_reported_not_hidden(capsys, tmp_path):
    """A lead screw's cyclic error with its zeros on the entries (period 2 entry spacings of
    33 entries over 300 mm): the default grid (9 per axis) falls on entries only, where the
    trims are zero and exact; the tool error between them is the cycle's full amplitude,
    and the report must say so."""
    spacing = 300 / 32
    rows = "\n".join(f"      - [{float(x)!r}, {float(2.0 * np.sin(np.pi * x / spacing))!r}]" for x in np.linspace(0, 300, 257))
    params = f"""\
machine: own_xyz
values:
  EXX:
    axis: X
    units: [mm, um]
    interpolation: linear
    outside: hold
    table:
{rows}
  EYY: 2 um
"""
    doc, out = export(capsys, tmp_path, params, "linuxcnc-comp")
    t = linuxcnc_comp.read((out / "joint0_X.comp").read_text(), 1)
    x = np.linspace(0, 300, 30001)
    truth = np.interp(x, np.linspace(0, 300, 257), 2e-3 * np.sin(np.pi * np.linspace(0, 300, 257) / spacing))
    left = np.abs(linuxcnc_comp.trim(t, x) + truth)   # the trims are tiny: the error at x itself
    assert left.max() > 1.9e-3
    assert doc["after"]["max_um"] == pytest.approx(left.max() * 1e3, rel=0.02)
    assert doc["after"]["max_um"] > 1.9


def test_matrixkins_names_where_its_joints_after_z_go_and_wants_x_y_z_first(capsys, tmp_path):
    """matrixkins.comp: j[0..2] = C . (x, y, z); j[3], j[4], j[5] = a, b, c, whatever the
    machine's letters: five_axis_ac's Cp on joint 4 lands on B, and the file says so; linear
    axes that are not joints 0, 1, 2 are refused."""
    machine, params = machine_path("five_axis_ac"), os.path.join(PARAMS, "five_axis_ac-demo.yaml")
    out = tmp_path / "m.hal"
    code, stdout, err = run_main(capsys, "export", machine, "--params", params, "--controller", "linuxcnc-matrixkins",
                                 "-o", out, "--grid", "3", "--no-breakdown")
    assert code == 0, err
    note = [line for line in out.read_text().splitlines() if "passes the joints after X, Y, Z" in line]
    assert note and "joint 3 (Ap) <-> axis A, joint 4 (Cp) <-> axis B" in note[0]
    nothing_written(tmp_path, "export", machine, "--params", params, "--controller", "linuxcnc-matrixkins", "-o",
                    tmp_path / "n.hal", "--joints", "Ap,X,Y,Z,Cp", match="matrixkins drives joints 0, 1, 2 from X, Y, Z")
