"""chaincomp ballbar's bad input: trace file faults named by file, line and field, option faults,
lengths beyond the bound after unit conversion, held axes beyond their limits (a warning)."""

from __future__ import annotations

import numpy as np
import pytest

from chaincomp.cli.main import main
from helpers import VMC, machine_path, refused, run_main


# vmc_xyz: X and Y move the tool along x and y; Z = 0 puts the tool at z = 400 mm
HEAD = ("# plane: XY\n# axes: X, Y\n# radius: 100 mm\n# centre: 0, 0, 400 mm\n# held: Z=0 mm\n"
        "angle [deg],direction,deviation [um]\n")                   # the header is line 6
ROWS = "".join(f"{a},ccw,{0.5 * np.cos(np.radians(a)):.6f}\n" for a in range(0, 360, 10))   # lines 7..42


def _trace(tmp_path, text: str) -> str:
    path = tmp_path / "trace.csv"
    path.write_text(text)
    return str(path)


@pytest.mark.parametrize("text,where", [
    # a decimal comma in a comma-separated file read '2,406424' as 2 (the rest a cell past the header)
    (HEAD + ROWS + "5,ccw,2,406424\n", ":43: 4 cells, the header has 3 (a decimal comma?"),
    (HEAD + ROWS + "5,ccw,0.1,junk\n", ":43: 4 cells, the header has 3"),
    # the same point twice: its residual counted twice, the uncertainties too small
    (HEAD + ROWS + "10,ccw,0.2\n", ":43: angle: the ccw point at 10 deg is given twice (first on line 8)"),
    (HEAD + ROWS + ROWS, ":43: angle: the ccw point at 0 deg is given twice (first on line 7)"),
    # an axis held twice took the last value
    (HEAD.replace("Z=0 mm", "Z=0 mm, Z=5 mm") + ROWS, ":5: held: Z given twice"),
    # --feed must be above 0; the header took any number
    (HEAD.replace("angle", "# feed: -5 mm/min\nangle") + ROWS,
     ":6: feed: the feed must be above 0 mm/min, got '-5 mm/min'"),
    (HEAD.replace("# held", "# feed: 0\n# held") + ROWS, ":5: feed: the feed must be above 0"),
    # refusals of the set-up named the file only (or nothing): now its line and field
    (HEAD.replace("X, Y", "Y, X") + ROWS, ":2: axes: Y does not move the tool along x here"),
    (HEAD.replace("Z=0 mm", "X=0 mm") + ROWS, ":5: held: X drives the circle; it cannot be held"),
    (HEAD.replace("0, 0, 400 mm", "0, 0, 500 mm") + ROWS,
     ":4: centre: the centre's z (500 mm) is not the tool's z with Z = 0 mm (400 mm)"),
    (HEAD.replace("100 mm", "300 mm") + ROWS,
     ":3: radius: the circle takes Y from -300 to 300 mm, beyond its limits [-250, 250]: not a circle this "
     "machine can run"),
])
def test_trace_faults_name_file_line_and_field(capsys, tmp_path, text, where):
    path = _trace(tmp_path, text)
    err = refused(capsys, "ballbar", VMC, "--fit", path, match=path + where)
    assert err.count("\n") == 1


def test_trailing_empty_cells_are_no_fault(capsys, tmp_path):
    """A spreadsheet's trailing comma leaves an empty cell: nothing is lost, nothing refused."""
    lines = (HEAD + ROWS).splitlines()
    path = _trace(tmp_path, "\n".join(lines[:6] + [r + "," for r in lines[6:]]) + "\n")
    code, _, err = run_main(capsys, "ballbar", VMC, "--fit", path)
    assert code == 0, err


def test_a_prediction_the_ballbar_could_not_read_is_refused(capsys, tmp_path):
    """R = 0.01 mm with µm-sized errors: the 'trace' is the tool's offset, not a deviation from R
    (G was 0, F the offset); read_trace refuses such a file, so predict refuses to make it."""
    demo = machine_path("vmc_xyz").replace("machines/vmc_xyz.yaml", "params/vmc_xyz-demo.yaml")
    refused(capsys, "ballbar", VMC, "--params", demo, "--plane", "XY", "--radius", "0.01",
             "-o", tmp_path / "t.csv", match="not small against the radius (0.01 mm)")
    assert not (tmp_path / "t.csv").exists()


@pytest.mark.parametrize("options,match", [
    # an empty value was taken as the default
    (["--plane", "XY", "--radius", "10", "--centre", ""], "--centre: an empty value"),
    (["--plane", "XY", "--radius", "10", "--axes", " "], "--axes: an empty value"),
    (["--plane", "XY", "--radius", "10", "--plot", "x.png", "-o", "x.png"], "--plot x.png: is also the -o output"),
])
def test_ballbar_option_faults(capsys, tmp_path, monkeypatch, options, match):
    monkeypatch.chdir(tmp_path)
    refused(capsys, "ballbar", VMC, *options, match=match)


