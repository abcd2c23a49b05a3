"""identify of errors that vary along an axis: tables on given knots and polynomials.

A small machine written here: an X slide whose error block holds its positioning EXX, its
straightness EYX and its yaw ECX, then a Y slide and a tool 100 mm long. Its tool point is
written in numpy below from the chain as stated (T(X) T(EXX, EYX, 0) Rz(ECX) T(0, Y, -L)),
with the injected shapes evaluated by numpy's own np.interp / np.polyval: the measurements
come from there, not from chaincomp's model.
"""

import json
import math

import numpy as np
import pytest

from chaincomp import load_machine, load_params
from chaincomp.cli.main import main
from chaincomp.measure.identify import Vary, identify
from chaincomp.measure.table import Table
from chaincomp.symbolic.numeric import ExactModel

UM, ARCSEC = 1e-3, math.pi / 648000
MACHINE = """\
name: x_slide
description: an X slide with its positioning, straightness and yaw, a Y slide, a tool
length_unit: mm
rotation_sense: right_hand
error_block_order: txyz
symbols:
  - {name: X, role: axis, unit: mm, limits: [0, 300], meaning: X slide}
  - {name: Y, role: axis, unit: mm, limits: [0, 200], meaning: Y slide}
  - {name: L, role: constant, unit: mm, nominal: 100, meaning: tool length}
  - {name: EXX, role: error, unit: um, meaning: X positioning}
  - {name: EYX, role: error, unit: um, meaning: X straightness in y}
  - {name: ECX, role: error, unit: arcsec, meaning: X yaw}
  - {name: EC0Y, role: error, unit: arcsec, meaning: squareness of Y to X}
chain:
  - {translate: [X, 0, 0]}
  - {errors: {dx: EXX, dy: EYX, ez: ECX}}
  - {translate: [-Y*sin(EC0Y), Y*cos(EC0Y), 0]}
  - {translate: [0, 0, -L]}
tool:
  point: [0, 0, 0]
"""
KNOTS = np.array([0.0, 100.0, 200.0, 300.0])          # mm
SIGMA = 1 * UM


def points(X, Y, exx, eyx, ecx, ec0y=0.0):
    """Tool point (rows, 3), all internal (mm, rad); error values per row."""
    x = X + exx + np.cos(ecx) * (-Y * np.sin(ec0y)) - np.sin(ecx) * Y * np.cos(ec0y)
    y = eyx + np.sin(ecx) * (-Y * np.sin(ec0y)) + np.cos(ecx) * Y * np.cos(ec0y)
    return np.stack([x, y, np.full_like(x, -100.0)], axis=1)


@pytest.fixture(scope="module")
def machine(tmp_path_factory):
    path = tmp_path_factory.mktemp("m") / "x_slide.yaml"
    path.write_text(MACHINE)
    m = load_machine(str(path))
    return str(path), m, ExactModel(m)


def setups():
    X = np.repeat(np.linspace(0, 300, 16), 2)
    Y = np.tile([0.0, 200.0], 16)
    return X, Y


def table_trial(m, model, rng, smooth=0.0, knots=KNOTS, shape=None):
    X, Y = setups()
    vx = rng.normal(0, 5, len(knots)) if shape is None else shape(knots)          # µm
    vy = rng.normal(0, 3, len(knots))
    vc = rng.normal(0, 4, len(knots))                                              # arcsec
    pts = points(X, Y, np.interp(X, knots, vx) * UM, np.interp(X, knots, vy) * UM,
                 np.interp(X, knots, vc) * ARCSEC)
    pts[:, :2] += SIGMA * rng.standard_normal((len(X), 2))
    pts[:, 2] = np.nan
    table = Table("trial", {"X": X, "Y": Y}, pts, list(range(len(X))))
    kn = tuple(knots)
    fit = identify(m, table, ("EC0Y",), {"x": SIGMA, "y": SIGMA}, model=model, smooth=smooth,
                   vary=[Vary("EXX", "X", "table", kn), Vary("EYX", "X", "table", kn), Vary("ECX", "X", "table", kn)])
    truth = {}
    for name, v, f in (("EXX", vx, UM), ("EYX", vy, UM), ("ECX", vc, ARCSEC)):
        for k, x in zip(knots, v):
            truth[f"{name}@X={k:.10g}"] = x * f
    return fit, truth


@pytest.mark.slow
def test_tables_recovered_within_their_uncertainty(machine):
    """200 seeded trials, three tables of 4 knots each: the injected knot values lie within 3
    reported standard uncertainties in at least 99 % of the cases."""
    _, m, model = machine
    rng = np.random.default_rng(20)
    inside = total = 0
    for _ in range(200):
        fit, truth = table_trial(m, model, rng)
        assert fit.converged and not fit.unidentifiable and set(fit.estimates) == set(truth)
        for name, value in fit.estimates.items():
            total += 1
            inside += abs(value - truth[name]) <= 3 * fit.uncertainties[name]
    assert total == 200 * 12 and inside / total >= 0.99, (inside, total)


