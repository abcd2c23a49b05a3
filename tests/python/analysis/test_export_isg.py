"""chaincomp export --controller isg-volcomp (ISG's and Beckhoff TwinCAT CNC's volumetric
compensation) against truth from outside the exporter: a machine the test writes into a
temp dir with its tool point written out by hand (own_model), the CSV read back by the
test's own reader written from ISG's manual (isg_csv.py), the controller's correction
replayed with what that reader holds, and the interpolation error of a parabola between
records worked out by hand (c h^2 / 4 at the midpoint)."""

import json

import numpy as np
import pytest

import isg_csv
from helpers import PARAMS, machine_path, refused_one_line, run_main, write_file

ARCSEC = np.pi / 648000

OWN = """\
name: own_iso
description: a gantry of the test's own, three slides with ISO-named errors and one that is not
length_unit: mm
rotation_sense: right_hand
symbols:
  - {name: X, role: axis, unit: mm, limits: [0, 300], meaning: X}
  - {name: Y, role: axis, unit: mm, limits: [0, 200], meaning: Y}
  - {name: Z, role: axis, unit: mm, limits: [-100, 0], meaning: Z}
  - {name: EXX, role: error, unit: um, meaning: X positioning}
  - {name: EYY, role: error, unit: um, meaning: Y positioning}
  - {name: EZZ, role: error, unit: um, meaning: Z positioning}
  - {name: EC0Y, role: error, unit: arcsec, meaning: Y leaning towards -X}
  - {name: SXZ, role: error, unit: arcsec, meaning: Z leaning towards +X (no ISO name)}
chain:
  - {translate: [X + EXX, 0, 0]}
  - {translate: [-Y*sin(EC0Y), Y*cos(EC0Y) + EYY, 0]}
  - {translate: [Z*sin(SXZ), 0, Z + EZZ]}
tool:
  point: [0, 0, 0]
"""

C2 = 4e-4   # um/mm^2: EXX = C2 X^2, 36 um at X = 300
PARAMS_TEXT = f"""\
machine: own_iso
values:
  EXX: {{axis: X, units: [mm, um], polynomial: [0.0, 0.0, {C2}]}}
  EYY:
    axis: Y
    units: [mm, um]
    interpolation: linear
    outside: hold
    table: [[0, 0.0], [37, 1.5], [80, -2.0], [200, 3.0]]
  EZZ: 3 um
  EC0Y: 6 arcsec
"""


def own_model(x, y, z, exx, eyy, ezz, ec0y, sxz=0.0):
    """The tool point of OWN (mm), written out by hand; exx, eyy: functions (mm -> mm)."""
    return np.array([x + exx(x) - y * np.sin(ec0y) + z * np.sin(sxz), y * np.cos(ec0y) + eyy(y) + 0 * x,
                     z + ezz + 0 * x])


def export(capsys, tmp_path, params_text=PARAMS_TEXT, *extra):
    machine = write_file(tmp_path, "own_iso.yaml", OWN)
    params = write_file(tmp_path, "own.yaml", params_text)
    out = tmp_path / "isg"
    code, stdout, err = run_main(capsys, "export", machine, "--params", params, "--controller", "isg-volcomp",
                                 "-o", out, "--format", "json", *extra)
    assert code == 0, err
    return json.loads(stdout), out


def test_the_file_carries_each_error_under_its_iso_name_in_mm_and_rad(capsys, tmp_path):
    doc, out = export(capsys, tmp_path, PARAMS_TEXT, "--entries", "5")
    blocks = isg_csv.read((out / "volcomp.csv").read_text())
    x = np.linspace(0, 300, 5)
    ex = next(b for b in blocks if b.arguments == ["X"])
    assert ex.grid[0] == pytest.approx(x)                       # 5 records over X's limits, in mm
    assert ex.values["EXX"] == pytest.approx(C2 * x * x * 1e-3, abs=1e-9)   # mm
    ey = next(b for b in blocks if b.arguments == ["Y"])
    assert {0, 37, 80, 200} <= set(ey.grid[0])                  # a linear table's knots are records
    assert isg_csv.value(blocks, "EYY", Y=37) == pytest.approx(1.5e-3, abs=1e-9)
    assert isg_csv.value(blocks, "C0Y") == pytest.approx(6 * ARCSEC, abs=1e-12)   # EC0Y, in rad
    assert isg_csv.value(blocks, "EZZ") == pytest.approx(3e-3, abs=1e-12)
    assert doc["isg"]["chain"] == "XYZ" and doc["isg"]["workpiece_axes"] == 0
    lis = (out / "volcomp.lis").read_text()
    assert "file_format[0] ISG_CSV" in lis and "interpolation GRID" in lis and "\nX 1\nY 2\nZ 3\n" in lis


