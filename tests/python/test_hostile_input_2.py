"""The second hostile-input hunt: a new user's own machine files, URDFs and measurement files,
written by hand (not the bundled ones), run through every verb. Each test states the exit code
and the message the contract asks for (exit 2, one line naming file, line and field; never a
traceback; never a silent wrong value), or, for a warning, what it must say."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

from conftest import cli, run_cli

# A four-axis machine written the way a user would: X, Y, Z slides and a B table, one error block
# after each, a tool length L.
M4 = """\
name: m4
description: four axis
length_unit: mm
error_block_order: txyz
rotation_sense: right_hand
symbols:
  - {name: X, role: axis, unit: mm, limits: [-300, 300]}
  - {name: Y, role: axis, unit: mm, limits: [-200, 200]}
  - {name: Z, role: axis, unit: mm, limits: [-300, 0]}
  - {name: B, role: axis, unit: deg, limits: [-90, 90]}
  - {name: L, role: constant, unit: mm, nominal: 120}
  - {name: EXX, role: error, unit: um}
  - {name: EYY, role: error, unit: um}
  - {name: EZZ, role: error, unit: um}
  - {name: EAX, role: error, unit: arcsec}
  - {name: EBB, role: error, unit: arcsec}
  - {name: EXB, role: error, unit: um}
chain:
  - {translate: [X, 0, 0]}
  - {errors: {dx: EXX, ex: EAX}}
  - {translate: [0, Y, 0]}
  - {errors: {dy: EYY}}
  - {translate: [0, 0, Z]}
  - {errors: {dz: EZZ}}
  - {rotate: y, angle: B}
  - {errors: {dx: EXB, ey: EBB}}
  - {translate: [0, 0, -L]}
tool:
  point: [0, 0, 0]
  direction: [0, 0, 1]
"""

# A three-joint arm in standard DH with a Hayati beta.
DH = """\
name: dharm
length_unit: mm
symbols:
  - {name: q1, role: axis, unit: deg, limits: [-180, 180]}
  - {name: q2, role: axis, unit: deg, limits: [-180, 180]}
  - {name: q3, role: axis, unit: deg, limits: [-180, 180]}
chain:
  - {dh: {theta: q1, d: 300, a: 0, alpha: pi/2}, errors: auto}
  - {dh: {theta: q2, d: 0, a: 400, alpha: 0}, errors: auto}
  - {beta: 0, errors: auto}
  - {dh: {theta: q3, d: 0, a: 300, alpha: 0}, errors: {theta: auto, a: auto}}
tool:
  point: [50, 20, 0]