@pytest.mark.slow
def test_polynomials_recovered_within_their_uncertainty(machine):
    _, m, model = machine
    rng = np.random.default_rng(21)
    X, Y = setups()
    inside = total = 0
    for _ in range(200):
        cx = rng.normal(0, 1, 4) * np.array([5, 5e-2, 5e-4, 5e-6])     # µm / mm^k, lowest first
        cc = rng.normal(0, 1, 3) * np.array([4, 4e-2, 4e-4])            # arcsec / mm^k
        pts = points(X, Y, np.polyval(cx[::-1], X) * UM, 0 * X, np.polyval(cc[::-1], X) * ARCSEC)
        pts[:, :2] += SIGMA * rng.standard_normal((len(X), 2))
        fit = identify(m, Table("t", {"X": X, "Y": Y}, pts, list(range(len(X)))), ("EC0Y", "EYX"), SIGMA,
                       model=model, vary=[Vary("EXX", "X", "poly", degree=3), Vary("ECX", "X", "poly", degree=2)])
        truth = {f"EXX.c{k}": c * UM for k, c in enumerate(cx)}
        truth.update({f"ECX.c{k}": c * ARCSEC for k, c in enumerate(cc)})
        assert set(fit.estimates) == set(truth)
        for name, value in fit.estimates.items():
            total += 1
            inside += abs(value - truth[name]) <= 3 * fit.uncertainties[name]
    assert total == 200 * 7 and inside / total >= 0.99, (inside, total)


@pytest.mark.slow
def test_smoothing_reduces_the_variance(machine):
    """Seven knots, a straight positioning error (no second difference: smoothing adds no bias):
    with --smooth the knot values scatter less over 60 trials, and the reported uncertainties
    are smaller."""
    _, m, model = machine
    knots = np.linspace(0, 300, 7)
    line = lambda k: 2.0 + 0.02 * k  # noqa: E731  (µm)
    spread, reported = {}, {}
    for smooth in (0.0, 4.0):
        rng = np.random.default_rng(22)
        est = []
        for _ in range(60):
            fit, truth = table_trial(m, model, rng, smooth, knots, line)
            names = [n for n in truth if n.startswith("EXX")]
            est.append([fit.estimates[n] - truth[n] for n in names])
        spread[smooth] = np.var(np.array(est), axis=0).mean()
        reported[smooth] = np.mean([fit.uncertainties[n] for n in names])
    assert spread[4.0] < 0.7 * spread[0.0], spread
    assert reported[4.0] < reported[0.0]


def write_csv(path, X, Y, pts):
    lines = ["X,Y,x,y"] + [",".join(repr(float(v)) for v in (a, b, p[0], p[1])) for a, b, p in zip(X, Y, pts)]
    path.write_text("\n".join(lines) + "\n")


def cli(capsys, *args):
    rc = main([str(a) for a in args])
    out, err = capsys.readouterr()
    return rc, out, err


def test_the_params_file_reads_back_as_tables_and_polynomials(machine, tmp_path, capsys):
    """Through the CLI: the axis found from the slide, the table and the polynomial written in
    the params format, read back by load_params and evaluated as the fit's values."""
    path, m, _ = machine
    X, Y = setups()
    rng = np.random.default_rng(23)
    vx = np.array([0.0, 3.0, -2.0, 4.0])
    cc = np.array([2.0, 1e-2, -5e-5])
    pts = points(X, Y, np.interp(X, KNOTS, vx) * UM, 0 * X, np.polyval(cc[::-1], X) * ARCSEC)
    pts += 0.1 * UM * rng.standard_normal(pts.shape)
    write_csv(tmp_path / "meas.csv", X, Y, pts)
    out = tmp_path / "fit.yaml"
    rc, text, err = cli(capsys, "identify", path, tmp_path / "meas.csv", "--assume-zero", "EYX,EC0Y",
                        "--vary", "EXX=table:0,100,200,300", "--vary", "ECX=poly:2", "-o", out)
    assert rc == 0, err
    assert "EXX varies along X: a table on 4 knots" in text and "EXX@X=100" in text and "ECX.c2" in text
    loaded = load_params(str(out), m)
    tab, poly = loaded["EXX"], loaded["ECX"]
    assert tab.describe().startswith("table over X, 4 points in [0, 300] mm, linear")
    np.testing.assert_allclose(tab(KNOTS) / UM, vx, atol=0.3)            # 0.1 µm noise
    np.testing.assert_allclose(poly(X) / ARCSEC, np.polyval(cc[::-1], X), atol=0.3)
    doc = json.loads(cli(capsys, "identify", path, tmp_path / "meas.csv", "--assume-zero", "EYX,EC0Y", "--vary",
                         "EXX=table:0,100,200,300", "--vary", "ECX=poly:2", "--format", "json")[1])
    v = doc["varying"]["EXX"]
    assert v["positions"] == [0, 100, 200, 300] and v["units"] == ["mm", "mm"]     # JSON: internal units
    assert np.allclose(v["values"], tab(KNOTS), rtol=1e-9, atol=1e-15)
    p = doc["varying"]["ECX"]
    assert p["range"] == [0, 300] and p["units"] == ["mm", "rad"]
    assert np.allclose(np.polyval(p["coefficients"][::-1], X), poly(X), rtol=1e-9, atol=1e-15)


