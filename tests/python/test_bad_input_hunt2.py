"""The second bad-input hunt over this session's new verbs (ballbar, plot --view volume/--html,
eval --units, display): each case a fault found by hand, with the message and exit code the
contract asks for written here (exit 2 and one line naming file, line and field; never exit 3,
never a silent wrong value)."""

from __future__ import annotations

import numpy as np
import pytest

from chaincomp.model import display
from chaincomp.cli.main import main
from conftest import machine_path

VMC = machine_path("vmc_xyz")


def _run(capsys, *argv) -> tuple[int, str]:
    capsys.readouterr()
    code = main([str(a) for a in argv])
    return code, capsys.readouterr().err


def _refused(capsys, *argv, match: str) -> str:
    code, err = _run(capsys, *argv)
    assert code == 2, err
    assert match in err, err
    assert "Traceback" not in err and "internal error" not in err
    return err


# ----------------------------------------------------------------------------- plot

def test_volume_view_of_an_error_table(tmp_path):
    """An error given as a table crashed the volume view (exit 3: 0.0 times a Table). EXX as a
    straight table 0 -> 4 um over X's travel: the arrows are (EXX(X), 0, 0), read off the table
    here (linear between its three knots)."""
    from chaincomp.cli import plot
    from chaincomp.cli.main import build_parser
    p = tmp_path / "p.yaml"
    p.write_text("machine: vmc_xyz\nvalues:\n  EXX:\n    axis: X\n    units: [mm, um]\n"
                 "    interpolation: linear\n    outside: hold\n"
                 "    table:\n      - [-400, 0]\n      - [0, 2]\n      - [400, 4]\n")
    args = build_parser().parse_args(["plot", VMC, "--params", str(p), "--view", "volume", "--grid", "3"])
    plot._normalise(args)
    d = plot.volume_data(args, args.over, args.grid)
    x = d.point[:, 0]
    assert np.allclose(d.error[:, 0], (x + 400) / 200, rtol=0, atol=1e-9)
    assert np.allclose(d.error[:, 1:], 0, atol=1e-9)
    assert main(["plot", VMC, "--params", str(p), "--view", "volume", "--grid", "3",
                 "-o", str(tmp_path / "v.png"), "--html", str(tmp_path / "v.html")]) == 0


# ----------------------------------------------------------------------------- display

@pytest.mark.parametrize("value,u,text", [
    # more digits than decimal's 28-digit context: InvalidOperation (identify's exit 3) before
    (1e300, 1.0, "1e+300 ± 1.0e+00"),
    (5.0, 1e-320, "5.0 ± 1.0e-320"),
    (-3e-7, 1e-25, "-3e-07 ± 1.0e-25"),
    # 17 significant digits still round as always
    (1.2345678901234567, 1e-16, "1.23456789012345670 ± 0.00000000000000010"),
    (0.0, 1e-300, "(0.0 ± 1.0)e-300"),
])
def test_plus_minus_of_an_uncertainty_finer_than_a_double(value, u, text):
    assert display.plus_minus(value, u) == text


# ----------------------------------------------------------------------------- ballbar

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
    err = _refused(capsys, "ballbar", VMC, "--fit", path, match=path + where)
    assert err.count("\n") == 1


def test_trailing_empty_cells_are_no_fault(capsys, tmp_path):
    """A spreadsheet's trailing comma leaves an empty cell: nothing is lost, nothing refused."""
    lines = (HEAD + ROWS).splitlines()
    path = _trace(tmp_path, "\n".join(lines[:6] + [r + "," for r in lines[6:]]) + "\n")
    code, err = _run(capsys, "ballbar", VMC, "--fit", path)
    assert code == 0, err