"""


def _line(text: str, part: str) -> int:
    """1-based line of the first line of ``text`` holding ``part``."""
    return next(i for i, t in enumerate(text.splitlines(), 1) if part in t)


def _write(tmp_path, name: str, text: str) -> str:
    path = tmp_path / name
    path.write_text(text, encoding="utf-8")
    return str(path)


def _edited(text: str, old: str, new: str) -> str:
    assert text.count(old) == 1, old
    return text.replace(old, new)


def _refused(*argv, match: str) -> str:
    proc = cli(*argv, check=False)
    assert proc.returncode == 2, (proc.returncode, proc.stderr)
    assert match in proc.stderr, proc.stderr
    assert "Traceback" not in proc.stderr and "internal error" not in proc.stderr
    assert proc.stderr.count("\n") == 1, proc.stderr   # one line
    return proc.stderr


# ----------------------------------------------------------------------------- units where they stand

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
    text = _edited(M4, old, new)
    path = _write(tmp_path, "m.yaml", text)
    at = _line(text, new.splitlines()[0].strip()) if field != "chain[8].translate[2]" else _line(text, "-L]")
    for verb in ("lint", "eval"):
        err = _refused(verb, path, match=f"m.yaml:{at}: {field}: {message}")
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
    path = _write(tmp_path, "arm.yaml", text)
    if field is None:
        assert cli("lint", path).returncode == 0
        return
    _refused("lint", path, match=f"arm.yaml:8: {field}: {message}")


def test_products_and_ratios_where_they_belong_still_load(tmp_path):
    """A lever arm times an angle is a length (L*EBB as dx); a squareness in um/m (ppm) is an angle
    to first order; a symbol inside a function is not checked (sin(B)^2 is a number). With
    EBB = 1 arcsec the block translates the tool by dx = L*EBB = 120 mm x 1 arcsec in rad (by
    hand), exactly: a translation has no higher-order part."""
    text = _edited(M4, "{errors: {dx: EXB, ey: EBB}}", "{errors: {dx: EXB + L*EBB, ey: EC0}}")
    text = _edited(text, "  - {name: EXB, role: error, unit: um}",
                   "  - {name: EXB, role: error, unit: um}\n  - {name: EC0, role: error, unit: ppm}")
    text = _edited(text, "{translate: [0, 0, -L]}", "{translate: [0, 0, -L*cos(B)^2 - L*sin(B)^2]}")
    path = _write(tmp_path, "m.yaml", text)
    assert cli("lint", path).returncode == 0
    error = json.loads(cli("eval", path, "--set", "EBB=1 arcsec", "--json").stdout)["error"]
    assert error["exact"] == pytest.approx([120 * math.radians(1 / 3600), 0, 0], rel=1e-12, abs=1e-15)
    # EC0 = 1 ppm turns the tool's 120 mm about y: dx = -120 mm x 1e-6 to first order
    error = json.loads(cli("eval", path, "--set", "EC0=1 ppm", "--json").stdout)["error"]
    assert error["first"] == pytest.approx([-120e-6, 0, 0], rel=1e-12, abs=1e-15)


# ----------------------------------------------------------------------------- an axis' nominal

def test_an_axis_with_a_nominal_is_refused(tmp_path):
    """Nothing read it: eval, identify and the rest put the axis at 0 (or mid-range)."""
    text = _edited(M4, "{name: B, role: axis, unit: deg, limits: [-90, 90]}",
                   "{name: B, role: axis, unit: deg, limits: [-90, 90], nominal: 45}")
    path = _write(tmp_path, "m.yaml", text)
    _refused("eval", path, match="m.yaml:10: symbols.B.nominal: an axis has no nominal value: it stands at 0 "
                                 "(or mid-range where 0 is outside its limits) unless a verb sets it")


# ----------------------------------------------------------------------------- URDF

URDF = """\
<?xml version="1.0"?>
<robot name="r1">
  <link name="base"/>
  <link name="l1"/>
  <link name="l2"/>
  <link name="tip"/>
  <joint name="j1" type="revolute">
    <parent link="base"/><child link="l1"/>
    <origin xyz="0.01 0.002 0.3" rpy="0.1 -0.2 0.3"/>
    <axis xyz="0 0 1"/>
    <limit lower="-3.1" upper="3.1" effort="1" velocity="1"/>
  </joint>
  <joint name="j2" type="prismatic">
    <parent link="l1"/><child link="l2"/>
    <origin xyz="0.1 0 0"/>
    <axis xyz="1 1 0"/>
    <limit lower="-0.2" upper="0.5" effort="1" velocity="1"/>
  </joint>
  <joint name="f" type="fixed">
    <parent link="l2"/><child link="tip"/>
    <origin xyz="0 0.05 0.05"/>
  </joint>