def test_a_knot_no_measurement_sees_is_reported(machine, tmp_path, capsys):
    path, m, _ = machine
    X, Y = setups()
    keep = X <= 200
    write_csv(tmp_path / "meas.csv", X[keep], Y[keep], points(X[keep], Y[keep], 0 * X[keep], 0 * X[keep], 0 * X[keep]))
    rc, text, err = cli(capsys, "identify", path, tmp_path / "meas.csv", "--assume-zero", "EYX,ECX,EC0Y",
                        "--vary", "EXX=table:0,100,250,300", "--sigma", "1um", "-o", tmp_path / "p.yaml")
    assert rc == 0, err
    assert "EXX@X=300: does not move the measured coordinates" in text
    assert "# EXX: not written, not identifiable: EXX@X=300" in (tmp_path / "p.yaml").read_text()
    rc, text, err = cli(capsys, "identify", path, tmp_path / "meas.csv", "--assume-zero", "EYX,ECX,EC0Y",
                        "--vary", "EXX=table:0,100,250", "--sigma", "1um")
    assert rc == 0 and "note: " not in text
    rc, text, err = cli(capsys, "identify", path, tmp_path / "meas.csv", "--assume-zero", "EYX,ECX,EC0Y",
                        "--vary", "EXX=table:0,100,150", "--sigma", "1um")
    assert "note: 6 set-ups lie outside EXX's knots [0, 150] mm of X: the table holds its end values there" in text


@pytest.mark.parametrize("args, message", [
    (["--vary", "EXX"], "--vary EXX: expected NAME=table:K1,K2,... or NAME=poly:DEGREE"),
    (["--vary", "EQQ=poly:2"],
     "--vary EQQ=poly:2: unknown error 'EQQ' for machine 'x_slide' (errors: EXX, EYX, ECX, EC0Y)"),
    (["--vary", "EXX@Q=poly:2"], "'Q' is not an axis of x_slide (axes: X, Y)"),
    (["--vary", "EC0Y=poly:1"], "EC0Y is not a component error of a slide"),
    (["--vary", "EXX=spline:3"], "unknown form 'spline'"),
    (["--vary", "EXX=table:100"], "a table needs 2 to 4096 knots, got 1"),
    (["--vary", "EXX=table:0,200,100"], "knots must increase (and differ in 10 significant digits): 100 follows 200"),
    (["--vary", "EXX=table:0,nan"], "expected a finite number, got 'nan'"),
    (["--vary", "EXX=table:0,,300"], "expected a number, got ''"),
    (["--vary", "EXX=table:0,400"], "knot 400 lies outside X's limits [0, 300] mm"),
    (["--vary", "EXX=table:"], "expected table:K1,K2,... (knots along X in mm)"),
    (["--vary", "EXX=poly:16"], "the degree must be 0 to 15"),
    (["--vary", "EXX=poly:two"], "expected poly:DEGREE, an integer 0 to 15, got 'two'"),
    (["--vary", "EXX=poly:1", "--vary", "EXX=poly:2"], "--vary EXX: given twice"),
    (["--vary", "EXX=poly:1", "--assume-zero", "EXX"], "--vary EXX: it is also assumed zero"),
    (["--smooth", "1", "--sigma", "1um"], "--smooth: no error is fitted as a table"),
    (["--vary", "EXX=table:0,100,300", "--smooth", "1"], "--smooth weighs the tables' second differences"),
    (["--smooth", "-1"], "argument --smooth: must be at least 0"),
])
def test_bad_specs_are_refused(machine, tmp_path, capsys, args, message):
    path, m, _ = machine
    X, Y = setups()
    write_csv(tmp_path / "meas.csv", X, Y, points(X, Y, 0 * X, 0 * X, 0 * X))
    try:
        rc, _, err = cli(capsys, "identify", path, tmp_path / "meas.csv", *args)
    except SystemExit as exc:          # argparse
        rc, err = exc.code, capsys.readouterr().err
    assert rc == 2 and message in err, err
    assert "Traceback" not in err and len(err.strip().splitlines()) <= 2