def test_the_residual_is_the_controllers_replay_and_a_parabolas_chord(capsys, tmp_path):
    """The report's residual equals the test's own replay (the reader's values, the
    correction taken off X, Y, Z, the hand-written model), and for EXX = c X^2 on 5
    records it is the chord's error at a midpoint, c h^2 / 4 with h = 75 mm."""
    doc, out = export(capsys, tmp_path, PARAMS_TEXT, "--entries", "5", "--grid", "5")
    blocks = isg_csv.read((out / "volcomp.csv").read_text())
    true = dict(exx=lambda x: C2 * x * x * 1e-3, eyy=lambda y: np.interp(y, [0, 37, 80, 200], [0, 1.5e-3, -2e-3, 3e-3]),
                ezz=3e-3, ec0y=6 * ARCSEC)
    held = dict(exx=lambda x: isg_csv.value(blocks, "EXX", X=x), eyy=lambda y: isg_csv.value(blocks, "EYY", Y=y),
                ezz=isg_csv.value(blocks, "EZZ"), ec0y=isg_csv.value(blocks, "C0Y"))
    # the check points the report promises: 5 per axis, and between every two records of each
    # table with the other axes at their limits and middle
    g = [np.linspace(0, 300, 5), np.linspace(0, 200, 5), np.linspace(-100, 0, 5)]
    g3 = [np.linspace(0, 300, 3), np.linspace(0, 200, 3), np.linspace(-100, 0, 3)]
    recs = {"X": next(b for b in blocks if b.arguments == ["X"]).grid[0],
            "Y": next(b for b in blocks if b.arguments == ["Y"]).grid[0]}
    sets = [g, [(recs["X"][1:] + recs["X"][:-1]) / 2, g3[1], g3[2]], [g3[0], (recs["Y"][1:] + recs["Y"][:-1]) / 2, g3[2]]]
    worst = []
    for s in sets:
        x, y, z = (v.ravel() for v in np.meshgrid(*s, indexing="ij"))
        nominal = np.array([x, y, z])
        d = own_model(x, y, z, **held) - nominal
        driven = nominal - d          # the nominal model's derivative is the identity here
        worst.append(np.linalg.norm(own_model(*driven, **true) - nominal, axis=0))
    worst = np.concatenate(worst)
    assert doc["after"]["max_um"] == pytest.approx(worst.max() * 1e3, abs=1e-5)
    assert doc["check_points"] == len(worst)
    chord = C2 * 75.0 ** 2 / 4        # um
    assert doc["after"]["max_um"] == pytest.approx(chord, rel=0.02)
    assert doc["isg"]["represented_only"]["max_um"] <= 1.0
    assert doc["before"]["max_um"] > 30.0


def test_bundled_laser_tables_their_knots_are_records_and_leave_under_a_micrometre(capsys, tmp_path):
    """five_axis_ac-laser.yaml: 18 component errors as monotone cubic tables of 101 knots."""
    code, stdout, err = run_main(capsys, "export", machine_path("five_axis_ac"), "--params",
                                 f"{PARAMS}/five_axis_ac-laser.yaml", "--controller", "isg-volcomp", "-o",
                                 tmp_path / "isg", "--grid", "3", "--no-breakdown", "--format", "json")
    assert code == 0, err
    doc = json.loads(stdout)
    blocks = isg_csv.read((tmp_path / "isg" / "volcomp.csv").read_text())
    ex = next(b for b in blocks if b.arguments == ["X"])
    assert set(np.round(np.linspace(-400, 400, 101), 6)) <= set(ex.grid[0])
    assert doc["isg"]["represented_only"]["max_um"] <= 1.0


def test_more_records_leave_less(capsys, tmp_path):
    coarse, _ = export(capsys, tmp_path, PARAMS_TEXT, "--entries", "5", "--no-breakdown")
    fine, _ = export(capsys, tmp_path, PARAMS_TEXT, "--entries", "33", "--no-breakdown")
    # the chord's error, and the one correction step's remainder EXX'(X) d at X = 300 (um/mm x mm)
    chord, step = C2 * (300 / 32) ** 2 / 4, 2 * C2 * 300 * (C2 * 300 ** 2 * 1e-3)
    assert chord < fine["after"]["max_um"] <= (chord + step) * 1.01
    assert fine["after"]["max_um"] < coarse["after"]["max_um"] / 20