</robot>
"""


def _import(tmp_path, text: str, check: bool = False):
    src = _write(tmp_path, "r.urdf", text)
    return cli("import-urdf", src, "--base", "base", "--tip", "tip", "-o", str(tmp_path / "r.yaml"), check=check)


def test_the_urdf_reference_imports(tmp_path):
    _import(tmp_path, URDF, check=True)
    assert (tmp_path / "r.yaml").exists()


def test_a_cycle_through_the_base_link_is_refused(tmp_path):
    """base -> l1 -> l2 -> tip, and a joint making base the child of tip: every link has one
    parent, so the per-link check passes; the tree has no root. Before, it imported (exit 0)."""
    text = _edited(URDF, "</robot>", '  <joint name="c" type="fixed"><parent link="tip"/><child link="base"/>'
                                     "</joint>\n</robot>")
    proc = _import(tmp_path, text)
    assert proc.returncode == 2, proc.stderr
    at = _line(text, '<joint name="c"')
    assert (f"r.urdf:{at}: joint c.child: --base 'base' is the child of joint 'c', and the "
            "joints above it come back round to link 'base' (through joint 'j1', line 7): a cycle") in proc.stderr
    assert not (tmp_path / "r.yaml").exists()


def test_a_root_above_the_base_is_no_cycle(tmp_path):
    text = _edited(URDF, "</robot>", '  <link name="world"/>\n  <joint name="c" type="fixed"><parent link="world"/>'
                                     '<child link="base"/></joint>\n</robot>')
    assert _import(tmp_path, text).returncode == 0


@pytest.mark.parametrize("element, old, new", [
    ("origin", '<origin xyz="0.1 0 0"/>', '<origin xyz="0.1 0 0"/>\n    <origin xyz="0.2 0 0"/>'),
    ("axis", '<axis xyz="1 1 0"/>', '<axis xyz="1 1 0"/>\n    <axis xyz="0 0 1"/>'),
    ("limit", '<limit lower="-0.2" upper="0.5" effort="1" velocity="1"/>',
     '<limit lower="-0.2" upper="0.5" effort="1" velocity="1"/>\n    <limit lower="-1" upper="1" effort="1" '
     'velocity="1"/>'),
    ("child", '<parent link="l1"/><child link="l2"/>',
     '<parent link="l1"/><child link="l2"/>\n    <child link="tip"/>'),
])
def test_a_joint_element_given_twice_is_refused(tmp_path, element, old, new):
    """yourdfpy takes the first and drops the rest: a second <origin> (a user's correction
    appended below the first) had no effect, without a word."""
    text = _edited(URDF, old, new)
    proc = _import(tmp_path, text)
    assert proc.returncode == 2, proc.stderr
    first = _line(text, old)            # each second element is written on the next line
    second = first + 1
    assert (f"r.urdf:{second}: joint j2.{element}: joint 'j2' has 2 <{element}> elements (first on line {first}): "
            "a joint has at most one") in proc.stderr


# ----------------------------------------------------------------------------- set-ups beyond the limits

def _measurements(tmp_path, rows: list[tuple]) -> str:
    text = "X,Y,Z,B,x,y,z\n" + "".join(",".join(f"{v:g}" for v in r) + "\n" for r in rows)
    return _write(tmp_path, "meas.csv", text)


def test_identify_warns_of_set_ups_beyond_the_axis_limits(tmp_path):
    """X = 9000 mm on a machine of X in [-300, 300]: a value in another unit, most likely. The
    warning names the file, the first such line, the axis and the count; the fit still runs."""
    machine = _write(tmp_path, "m.yaml", M4)
    rng = np.random.default_rng(5)
    rows = []
    for i in range(30):
        x, y, z, b = rng.uniform(-300, 300), rng.uniform(-200, 200), rng.uniform(-300, 0), rng.uniform(-90, 90)
        if i in (3, 7):
            x = 9000.0 + i
        # the nominal tool point of m4 (independent: T(X) T(Y) T(Z) Ry(B) T(0, 0, -L)), L = 120
        rb = math.radians(b)
        rows.append((x, y, z, b, x - 120 * math.sin(rb), y, z - 120 * math.cos(rb)))
    proc = cli("identify", machine, _measurements(tmp_path, rows), "--assume-zero", "EXB", check=False)
    assert proc.returncode == 0, proc.stderr
    # rows 3 and 7 are on lines 5 and 9 (the header is line 1)
    assert ("chaincomp identify: warning: " + str(tmp_path / "meas.csv") + ":5: X: 9003 mm is outside its limits "
            "[-300, 300] (2 rows of 30; are they in mm?)") in proc.stderr
    assert "warning" not in proc.stderr.replace("warning: " + str(tmp_path / "meas.csv") + ":5", "")


def test_identify_is_quiet_within_the_limits(tmp_path):
    machine = _write(tmp_path, "m.yaml", M4)
    rows = [(x, 0, -100, b, x - 120 * math.sin(math.radians(b)), 0, -100 - 120 * math.cos(math.radians(b)))
            for x in (-300, 0, 300) for b in (-90, 0, 90)]
    proc = cli("identify", machine, _measurements(tmp_path, rows), "--assume-zero", "EXB,EAX,EYY,EBB", check=False)
    assert "outside its limits" not in proc.stderr


def test_simulate_measurements_warns_of_set_ups_beyond_the_limits(tmp_path):
    """grid: values beyond the limits are left out with a note, --set beyond them is refused;
    a set-ups CSV beyond them was simulated without a word."""
    machine = _write(tmp_path, "m.yaml", M4)
    setups = _write(tmp_path, "s.csv", "X,Y,Z,B\n1,2,-3,4\n1,2,-3,4000\n")
    proc = cli("simulate-measurements", machine, "--setups", setups, "-o", str(tmp_path / "o.csv"))
    assert f"chaincomp simulate-measurements: warning: {setups}:3: B: 4000 deg is outside its limits [-90, 90] " \
           "(1 row of 2; is it in deg?)" in proc.stderr
    # B held by --set: the CSV's B is not used, so nothing to warn about
    proc = cli("simulate-measurements", machine, "--setups", setups, "--set", "B=0", "-o", str(tmp_path / "o.csv"))
    assert "outside its limits" not in proc.stderr


# ----------------------------------------------------------------------------- lint at large travel

def test_lint_sees_a_slide_of_very_long_travel_move_the_tool(tmp_path):
    """A slide with limits of +-1e14 mm (a URDF's prismatic limits of +-1e11 m): at such values a
    step of 1e-6 mm does not change the double, and lint said 'axis X never moves the tool point'.
    The slide moves the tool by dx/dX = 1 (by hand). An error that truly never moves it (an ez
    turn about the tool's own axis through the tool point) is still reported."""
    text = _edited(M4, "limits: [-300, 300]}", "limits: [-1e14, 1e14]}")
    text = _edited(text, "{translate: [0, 0, -L]}", "{translate: [0, 0, -L]}\n  - {errors: {ez: EZT}}")
    text = _edited(text, "  - {name: EXB, role: error, unit: um}",
                   "  - {name: EXB, role: error, unit: um}\n  - {name: EZT, role: error, unit: arcsec}")
    path = _write(tmp_path, "m.yaml", text)
    proc = cli("lint", path)
    assert "axis X never moves" not in proc.stderr + proc.stdout
    assert "error EZT never moves the tool point or direction" in proc.stderr + proc.stdout


# ----------------------------------------------------------------------------- report

def test_report_to_an_upper_case_tex_file_is_latex(tmp_path):
    machine = _write(tmp_path, "m.yaml", M4)
    out = tmp_path / "R.TEX"
    proc = cli("report", machine, "-o", str(out))
    assert "(latex, m4, order 1)" in proc.stdout + proc.stderr
    assert "\\begin" in out.read_text() or "\\section" in out.read_text()


# ----------------------------------------------------------------------------- one real process

def test_a_unit_mismatch_exits_2_from_a_process(tmp_path):
    text = _edited(M4, "{errors: {dx: EXB, ey: EBB}}", "{errors: {dx: EBB, ey: EXB}}")
    path = _write(tmp_path, "m.yaml", text)
    proc = run_cli("eval", path, check=False)
    assert proc.returncode == 2
    assert "Traceback" not in proc.stderr
    assert proc.stderr.startswith(f"chaincomp eval: error: {path}:{_line(text, 'dx: EBB')}: chain[7].errors.dx: ")


# ----------------------------------------------------------------------------- --set

@pytest.mark.parametrize("verb, extra", [("eval", ()), ("protocol", ("--poses", "30"))])
def test_set_of_one_symbol_twice_is_refused(tmp_path, verb, extra):
    """Before, the second silently won (eval printed X = 20)."""
    path = _write(tmp_path, "arm.yaml", DH)
    _refused(verb, path, *extra, "--set", "q1=10", "--set", "q1=20 deg",
             match=f"chaincomp {verb}: error: --set q1 given twice ('10', then '20 deg'): set each symbol once")


def test_set_of_two_symbols_in_one_item_says_how_to_write_it(tmp_path):
    """Before: --set X: unknown unit ',Y=20' (expected one of: mm, m, ...)."""
    path = _write(tmp_path, "m.yaml", M4)
    _refused("eval", path, "--set", "X=10,Y=20",
             match="--set X: '10,Y=20' sets more than one symbol: give one --set per symbol (--set X=10 --set Y=20)")
    out = cli("eval", path, "--set", "X=10", "--set", "Y=3mm", "--json").stdout
    assert json.loads(out)["axes"] == {"X": 10.0, "Y": 3.0, "Z": 0.0, "B": 0.0}


# ----------------------------------------------------------------------------- spreadsheet exports

def _nominal_rows() -> list[list[str]]:
    """Set-ups of m4 and their nominal tool points (by hand: x = X - L sin B, z = Z - L cos B)."""
    rows = []
    for x, b in ((-300, -90), (0, 0), (300, 90), (100, 30), (-50, -45)):
        rb = math.radians(b)
        rows.append([f"{x}", "10", "-100", f"{b}", f"{x - 120 * math.sin(rb)!r}", "10",
                     f"{-100 - 120 * math.cos(rb)!r}"])
    return rows


@pytest.mark.parametrize("sep, word", [(";", "';'"), ("\t", "tabs")])
def test_identify_a_csv_with_another_separator_says_so(tmp_path, sep, word):
    """Before: unknown column 'X;Y;Z;B;x;y;z' (expected the axes X, Y, Z, B and ...)."""
    text = sep.join("X Y Z B x y z".split()) + "\n" + "".join(sep.join(r) + "\n" for r in _nominal_rows())
    path = _write(tmp_path, "meas.csv", text)
    _refused("identify", _write(tmp_path, "m.yaml", M4), path,
             match=f"meas.csv:1: header: the header is one cell {text.splitlines()[0]!r}: columns are separated by "
                   f"commas, not {word}")


def test_identify_units_in_the_header_are_refused_with_the_unit_it_reads(tmp_path):
    """A header 'X [m]' would have been read in the machine's mm had it been accepted; it is
    refused, naming the unit identify reads the column in."""
    text = "X [m],Y,Z,B,x,y,z\n" + "".join(",".join(r) + "\n" for r in _nominal_rows())
    path = _write(tmp_path, "meas.csv", text)
    _refused("identify", _write(tmp_path, "m.yaml", M4), path,
             match="meas.csv:1: header: column 'X [m]': the header holds names only, no units; X is read in its "
                   "declared unit (mm): write 'X' and its values in that unit")
    text = "X,Y,Z,B,x (mm),y,z\n" + "".join(",".join(r) + "\n" for r in _nominal_rows())
    _refused("identify", _write(tmp_path, "m.yaml", M4), _write(tmp_path, "meas.csv", text),
             match="column 'x (mm)': the header holds names only, no units; x is read in the machine's length "
                   "unit (mm)")


# ----------------------------------------------------------------------------- units: the Greek mu

@pytest.mark.parametrize("where", ["params", "set", "machine"])
def test_a_unit_written_with_the_greek_mu_says_which_letter_to_use(tmp_path, where):
    """'μm' (U+03BC) and 'µm' (U+00B5) look the same; the refusal listed 'µm' among the units it
    expected, which read as nonsense."""
    machine = _write(tmp_path, "m.yaml", M4 if where != "machine" else
                     _edited(M4, "{name: EXX, role: error, unit: um}", "{name: EXX, role: error, unit: \u03bcm}"))
    argv = {"params": ("--params", _write(tmp_path, "p.yaml", "machine: m4\nvalues:\n  EXX: 5 \u03bcm\n")),
            "set": ("--set", "EXX=5 \u03bcm"), "machine": ()}[where]
    _refused("eval", machine, *argv, match="unknown unit '\u03bcm' (expected one of: mm, m, um, \u00b5m, nm, in, rad, "
             "deg, mrad, urad, \u00b5rad, arcsec, 1, ppm); it is written with the Greek letter mu (U+03BC): write "
             "the micro sign \u00b5 (U+00B5) or u, e.g. 'um'")


# ----------------------------------------------------------------------------- protocol of an imported arm

def test_protocol_of_an_imported_urdf_arm_is_bounded(tmp_path):
    """A three-joint URDF (revolute, prismatic, revolute about an oblique axis, origins with rpy
    0.1 -0.2 0.3) with --errors all: 21 errors at two set-ups. trigsimp of its coefficients
    took 24 s of CPU (48 s on the shared machine) for an answer that no error is identifiable;
    the coefficients are now only factored past a size. CPU time, not wall time: other jobs share
    the machine. The answer stays the same: every error but j3_ex is in one test of 6 equations."""
    import time
    text = _edited(URDF, '  <joint name="f" type="fixed">\n    <parent link="l2"/><child link="tip"/>',
                   '  <joint name="f" type="fixed">\n    <parent link="l2"/><child link="l3"/>')
    text = _edited(text, '  <link name="tip"/>', '  <link name="tip"/>\n  <link name="l3"/>')
    text = _edited(text, "</robot>", """  <joint name="j3" type="revolute">
    <parent link="l3"/><child link="tip"/>
    <origin xyz="0.2 0 0"/>
    <axis xyz="0.3 -0.4 0.5"/>
    <limit lower="-1" upper="1" effort="1" velocity="1"/>
  </joint>
</robot>""")
    src = _write(tmp_path, "r.urdf", text)
    out = str(tmp_path / "r.yaml")
    cli("import-urdf", src, "--base", "base", "--tip", "tip", "--errors", "all", "-o", out)
    start = time.process_time()
    proc = cli("protocol", out)
    assert time.process_time() - start < 15
    assert "j3_ex: does not move the tool point at any set-up of the grid" in proc.stdout
    assert "from 6 simultaneous equations" in proc.stdout


# ----------------------------------------------------------------------------- identify --sigma

def test_identify_a_sigma_whose_weight_overflows_is_refused(tmp_path):
    """--sigma 1e-200um: 1/sigma^2 is beyond a double, and the fit said 'none of the 6 parameters
    fitted moves the 15 coordinates: nothing to identify', which is false (they all do)."""
    machine = _write(tmp_path, "m.yaml", M4)
    meas = _write(tmp_path, "meas.csv", "X,Y,Z,B,x,y,z\n" + "".join(",".join(r) + "\n" for r in _nominal_rows()))
    _refused("identify", machine, meas, "--sigma", "1e-200um",
             match="--sigma: '1e-200um' is below 1e-30 mm: the weights 1/sigma^2 would leave a double's range")
    _refused("identify", machine, meas, "--sigma", "1um,x=1e-40m", match="--sigma: '1e-40m' is below 1e-30 mm")


# ----------------------------------------------------------------------------- a model outside its domain

# m4 with a tool length that needs X above -400 mm (sqrt): finite within X's limits, as the loader
# checks, but not at a set-up written beyond them
M4_SQRT = _edited(M4, "{translate: [0, 0, -L]}", "{translate: [0, 0, -L + sqrt(X + 400)]}")


def test_simulate_measurements_refuses_set_ups_where_the_model_is_not_finite(tmp_path):
    """Before: exit 0 and a row 'nan,nan,nan' in the CSV, which identify then refused."""
    machine = _write(tmp_path, "m.yaml", M4_SQRT)
    setups = _write(tmp_path, "s.csv", "X,Y,Z,B\n0,0,0,0\n-500,0,0,0\n")
    out = tmp_path / "o.csv"
    _refused_any = cli("simulate-measurements", machine, "--setups", setups, "-o", str(out), check=False)
    assert _refused_any.returncode == 2
    assert ("error: set-up 2 (X = -500 mm, Y = 0 mm, Z = 0 mm, B = 0 deg) gives a tool point that is not finite "
            "(1 of 2 set-ups): the machine's expressions leave their domain there") in _refused_any.stderr
    assert not out.exists()


def test_identify_names_the_set_up_where_the_model_is_not_finite(tmp_path):
    """Before: 'the fit went to non-finite values on these 15 coordinates ... (coordinates in mm?
    axes in their declared units?)', naming no row, though the model fails before any fit."""
    machine = _write(tmp_path, "m.yaml", M4_SQRT)
    rows = _nominal_rows()
    rows[2][0] = "-500"
    meas = _write(tmp_path, "meas.csv", "# a comment\nX,Y,Z,B,x,y,z\n" + "".join(",".join(r) + "\n" for r in rows))
    proc = cli("identify", machine, meas, check=False)
    assert proc.returncode == 2
    assert (f"error: {meas}:5: the model's tool pose is not finite at this set-up (X = -500 mm, Y = 10 mm, "
            "Z = -100 mm, B = 90 deg) with every error zero (1 set-up of 5): the machine's expressions leave their "
            "domain there") in proc.stderr


# ----------------------------------------------------------------------------- outputs that are not plain files

def _full_device(tmp_path) -> str:
    """A character device like /dev/full (1, 7: every write fails with ENOSPC), made in tmp_path
    so that a regression never touches the system's own. Needs root."""
    import os
    import stat
    if os.geteuid() != 0:
        pytest.skip("making a device node needs root")
    path = str(tmp_path / "full")
    os.mknod(path, 0o666 | stat.S_IFCHR, os.makedev(1, 7))
    return path


def _outputs(tmp_path) -> dict[str, list[str]]:
    machine = _write(tmp_path, "m.yaml", M4)
    meas = _write(tmp_path, "meas.csv", "X,Y,Z,B,x,y,z\n" + "".join(",".join(r) + "\n" for r in _nominal_rows()))
    return {"import-urdf": ["import-urdf", _write(tmp_path, "r.urdf", URDF), "--base", "base", "--tip", "tip"],
            "identify": ["identify", machine, meas, "--assume-zero", "EXB,EAX,EYY,EBB"],
            "simulate-measurements": ["simulate-measurements", machine],
            "simulate-log": ["simulate-log", machine, "--seconds", "0.01"],
            "report": ["report", machine],
            "testvectors": ["testvectors", machine, "--count", "2"]}


@pytest.mark.parametrize("verb", ["import-urdf", "identify", "simulate-measurements", "simulate-log", "report",
                                  "testvectors"])
def test_an_output_on_a_full_device_is_refused_and_the_device_stays(tmp_path, verb):
    """'-o /dev/full' run as root: import-urdf and identify -o wrote beside it and renamed over
    it, so /dev/full became a regular file and the verb said 'wrote'; simulate-log's liblcm
    ignored the failed writes and reported success."""
    import os
    import stat
    full = _full_device(tmp_path)
    proc = cli(*_outputs(tmp_path)[verb], "-o", full, check=False)
    assert proc.returncode == 2, proc.stderr
    assert f"error: {full}: cannot write" in proc.stderr and "No space left on device" in proc.stderr
    assert stat.S_ISCHR(os.stat(full).st_mode)
    assert not [f for f in os.listdir(tmp_path) if f.endswith(".tmp") or f.startswith(".")]


def test_an_output_through_a_symbolic_link_is_written_through_it(tmp_path):
    """The link stays a link (a rename over it would have replaced the link by a file)."""
    import os
    real = tmp_path / "real.yaml"
    real.write_text("old\n")
    link = tmp_path / "link.yaml"
    os.symlink(real, link)
    cli(*_outputs(tmp_path)["import-urdf"], "-o", str(link))
    assert os.path.islink(link)
    assert real.read_text().startswith("# Imported from the URDF")


@pytest.mark.parametrize("verb", ["simulate-measurements", "simulate-log", "report", "testvectors"])
def test_a_write_that_fails_midway_leaves_the_old_file_whole(tmp_path, verb):
    """A file size limit of 2 kB (RLIMIT_FSIZE, as a full disk would): the write fails partway.
    Before, simulate-measurements left the first 100 kB of its CSV (which identify reads as the
    whole run, a line short), and simulate-log exited 3 (an internal error)."""
    import resource
    import signal
    import subprocess
    import sys

    def limit():
        signal.signal(signal.SIGXFSZ, signal.SIG_IGN)
        resource.setrlimit(resource.RLIMIT_FSIZE, (2000, 2000))
    argv = _outputs(tmp_path)[verb]
    if verb == "simulate-measurements":
        argv += ["--setups", "random:200"]
    if verb in ("testvectors", "simulate-log"):
        argv[-1] = {"testvectors": "100", "simulate-log": "1"}[verb]   # 100 vectors, 1000 records: past 2 kB
    out = tmp_path / "out.dat"
    out.write_text("old\n")
    proc = subprocess.run([sys.executable, "-m", "chaincomp.cli.main", *argv, "-o", str(out)], capture_output=True,
                          text=True, preexec_fn=limit)
    assert proc.returncode == 2, proc.stderr
    assert f"error: {out}: cannot write" in proc.stderr and "File too large" in proc.stderr
    assert out.read_text() == "old\n"
    import os
    assert not [f for f in os.listdir(tmp_path) if f.startswith(".")]   # no temporary file left


def test_identify_a_column_in_another_unit_is_named_as_the_likely_cause(tmp_path):
    """B written in rad where the machine declares deg: every B is inside the limits, so no
    warning; the fit cannot converge (the model puts the tool 100 mm away), and the message
    now says what such a residual usually is."""
    machine = _write(tmp_path, "m.yaml", M4)
    rows = _nominal_rows()
    for r in rows:
        r[3] = repr(math.radians(float(r[3])))
    meas = _write(tmp_path, "meas.csv", "X,Y,Z,B,x,y,z\n" + "".join(",".join(r) + "\n" for r in rows))
    err = _refused("identify", machine, meas, "--assume-zero", "EXB,EBB", match="the fit did not converge")
    assert ("a residual this large is most often a column in another unit (the axes are read in their declared "
            "units, X in mm, Y in mm, Z in mm, B in deg; x, y, z in mm)") in err


# ----------------------------------------------------------------------------- limits in the other angle unit

@pytest.mark.parametrize("unit, limits, message", [
    ("deg", "[-3.14159, 3.14159]", "axis B's limits [-3.14159, 3.14159] deg look like radians (-pi, pi): a travel "
                                   "of only 6.28 deg; if they are radians, write [-180, 180] or declare the axis "
                                   "in rad"),
    ("deg", "[0, 6.2832]", "deg look like radians (0, 2 pi): a travel of only 6.28 deg; if they are radians, write "
                           "[0, 360]"),
    ("deg", "[-1.5708, 1.5708]", "look like radians (-pi/2, pi/2)"),
    ("rad", "[-180, 180]", "axis B's limits [-180, 180] rad are 57.3 turns: if they are degrees, declare the axis "
                           "in deg"),
    ("deg", "[-3, 3]", None), ("deg", "[-90, 90]", None), ("rad", "[-3.1416, 3.1416]", None),
])
def test_lint_warns_of_limits_written_in_the_other_angle_unit(tmp_path, unit, limits, message):
    """B in deg with limits [-3.14159, 3.14159]: every random set-up, every protocol angle and
    every plot then stays within +-3 deg, without a word. 180/pi = 57.2958 (by hand)."""
    text = _edited(M4, "{name: B, role: axis, unit: deg, limits: [-90, 90]}",
                   f"{{name: B, role: axis, unit: {unit}, limits: {limits}}}")
    proc = cli("lint", _write(tmp_path, "m.yaml", text))
    assert proc.returncode == 0
    if message is None:
        assert "limits" not in proc.stderr
    else:
        assert f"chaincomp lint: warning: {tmp_path / 'm.yaml'}:10: symbols.B.limits: " in proc.stderr
        assert message in proc.stderr
        assert cli("lint", _write(tmp_path, "m.yaml", text), "--strict", check=False).returncode == 2


def test_a_constant_or_error_beyond_the_limits_the_machine_file_gives_it_warns(tmp_path):
    """The loader checks a constant's nominal against its limits, but a --params or --set value
    beyond them went without a word (axes warn)."""
    text = _edited(M4, "{name: L, role: constant, unit: mm, nominal: 120}",
                   "{name: L, role: constant, unit: mm, nominal: 120, limits: [100, 200]}")
    text = _edited(text, "{name: EXX, role: error, unit: um}", "{name: EXX, role: error, unit: um, limits: [-5, 5]}")
    path = _write(tmp_path, "m.yaml", text)
    params = _write(tmp_path, "p.yaml", "machine: m4\nvalues:\n  L: 500 mm\n  EXX: 50 um\n")
    proc = cli("eval", path, "--params", params, "--json")
    assert f"chaincomp: warning: constant L = 500 mm is outside its limits [100, 200] ({path}:11)" in proc.stderr
    assert f"chaincomp: warning: error EXX = 50 um is outside its limits [-5, 5] ({path}:12)" in proc.stderr
    # the values are used as given: the tool 500 mm below, moved 50 um in x
    out = json.loads(proc.stdout)
    assert out["position"] == pytest.approx([0, 0, -500])
    assert out["error"]["exact"] == pytest.approx([0.05, 0, 0])
    assert "warning" not in cli("eval", path, "--set", "L=150", "--set", "EXX=1").stderr