def test_a_prediction_the_ballbar_could_not_read_is_refused(capsys, tmp_path):
    """R = 0.01 mm with µm-sized errors: the 'trace' is the tool's offset, not a deviation from R
    (G was 0, F the offset); read_trace refuses such a file, so predict refuses to make it."""
    demo = machine_path("vmc_xyz").replace("machines/vmc_xyz.yaml", "params/vmc_xyz-demo.yaml")
    _refused(capsys, "ballbar", VMC, "--params", demo, "--plane", "XY", "--radius", "0.01",
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
    _refused(capsys, "ballbar", VMC, *options, match=match)


def test_fit_option_faults(capsys, tmp_path):
    path = _trace(tmp_path, HEAD + ROWS)
    _refused(capsys, "ballbar", VMC, "--fit", path, "--prefer", "", match="--prefer: an empty value")
    # preferred and held at the start value at once: the preference was silently dropped
    _refused(capsys, "ballbar", VMC, "--fit", path, "--prefer", "EC0Y", "--assume-zero", "ECX,EC0Y",
             match="--prefer EC0Y: it is also in --assume-zero")


@pytest.mark.parametrize("options,match", [
    # '' was taken as the default (-o '': no file written at all, exit 0)
    (["--view", "volume", "--over", ""], "--over: an empty value"),
    (["-o", ""], "-o: an empty value"),
    (["--html", ""], "--html: an empty value"),
    # 1e308 reached the model (a 'not finite' error naming no option); the bound of every value
    (["--view", "volume", "--range", "-1e308:1e308"], "--range: values are at most 1e+15 in magnitude"),
    (["--range2", "0:1e16"], "--range2: values are at most 1e+15 in magnitude"),
])
def test_plot_option_faults(capsys, tmp_path, monkeypatch, options, match):
    monkeypatch.chdir(tmp_path)
    _refused(capsys, "plot", VMC, "--set", "EXX=1", "--grid", "3", *options, match=match)
    assert not list(tmp_path.iterdir())


def test_plot_range_beyond_the_limits_warns(capsys, tmp_path):
    """vmc_xyz's X travels -400..400 mm: a map out to -500 shows where the machine cannot go."""
    code, err = _run(capsys, "plot", VMC, "--set", "EXX=1", "--grid", "3", "--over", "X,Y", "--range", "-500:100",
                     "--range2", "-10:10", "-o", tmp_path / "m.png")
    assert code == 0 and (tmp_path / "m.png").exists()
    assert "warning: --range -500:100: beyond the limits of X [-400, 400] mm" in err
    assert "--range2" not in err


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
    _refused(capsys, "ballbar", m, "--set", "SX=10", "--plane", "XY", *options, match=match)


@pytest.mark.parametrize("argv", [
    ["plot", VMC, "--set", "EXX=1", "--component", "dx", "--grid", "3", "-o", "/dev/full"],
    ["plot", VMC, "--set", "EXX=1", "--grid", "3", "--view", "volume", "-o", "/dev/full"],
    ["ballbar", VMC, "--set", "EXX=1", "--plane", "XY", "--radius", "10", "--plot", "/dev/full"],
])
def test_a_failed_image_write_is_an_error_naming_the_file(capsys, argv):
    """A full disk (/dev/full: ENOSPC on every write) was an internal error (exit 3), or an image
    silently cut short; refused before the work where the folder is not writable."""
    err = _refused(capsys, *argv, match="/dev/full")
    assert err.count("\n") == 1


def test_a_failed_html_write_is_an_error_naming_the_file(capsys):
    """--html where no file can be made (/proc takes none, even from root): exit 2 naming the file,
    not exit 3."""
    err = _refused(capsys, "plot", VMC, "--set", "EXX=1", "--component", "dx", "--grid", "3",
                   "--html", "/proc/chaincomp-test.html", match="/proc/chaincomp-test.html")
    assert err.count("\n") == 1


def _replay_csv(tmp_path, rows=None, header=None) -> str:
    """A replay CSV of a three-axis machine in the columns 'chaincomp replay --csv' writes."""
    axes = ("X", "Y", "Z")
    head = header or (["event", "utime", "seq", "result"] + [f"{k}_{a}_mm" for k in ("commanded", "corrected",
                                                                                       "correction") for a in axes]
                      + ["residual_point_mm"])
    rows = _replay_rows(lambda r: None) if rows is None else rows
    path = tmp_path / "replay.csv"
    path.write_text("\n".join(",".join(r) for r in [head] + rows) + "\n")
    return str(path)


def _replay_rows(change):
    """Five corrected records; change(rows) edits them in place."""
    rows = [[str(i), str(1_700_000_000_000_000 + 1000 * i), str(i + 1), "ok"] + ["1"] * 3 + ["1.001"] * 3
            + ["0.001"] * 3 + ["1e-9"] for i in range(5)]
    change(rows)
    return rows


@pytest.mark.parametrize("change,where", [
    # a row cut short read as a record without a result: counted as rejected, silently
    (lambda r: r.__setitem__(2, r[2][:3]), ":4: a row of 3 cells, the header has 14"),
    (lambda r: r[2].append("7"), ":4: a row of 15 cells, the header has 14"),
    # 1e308 mm reached the exact model
    (lambda r: r[1].__setitem__(4, "1e308"), ":3: commanded_X_mm: '1e308' is beyond 1e+15 in magnitude"),
    (lambda r: r[1].__setitem__(1, "-5"), ":3: utime: expected whole microseconds from 0 to 2^62, got '-5'"),
    (lambda r: r[1].__setitem__(1, "1.5"), ":3: utime: expected whole microseconds"),
])
def test_replay_csv_faults(capsys, tmp_path, change, where):
    path = _replay_csv(tmp_path, _replay_rows(change))
    _refused(capsys, "plot", "--replay", path, "-o", tmp_path / "r.png", match=path + where)


def test_replay_csv_header_faults(capsys, tmp_path):
    head = ["event", "utime", "seq", "result", "commanded_X_mm", "corrected_X_mm", "correction_X_mm",
            "residual_point_mm", "utime"]
    path = _replay_csv(tmp_path, [["0", "1", "1", "ok", "1", "1", "0", "0", "1"]], head)
    _refused(capsys, "plot", "--replay", path, "-o", tmp_path / "r.png", match=path + ":1: two columns named 'utime'")


def test_replay_csv_with_a_byte_order_mark_and_utime_first(capsys, tmp_path):
    """A spreadsheet's BOM glued to the first column's name: 'no utime column' before."""
    path = _replay_csv(tmp_path)
    lines = open(path).read().splitlines()
    cols = [line.split(",") for line in lines]
    with open(path, "w", encoding="utf-8-sig") as f:
        f.write("\n".join(",".join([c[1], c[0]] + c[2:]) for c in cols) + "\n")
    code, err = _run(capsys, "plot", "--replay", path, "-o", tmp_path / "r.png")
    assert code == 0, err


def test_replay_csv_time_going_back_warns(capsys, tmp_path):
    path = _replay_csv(tmp_path, _replay_rows(lambda r: r[3].__setitem__(1, "1600000000000000")))
    code, err = _run(capsys, "plot", "--replay", path, "-o", tmp_path / "r.png")
    assert code == 0 and f"{path}:5: utime goes back" in err, err


# ----------------------------------------------------------------------------- eval

def test_eval_refuses_a_polynomial_beyond_the_value_bound(capsys, tmp_path):
    """Each coefficient within bounds, the value not: 1 + 1e300 * 100 = 1e302 um at X = 100 mm was
    printed as a 300-digit error."""
    p = tmp_path / "p.yaml"
    p.write_text("machine: vmc_xyz\nvalues:\n  EXX:\n    axis: X\n    units: [mm, um]\n"
                 "    polynomial: [1, 1.0e+300]\n    range: [-400, 400]\n    outside: hold\n")
    _refused(capsys, "eval", VMC, "--params", p, "--set", "X=100",
             match=f"{p}:3: values.EXX: EXX = 1e+302 um at X = 100 mm: beyond 1e+15 (mm, rad) in magnitude")
    code, err = _run(capsys, "eval", VMC, "--params", p, "--set", "X=0")   # 1 um there
    assert code == 0, err


def test_plus_minus_of_numpy_floats():
    """repr(np.float64(2.4)) is 'np.float64(2.4)' in numpy 2: no decimal text (exit 3 before)."""
    assert display.plus_minus(np.float64(4.6), np.float64(0.21)) == "4.60 ± 0.21"
    assert display.uncertain(np.float64(4.6e-3), np.float64(2.1e-4), "length") == "4.60 ± 0.21 µm"


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


def test_plot_of_a_one_axis_machine(capsys, tmp_path):
    """A map needs two axes: '--over expects two different axes ..., got None' before."""
    m = tmp_path / "one.yaml"
    m.write_text("name: one_axis\nlength_unit: mm\nsymbols:\n  - {name: X, role: axis, unit: mm, limits: [-300, 300]}\n"
                 "  - {name: EXX, role: error, unit: um}\nchain:\n  - {translate: [X + EXX, 0, 0]}\n"
                 "tool: {point: [0, 0, 0]}\n")
    for view in (["-o", tmp_path / "m.png"], ["--view", "surface", "-o", tmp_path / "m.png"],
                 ["--html", tmp_path / "m.html"]):
        _refused(capsys, "plot", m, "--set", "EXX=1", *view,
                 match="one_axis has one axis (X): a map, a surface and --html draw over two")
    code, err = _run(capsys, "plot", m, "--set", "EXX=1", "--view", "volume", "-o", tmp_path / "v.png")
    assert code == 0, err


@pytest.mark.parametrize("verb,options", [
    ("eval", []),
    ("plot", ["-o", "x.png"]),
    ("ballbar", ["--plane", "XY", "--radius", "10"]),
])
def test_an_empty_params_value_is_refused(capsys, tmp_path, monkeypatch, verb, options):
    """--params '' ran with every error zero: eval printed the nominal pose alone, exit 0."""
    monkeypatch.chdir(tmp_path)
    _refused(capsys, verb, VMC, "--params", "", *options, match="--params: an empty value")


def test_a_held_axis_beyond_its_limits_warns(capsys, tmp_path):
    """vmc_xyz's Z travels -400..0 mm: a trace held at Z = 100 mm was fitted without a word (a
    prediction with --set Z=100 warns)."""
    path = _trace(tmp_path, HEAD.replace("Z=0 mm", "Z=100 mm").replace("0, 0, 400 mm", "0, 0, 500 mm") + ROWS)
    code, err = _run(capsys, "ballbar", VMC, "--fit", path)
    assert code == 0, err
    assert f"warning: {path}:5: held: Z = 100 mm is outside its limits [-400, 0]" in err