def test_an_error_without_an_iso_name_is_left_out_and_its_share_reported(capsys, tmp_path):
    doc, _ = export(capsys, tmp_path, PARAMS_TEXT + "  SXZ: 10 arcsec\n", "--grid", "3")
    assert "SXZ" in doc["isg"]["left_out"] and "SXZ" not in doc["isg"]["names"]
    share = next(e for e in doc["errors"] if e["name"] == "SXZ")
    assert share["represented"] == "no" and share["after"]["max_um"] == share["before"]["max_um"]
    assert share["before"]["max_um"] == pytest.approx(100 * np.sin(10 * ARCSEC) * 1e3, rel=1e-6)  # Z = -100
    assert doc["after"]["max_um"] >= share["before"]["max_um"] * 0.99
    assert doc["isg"]["represented_only"]["max_um"] <= 1.0


@pytest.mark.parametrize("name", ["vmc_xyz", "five_axis_ac"])
def test_bundled_every_iso_error_is_carried_and_leaves_under_a_micrometre(capsys, tmp_path, name):
    code, stdout, err = run_main(capsys, "export", machine_path(name), "--params", f"{PARAMS}/{name}-demo.yaml",
                                 "--controller", "isg-volcomp", "-o", tmp_path / "isg", "--grid", "5", "--format", "json")
    assert code == 0, err
    doc = json.loads(stdout)
    iso = [e for e in doc["errors"] if isg_csv.COMPONENT.match(e["name"]) or isg_csv.POSITION.match(e["name"][1:])]
    assert len(iso) == 21
    for e in iso:
        assert e["represented"] == "yes" and e["after"]["max_um"] <= 1.0, e
    assert doc["isg"]["represented_only"]["max_um"] <= 1.0
    if name == "vmc_xyz":
        # the table carries X on Y (walking from the workpiece: X, Y, then the column's Z);
        # workpiece_axes stays ISG's default 0: the errors are the tool's relative to the workpiece
        assert doc["isg"]["chain"] == "XYZ" and doc["isg"]["workpiece_side"] == 2
        assert doc["isg"]["workpiece_axes"] == 0
        assert doc["after"]["max_um"] <= 1.0 < doc["before"]["max_um"]
    else:   # the head's errors have no ISO 230-1 names: left out, and the residual says so
        assert doc["isg"]["axes"] == {"X": "X", "Y": "Y", "Z": "Z", "A": "Ap", "C": "Cp"}
        assert doc["isg"]["chain"] == "XYZCA" and doc["isg"]["workpiece_side"] == 0   # slides carry C, C carries A
        # the head's A is inclined (50 deg from C): named in a note, as no error of it is written
        assert any("Ap turns about (+0.000, +0.766, +0.643)" in n for n in doc["isg"]["notes"])
        assert set(doc["isg"]["left_out"]) == {"ThetaAs", "Oas", "ThetaAv", "DY", "Ocx", "Ocy", "ThetaCh", "ThetaCv"}
        assert doc["after"]["max_um"] > 10


def nothing_written(tmp_path, *argv, match):
    before = sorted(p.name for p in tmp_path.iterdir())
    refused_one_line(*map(str, argv), match=match)
    assert sorted(p.name for p in tmp_path.iterdir()) == before


def test_refusals_write_nothing(tmp_path):
    machine = write_file(tmp_path, "own_iso.yaml", OWN)
    params = write_file(tmp_path, "own.yaml", PARAMS_TEXT)
    out = tmp_path / "isg"
    base = ("export", machine, "--params", params, "--controller", "isg-volcomp", "-o", out)
    nothing_written(tmp_path, *base, "--iso-axes", "X=Y,Y=X,Z=Q", match="--iso-axes Z=Q: not an axis of own_iso")
    nothing_written(tmp_path, *base, "--iso-axes", "X=X,Y=Y,W=Z", match="--iso-axes W=Z: W is not an ISO axis letter")
    nothing_written(tmp_path, *base, "--iso-axes", "X=X,Y=Y,A=Z", match="A is a rotary axis in ISO 230-1, but Z")
    nothing_written(tmp_path, *base, "--iso-axes", "X=X,Y=Y", match="needs three linear axes X, Y, Z")
    nothing_written(tmp_path, *base, "--iso-axes", "X=X,X=Y", match="--iso-axes: X given twice")
    nothing_written(tmp_path, "export", machine, "--params", params, "--controller", "marlin", "-o", tmp_path / "m.g",
                    "--iso-axes", "X=X,Y=Y,Z=Z", match="--iso-axes: only isg-volcomp")
    only_sxz = write_file(tmp_path, "sxz.yaml", "machine: own_iso\nvalues:\n  SXZ: 10 arcsec\n")
    nothing_written(tmp_path, "export", machine, "--params", only_sxz, "--controller", "isg-volcomp", "-o", out,
                    match="isg-volcomp represents none of the errors given for own_iso")
    (tmp_path / "afile").write_text("x")
    nothing_written(tmp_path, "export", machine, "--params", params, "--controller", "isg-volcomp", "-o",
                    tmp_path / "afile", match="isg-volcomp writes a folder of files")
    lathe = machine_path("me220_xz")
    nothing_written(tmp_path, "export", lathe, "--params", f"{PARAMS}/me220_xz-example.yaml", "--controller",
                    "isg-volcomp", "-o", out, match="needs three linear axes X, Y, Z")