def test_fit_option_faults(capsys, tmp_path):
    path = _trace(tmp_path, HEAD + ROWS)
    refused(capsys, "ballbar", VMC, "--fit", path, "--prefer", "", match="--prefer: an empty value")
    # preferred and held at the start value at once: the preference was silently dropped
    refused(capsys, "ballbar", VMC, "--fit", path, "--prefer", "EC0Y", "--assume-zero", "ECX,EC0Y",
             match="--prefer EC0Y: it is also in --assume-zero")


INCH_MACHINE = """\
name: inch_xy
length_unit: in
rotation_sense: right_hand
symbols:
  - {name: X, role: axis, unit: in, limits: [-10, 10]}
  - {name: Y, role: axis, unit: in, limits: [-10, 10]}
  - {name: SX, role: error, unit: ppm}
chain:
  - {translate: ["X*(1 + SX)", Y, 0]}
tool: {point: [0, 0, 0]}
"""


@pytest.mark.parametrize("options,match", [
    # 1e308 in is inf mm: Newton 'missed by nan mm' before
    (["--radius", "1e308"], "--radius: 1e+308 in is larger than 1e+15 mm in magnitude"),
    (["--radius", "1", "--centre", "x=1e308"], "--centre x: 1e+308 in is larger than 1e+15 mm in magnitude"),
])
def test_ballbar_lengths_beyond_the_bound_after_conversion(capsys, tmp_path, options, match):
    m = tmp_path / "inch_xy.yaml"
    m.write_text(INCH_MACHINE)
    refused(capsys, "ballbar", m, "--set", "SX=10", "--plane", "XY", *options, match=match)


def test_ballbar_fit_prints_estimates_as_people_read_them(capsys, tmp_path):
    """The fit's table as identify's: 'estimate ± uncertainty' (two significant digits) in µm,
    arcsec, µm/m. A trace of the squareness 9 arcsec and the scale errors 12 and -7 ppm of the
    test's three-axis machine, where x = V (1 + SV) + U sin(SQ), y = U (1 + SU) cos(SQ)."""
    import re
    m = tmp_path / "m.yaml"
    m.write_text("name: bb_hunt\nlength_unit: mm\nrotation_sense: right_hand\nsymbols:\n"
                 "  - {name: U, role: axis, unit: mm, limits: [-300, 300]}\n"
                 "  - {name: V, role: axis, unit: mm, limits: [-300, 300]}\n"
                 "  - {name: SV, role: error, unit: ppm}\n  - {name: SU, role: error, unit: ppm}\n"
                 "  - {name: SQ, role: error, unit: arcsec}\n"
                 'chain:\n  - {translate: ["V*(1 + SV) + U*sin(SQ)", "U*(1 + SU)*cos(SQ)", 0]}\n'
                 "tool: {point: [0, 0, 0]}\n")
    trace = tmp_path / "t.csv"
    assert main(["ballbar", str(m), "--set", "SV=12", "--set", "SU=-7", "--set", "SQ=9", "--plane", "XY",
                 "--radius", "100", "-o", str(trace)]) == 0
    capsys.readouterr()
    assert main(["ballbar", str(m), "--fit", str(trace)]) == 0
    out = capsys.readouterr().out
    for name, unit, want in (("SQ", "arcsec", 9.0), ("SV", "ppm", 12.0), ("SU", "ppm", -7.0)):
        found = re.search(rf"^  {name}\s+(\S+) ± (\S+) {unit}\s", out, re.M)
        assert found, out
        value, u = found.groups()
        assert abs(float(value) - want) < 1e-3          # second-order terms the linear fit leaves
        assert len(u.replace("0.", "").lstrip("0")) == 2   # two significant digits
    assert "± " in re.search(r"^  centre x .*$", out, re.M).group(0) and " µm " in out


def test_a_held_axis_beyond_its_limits_warns(capsys, tmp_path):
    """vmc_xyz's Z travels -400..0 mm: a trace held at Z = 100 mm was fitted without a word (a
    prediction with --set Z=100 warns)."""
    path = _trace(tmp_path, HEAD.replace("Z=0 mm", "Z=100 mm").replace("0, 0, 400 mm", "0, 0, 500 mm") + ROWS)
    code, _, err = run_main(capsys, "ballbar", VMC, "--fit", path)
    assert code == 0, err
    assert f"warning: {path}:5: held: Z = 100 mm is outside its limits [-400, 0]" in err