def test_a_polynomial_needs_positions(machine, tmp_path, capsys):
    path, m, _ = machine
    X, Y = setups()
    X = np.full_like(X, 50.0)
    write_csv(tmp_path / "meas.csv", X, Y, points(X, Y, 0 * X, 0 * X, 0 * X))
    rc, _, err = cli(capsys, "identify", path, tmp_path / "meas.csv", "--vary", "EXX=poly:1")
    assert rc == 2 and "every set-up has X = 50 mm; a polynomial along X needs measurements" in err


def test_the_fit_size_is_bounded(machine, tmp_path, capsys, monkeypatch):
    import chaincomp.measure.identify as identify_module
    monkeypatch.setattr(identify_module, "MAX_JACOBIAN", 500)
    path, m, _ = machine
    X, Y = setups()
    write_csv(tmp_path / "meas.csv", X, Y, points(X, Y, 0 * X, 0 * X, 0 * X))
    rc, _, err = cli(capsys, "identify", path, tmp_path / "meas.csv", "--vary", "EXX=table:0,50,100,150,200,250,300")
    assert rc == 2 and "10 parameters for 64 measured coordinates: the fit's Jacobian would hold 640 numbers" in err


def test_direction_columns_need_a_tool_direction(machine, tmp_path, capsys):
    path, m, _ = machine
    (tmp_path / "meas.csv").write_text("X,Y,x,kx\n0,0,0,1\n")
    rc, _, err = cli(capsys, "identify", path, tmp_path / "meas.csv")
    assert rc == 2 and err.strip().endswith("meas.csv:1: header: column 'kx' is a measured tool direction, but "
                                            f"x_slide has no tool direction (tool: direction in {path})")


def test_minimal_ties_go_to_the_first_error_in_the_machine_file(tmp_path, capsys):
    """ECX (yaw of X) and EC0Y (squareness of Y) turn the Y travel alike: their scaled columns
    tie exactly, and the minimal set keeps whichever the machine file declares first."""
    X, Y = setups()
    for first, second in (("ECX", "EC0Y"), ("EC0Y", "ECX")):
        text = MACHINE
        if first == "EC0Y":        # declare EC0Y before ECX
            lines = text.splitlines()
            i, j = (next(k for k, s in enumerate(lines) if f"name: {n}," in s) for n in ("ECX", "EC0Y"))
            lines[i], lines[j] = lines[j], lines[i]
            text = "\n".join(lines) + "\n"
        path = tmp_path / f"{first}.yaml"
        path.write_text(text)
        write_csv(tmp_path / "meas.csv", X, Y, points(X, Y, 0 * X, 0 * X, 4 * ARCSEC + 0 * X))
        rc, out, err = cli(capsys, "identify", path, tmp_path / "meas.csv", "--minimal", "--sigma", "1um",
                           "--format", "json")
        assert rc == 0, err
        doc = json.loads(out)
        assert first in doc["estimates"] and second in doc["redundant"]
        assert doc["redundant"][second]["carried_by"] == pytest.approx({first: 1.0}, rel=1e-9)
        assert doc["estimates"][first]["value"] == pytest.approx(4 * ARCSEC, rel=1e-6)


def test_the_number_of_parameters_is_bounded(machine, tmp_path, capsys):
    path, m, _ = machine
    X, Y = setups()
    write_csv(tmp_path / "meas.csv", X, Y, points(X, Y, 0 * X, 0 * X, 0 * X))
    knots = ",".join(f"{k:g}" for k in np.linspace(0, 300, 501))
    rc, _, err = cli(capsys, "identify", path, tmp_path / "meas.csv", "--vary", f"EXX=table:{knots}",
                     "--vary", f"EYX=table:{knots}")
    assert rc == 2 and "1004 parameters to fit (errors, knots and coefficients), more than 1000" in err


def test_a_large_fit_reports_its_stages_on_stderr(machine, tmp_path, capsys, monkeypatch):
    import chaincomp.measure.identify as identify_module
    monkeypatch.setattr(identify_module, "PROGRESS_SIZE", 0)
    path, m, _ = machine
    X, Y = setups()
    write_csv(tmp_path / "meas.csv", X, Y, points(X, Y, 0 * X, 0 * X, 0 * X))
    rc, out, err = cli(capsys, "identify", path, tmp_path / "meas.csv", "--assume-zero", "EC0Y", "--sigma", "1um")
    lines = err.strip().splitlines()
    assert rc == 0 and lines[0].startswith("chaincomp identify: 3 parameters, 64 coordinates (x, y) at 32 set-ups")
    assert "rank 3; Gauss-Newton on the exact model" in lines[1] and "iteration 1: " in lines[2]
    assert "chaincomp identify:" not in out