# ----------------------------------------------------------------------------- found by a bad-input hunt

def test_rotary_arguments_are_degrees_and_linear_ones_mm_whatever_the_declared_unit(capsys, tmp_path):
    """296426379: arguments in mm (X, Y, Z) and degrees (A, B, C). A C axis in deg and an X
    axis declared in inches: the records span the limits in deg and in mm, and the values
    sit where the arguments say."""
    params = write_file(tmp_path, "tr.yaml", "machine: trunnion_ac\nvalues:\n  EC0C: 5 arcsec\n"
                        "  EX0C: {axis: C, units: [deg, um], polynomial: [0, 0.05]}\n")
    code, _, err = run_main(capsys, "export", machine_path("trunnion_ac"), "--params", params, "--controller",
                            "isg-volcomp", "-o", tmp_path / "tr", "--entries", "5", "--grid", "3", "--no-breakdown")
    assert code == 0, err
    c = next(b for b in isg_csv.read((tmp_path / "tr" / "volcomp.csv").read_text()) if b.arguments == ["C"])
    assert c.grid[0] == pytest.approx([-360.0, -180.0, 0.0, 180.0, 360.0])    # trunnion_ac's C limits, deg
    assert c.at("X0C", C=90.0) == pytest.approx(0.05 * 90 * 1e-3, abs=1e-9)
    inches = OWN.replace("{name: X, role: axis, unit: mm, limits: [0, 300]", "{name: X, role: axis, unit: in, "
                         "limits: [0, 10]").replace("[X + EXX, 0, 0]", "[X*25.4 + EXX, 0, 0]")
    machine = write_file(tmp_path, "own_in.yaml", inches)
    params = write_file(tmp_path, "in.yaml", "machine: own_iso\nvalues:\n  EXX: {axis: X, units: [in, um], "
                        "polynomial: [0, 1]}\n")
    code, _, err = run_main(capsys, "export", machine, "--params", params, "--controller", "isg-volcomp", "-o",
                            tmp_path / "in", "--entries", "3", "--grid", "3", "--no-breakdown")
    assert code == 0, err
    x = next(b for b in isg_csv.read((tmp_path / "in" / "volcomp.csv").read_text()) if b.arguments == ["X"])
    assert x.grid[0] == pytest.approx([0.0, 127.0, 254.0])            # mm
    assert x.at("EXX", X=254.0) == pytest.approx(10 * 1e-3, abs=1e-9)  # 1 um per inch, 10 in


def test_an_error_it_cannot_carry_is_never_called_represented(capsys, tmp_path):
    ppm = OWN.replace("{name: EXX, role: error, unit: um", "{name: EXX, role: error, unit: ppm").replace(
        "[X + EXX, 0, 0]", "[X + EXX*X, 0, 0]")
    machine = write_file(tmp_path, "own_ppm.yaml", ppm)
    params = write_file(tmp_path, "ppm.yaml", "machine: own_iso\nvalues:\n  EXX: 0.2 ppm\n  EYY: 3 um\n")
    code, stdout, err = run_main(capsys, "export", machine, "--params", params, "--controller", "isg-volcomp", "-o",
                                 tmp_path / "isg", "--grid", "3", "--format", "json")
    assert code == 0, err
    doc = json.loads(stdout)
    assert "EXX" in doc["isg"]["left_out"]
    assert next(e for e in doc["errors"] if e["name"] == "EXX")["represented"] == "no"   # 0.06 um, under the floor


def test_more_refusals_write_nothing(tmp_path):
    machine = write_file(tmp_path, "own_iso.yaml", OWN)
    out = tmp_path / "isg"

    def refused(params_text, *extra, match, machine=machine):
        params = write_file(tmp_path, "p.yaml", params_text)
        nothing_written(tmp_path, "export", machine, "--params", params, "--controller", "isg-volcomp", "-o", out,
                        *extra, match=match)

    refused("machine: own_iso\nvalues:\n  EXX: {axis: X, units: [mm, um], interpolation: linear, outside: hold, "
            "table: [[0, 0], [100.0000001, 0], [100.0000002, 5], [100.0000003, 0], [300, 0]]}\n",
            match="EXX: knots of its table closer than 1e-6 mm")
    refused("machine: own_iso\nvalues:\n  EXX: {axis: X, units: [mm, um], polynomial: [0, 0, 1.0e+12]}\n",
            match="an ISG CSV file carries errors below 1000")
    refused("machine: own_iso\nvalues:\n  EXX: 3 um\n", "--iso-axes", "X=Y,Y=X,Z=Z",
            match="X must move the tool along +x")
    refused("machine: own_iso\nvalues:\n  EXX: 3 um\n", "--iso-axes", "", match="--iso-axes: empty")
    tiny = OWN.replace("limits: [0, 300]", "limits: [0, 0.0000001]")
    refused("machine: own_iso\nvalues:\n  EXX: {axis: X, units: [mm, um], polynomial: [1, 0.001]}\n",
            machine=write_file(tmp_path, "tiny.yaml", tiny), match="are too close for 33 records")
    both = OWN.replace("name: own_iso", "name: own_both").replace("chain:\n", "loop:\n  tool:\n").replace(
        "  - {translate: [X + EXX, 0, 0]}\n  - {translate: [-Y*sin(EC0Y), Y*cos(EC0Y) + EYY, 0]}\n"
        "  - {translate: [Z*sin(SXZ), 0, Z + EZZ]}\n",
        "    - {translate: [X + EXX, 0, 0]}\n    - {translate: [-Y*sin(EC0Y), Y*cos(EC0Y) + EYY, 0]}\n"
        "    - {translate: [Z*sin(SXZ), 0, Z + EZZ]}\n  workpiece:\n    - {translate: [0, 0, X/1000]}\n")
    refused("machine: own_both\nvalues:\n  EXX: 3 um\n", machine=write_file(tmp_path, "both.yaml", both),
            match="moves both the tool and the workpiece side")


def test_trunnion_chain_letters_and_directions(capsys, tmp_path):
    """trunnion_ac: C on A on the table, X Y Z the tool's: chain CAXYZ, two axes on the
    workpiece side; --workpiece-axes is written as given; swapped rotary letters, a linear
    axis moving along -x and a --workpiece-axes past the chain are refused."""
    params = f"{PARAMS}/trunnion_ac-demo.yaml"
    code, stdout, err = run_main(capsys, "export", machine_path("trunnion_ac"), "--params", params, "--controller",
                                 "isg-volcomp", "-o", tmp_path / "t", "--grid", "3", "--no-breakdown",
                                 "--workpiece-axes", "2", "--format", "json")
    assert code == 0, err
    doc = json.loads(stdout)
    assert doc["isg"]["chain"] == "CAXYZ" and doc["isg"]["workpiece_side"] == 2 and doc["isg"]["workpiece_axes"] == 2
    assert "\nworkpiece_axes 2\n" in (tmp_path / "t" / "volcomp.lis").read_text()
    base = ("export", machine_path("trunnion_ac"), "--params", params, "--controller", "isg-volcomp", "-o", tmp_path / "u")
    nothing_written(tmp_path, *base, "--iso-axes", "X=X,Y=Y,Z=Z,A=C,C=A",
                    match="A must turn about x (ISO 841), but C of trunnion_ac turns about (+0.000, +0.000, +1.000)")
    nothing_written(tmp_path, *base, "--workpiece-axes", "5", match="--workpiece-axes 5: expected 0 to 4")
    minus = OWN.replace("[X + EXX, 0, 0]", "[-X - EXX, 0, 0]")
    machine = write_file(tmp_path, "minus.yaml", minus)
    p = write_file(tmp_path, "m.yaml", "machine: own_iso\nvalues:\n  EXX: 3 um\n")
    nothing_written(tmp_path, "export", machine, "--params", p, "--controller", "isg-volcomp", "-o", tmp_path / "v",
                    match="X must move the tool along +x relative to the workpiece (ISO 841), but X of own_iso "
                          "moves it along (-1.000, +0.000, +0.000)")


def test_the_readers_grid_on_the_manuals_two_argument_example():
    """The test's reader on 296429067's own example of a block over Z and X (sag): GRID is
    linear in each argument, so halfway in both is the mean of the four records."""
    text = """// The argument "Z" now crops up in the header.
Z X EXX EYX EZX EAX EBX ECX
// In the first block Z is always = 0.
0.0 0.0 0.02 0.01 0.07 0.00 0.0042 0.003
0.0 10.0 0.00 -0.1 0.01 0.00 0.0011 0.002
// In the second block Z is always = 100.
100.0 0.0 0.01 0.02 0.03 0.07 0.0040 0.003
100.0 10.0 0.03 -0.09 0.03 0.06 0.0015 0.000
"""
    (b,) = isg_csv.read(text)
    assert b.arguments == ["Z", "X"]
    assert b.at("EXX", Z=50.0, X=5.0) == pytest.approx((0.02 + 0.00 + 0.01 + 0.03) / 4)
    assert b.at("EYX", Z=100.0, X=10.0) == pytest.approx(-0.09)
    assert b.at("EZX", Z=0.0, X=2.5) == pytest.approx(0.07 + 0.25 * (0.01 - 0.07))


NUTATING = """\
name: nutating
description: X, Y, Z slides and a B table turning about an axis n from z in the yz plane (a nutating table)
length_unit: mm
rotation_sense: right_hand
symbols:
  - {{name: X, role: axis, unit: mm, limits: [0, 300], meaning: X}}
  - {{name: Y, role: axis, unit: mm, limits: [0, 200], meaning: Y}}
  - {{name: Z, role: axis, unit: mm, limits: [-100, 0], meaning: Z}}
  - {{name: B, role: axis, unit: deg, limits: [-90, 90], meaning: the inclined table}}
  - {{name: n, role: constant, unit: deg, nominal: {n}, meaning: the table axis' angle from {frm}}}
  - {{name: EXX, role: error, unit: um, meaning: X positioning}}
  - {{name: EX0B, role: error, unit: um, meaning: B's line in x}}
  - {{name: EB0B, role: error, unit: arcsec, meaning: B's zero}}
chain:
  - {{rotate: x, angle: {tilt}}}
  - {{translate: [EX0B, 0, 0]}}
  - {{rotate: {about}, angle: -(B + EB0B)}}
  - {{translate: [-EX0B, 0, 0]}}
  - {{rotate: x, angle: -({tilt})}}
  - {{translate: [X + EXX, Y, Z]}}
tool:
  point: [0, 0, 0]
  direction: [0, 0, 1]
"""


@pytest.mark.parametrize("n", [0, 44, 45, 46, 90])
def test_one_rule_for_a_rotary_axis_at_any_inclination(capsys, tmp_path, n):
    """B's errors go into the file only where B turns about y (ISO 841's B): at 0 degrees from y
    they are carried; inclined at 44, 45 or 46 degrees (a nutating table) they are left out, each
    with the angle and why, and a note; about z (90 degrees) the letter is wrong: refused, naming
    --iso-axes. (Before: 45 degrees was written as a B about y, 44 refused.)"""
    text = NUTATING.format(n=n, frm="y", tilt="n - pi/2", about="z")   # the axis z turned by n - 90 deg about x
    machine = write_file(tmp_path, "nutating.yaml", text)
    params = write_file(tmp_path, "p.yaml", "machine: nutating\nvalues:\n  EXX: 3 um\n  EX0B: 5 um\n"
                                            "  EB0B: 8 arcsec\n")
    argv = ("export", machine, "--params", params, "--controller", "isg-volcomp", "-o", tmp_path / "isg", "--grid", "3",
            "--no-breakdown", "--format", "json")
    code, stdout, err = run_main(capsys, *argv)
    if n == 90:
        assert code == 2 and "must turn about y" in err and "--iso-axes" in err
        return
    assert code == 0, err
    doc = json.loads(stdout)["isg"]
    assert doc["names"]["EXX"] == "EXX"
    if n == 0:
        assert doc["names"]["EX0B"] == "X0B" and "EX0B" not in doc["left_out"]
    else:
        for e in ("EX0B", "EB0B"):
            why = doc["left_out"][e]
            assert e not in doc["names"] and f"{n:.3f} degrees from y" in why and "ISO 230-1" in why
