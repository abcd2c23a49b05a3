"""chaincomp identify's bad input: measurement files a user writes (other separators, units in the
header, cells beyond the CSV field limit, set-ups beyond the limits or where the model is not
finite), smoothing weights and sigmas beyond their bounds, empty option values."""

from __future__ import annotations

import json
import math
import os

import numpy as np
import pytest

from chaincomp.cli.main import main
from helpers import M4, M4_SQRT, ROOT, VMC, cli, m4_nominal_rows, one_error_line, refused, refused_one_line, run_in_process, write_file


def test_identify_a_cell_beyond_the_csv_field_limit_is_bad_input(tmp_path):
    p = tmp_path / "meas.csv"
    p.write_text("X,Y,Z,x\n" + "1" * 200_000 + ",0,0,0\n", encoding="utf-8")
    res = run_in_process("identify", os.path.join(ROOT, "configs", "machines", "vmc_xyz.yaml"), str(p))
    one_error_line(res, "identify", "meas.csv:2:")


# ----------------------------------------------------------------------------- identify


@pytest.mark.parametrize("weight", ["1e13", "1e200", "1e306"])
def test_identify_refuses_a_smoothing_weight_beyond_1e12(capsys, measurements, weight):
    """At 1e200 the fit printed (0.0 ± 1.0)e-100 µm, at 1e306 'nothing to identify'."""
    refused(capsys, "identify", VMC, measurements, "--minimal", "--vary", "EXX=table:-400,0,400",
             "--sigma", "1um", "--smooth", weight,
             match=f"argument --smooth: must be at least 0 and at most 1e+12, got '{weight}'")


def test_identify_at_the_smoothing_bound_still_fits_a_straight_table(tmp_path):
    """EXX a tent 0, 3, 0 um over X's knots -400, 0, 400 mm, every other error zero and held so:
    without smoothing the fit finds the tent (within 4 standard uncertainties); at the bound,
    1e12, the second difference is nil (a straight table) and every number finite."""
    from chaincomp.measure.identify import Vary, identify
    from chaincomp.measure.table import read_table
    from chaincomp.model.machine import load_machine
    p, meas = tmp_path / "p.yaml", tmp_path / "meas.csv"
    p.write_text("machine: vmc_xyz\nvalues:\n  EXX:\n    axis: X\n    units: [mm, um]\n    interpolation: linear\n"
                 "    outside: hold\n    table:\n      - [-400, 0]\n      - [0, 3]\n      - [400, 0]\n")
    assert main(["simulate-measurements", VMC, "--params", str(p), "--setups", "random:40", "--noise", "0.1um",
                 "--seed", "5", "-o", str(meas)]) == 0
    m = load_machine(VMC)
    others = tuple(s.name for s in m.errors if s.name != "EXX")
    knots = ("EXX@X=-400", "EXX@X=0", "EXX@X=400")
    vary = [Vary("EXX", "X", "table", (-400.0, 0.0, 400.0))]
    fit = identify(m, read_table(str(meas), m), others, 1e-4, vary=vary)
    v, u = (np.array([d[k] * 1e3 for k in knots]) for d in (fit.estimates, fit.uncertainties))   # um
    assert np.all(np.abs(v - [0, 3, 0]) < 4 * u), (v, u)
    fit = identify(m, read_table(str(meas), m), others, 1e-4, vary=vary, smooth=1e12)
    v = np.array([fit.estimates[k] * 1e3 for k in knots])
    assert fit.converged and np.all(np.isfinite(v)) and abs(v[0] - 2 * v[1] + v[2]) < 1e-5, v


def test_identify_api_refuses_a_smoothing_weight_beyond_1e12(measurements):
    from chaincomp.errors import ChaincompError
    from chaincomp.measure.identify import identify
    from chaincomp.measure.table import read_table
    from chaincomp.model.machine import load_machine
    m = load_machine(VMC)
    with pytest.raises(ChaincompError, match="--smooth: must be at least 0 and at most 1e"):
        identify(m, read_table(measurements, m), sigma=1e-3, smooth=1e13)


@pytest.mark.parametrize("option", ["--prefer", "--assume-zero", "--vary", "--sigma"])
@pytest.mark.parametrize("value", ["", " "])
def test_identify_refuses_an_empty_option_value(capsys, measurements, option, value):
    """--prefer '' and --assume-zero '' were ignored (exit 0, the fit as without them)."""
    refused(capsys, "identify", VMC, measurements, "--minimal", option, value,
             match=f"chaincomp identify: error: {option}: an empty value (leave the option out for its default)")

# A four-axis machine written the way a user would: X, Y, Z slides and a B table, one error block
# after each, a tool length L.


# ----------------------------------------------------------------------------- set-ups beyond the limits

def _measurements(tmp_path, rows: list[tuple]) -> str:
    text = "X,Y,Z,B,x,y,z\n" + "".join(",".join(f"{v:g}" for v in r) + "\n" for r in rows)
    return write_file(tmp_path, "meas.csv", text)


def test_identify_warns_of_set_ups_beyond_the_axis_limits(tmp_path):
    """X = 9000 mm on a machine of X in [-300, 300]: a value in another unit, most likely. The
    warning names the file, the first such line, the axis and the count; the fit still runs."""
    machine = write_file(tmp_path, "m.yaml", M4)
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
    machine = write_file(tmp_path, "m.yaml", M4)
    rows = [(x, 0, -100, b, x - 120 * math.sin(math.radians(b)), 0, -100 - 120 * math.cos(math.radians(b)))
            for x in (-300, 0, 300) for b in (-90, 0, 90)]
    proc = cli("identify", machine, _measurements(tmp_path, rows), "--assume-zero", "EXB,EAX,EYY,EBB", check=False)
    assert "outside its limits" not in proc.stderr


# ----------------------------------------------------------------------------- spreadsheet exports


@pytest.mark.parametrize("sep", [";", "\t"])
def test_identify_reads_a_semicolon_or_tab_export_as_the_comma_one(tmp_path, sep):
    """One CSV reader for every verb (model/csvtable.py): the header's separator is the file's, as
    iso230-2 and thermal read it; the cells are the comma file's, so are the set-ups and points
    (by hand in m4_nominal_rows). Before, identify alone refused such a file."""
    from chaincomp.measure.table import read_table
    from chaincomp.model.machine import load_machine
    machine = load_machine(write_file(tmp_path, "m.yaml", M4))
    rows = m4_nominal_rows()
    got = read_table(write_file(tmp_path, "meas.csv", sep.join("X Y Z B x y z".split()) + "\n"
                                + "".join(sep.join(r) + "\n" for r in rows)), machine)
    assert got.axes["X"].tolist() == [float(r[0]) for r in rows]
    assert got.coords[:, 0].tolist() == [float(r[4]) for r in rows]
    assert got.coords[:, 2].tolist() == [float(r[6]) for r in rows]


def test_identify_a_csv_separated_by_bars_says_so(tmp_path):
    """Before: unknown column 'X|Y|Z|B|x|y|z' (expected the axes X, Y, Z, B and ...)."""
    text = "|".join("X Y Z B x y z".split()) + "\n" + "".join("|".join(r) + "\n" for r in m4_nominal_rows())
    path = write_file(tmp_path, "meas.csv", text)
    refused_one_line("identify", write_file(tmp_path, "m.yaml", M4), path,
             match=f"meas.csv:1: header: the header is one cell {text.splitlines()[0]!r}: columns are separated by "
                   "commas, semicolons or tabs, not '|'")


def test_identify_units_in_the_header_are_refused_with_the_unit_it_reads(tmp_path):
    """A header 'X [m]' would have been read in the machine's mm had it been accepted; it is
    refused, naming the unit identify reads the column in."""
    text = "X [m],Y,Z,B,x,y,z\n" + "".join(",".join(r) + "\n" for r in m4_nominal_rows())
    path = write_file(tmp_path, "meas.csv", text)
    refused_one_line("identify", write_file(tmp_path, "m.yaml", M4), path,
             match="meas.csv:1: header: column 'X [m]': the header holds names only, no units; X is read in its "
                   "declared unit (mm): write 'X' and its values in that unit")
    text = "X,Y,Z,B,x (mm),y,z\n" + "".join(",".join(r) + "\n" for r in m4_nominal_rows())
    refused_one_line("identify", write_file(tmp_path, "m.yaml", M4), write_file(tmp_path, "meas.csv", text),
             match="column 'x (mm)': the header holds names only, no units; x is read in the machine's length "
                   "unit (mm)")


# ----------------------------------------------------------------------------- identify --sigma

def test_identify_a_sigma_whose_weight_overflows_is_refused(tmp_path):
    """--sigma 1e-200um: 1/sigma^2 is beyond a double, and the fit said 'none of the 6 parameters
    fitted moves the 15 coordinates: nothing to identify', which is false (they all do)."""
    machine = write_file(tmp_path, "m.yaml", M4)
    meas = write_file(tmp_path, "meas.csv", "X,Y,Z,B,x,y,z\n" + "".join(",".join(r) + "\n" for r in m4_nominal_rows()))
    refused_one_line("identify", machine, meas, "--sigma", "1e-200um",
             match="--sigma: '1e-200um' is below 1e-30 mm: the weights 1/sigma^2 would leave a double's range")
    refused_one_line("identify", machine, meas, "--sigma", "1um,x=1e-40m", match="--sigma: '1e-40m' is below 1e-30 mm")


# ----------------------------------------------------------------------------- a model outside its domain

# m4 with a tool length that needs X above -400 mm (sqrt): finite within X's limits, as the loader
# checks, but not at a set-up written beyond them


def test_identify_names_the_set_up_where_the_model_is_not_finite(tmp_path):
    """Before: 'the fit went to non-finite values on these 15 coordinates ... (coordinates in mm?
    axes in their declared units?)', naming no row, though the model fails before any fit."""
    machine = write_file(tmp_path, "m.yaml", M4_SQRT)
    rows = m4_nominal_rows()
    rows[2][0] = "-500"
    meas = write_file(tmp_path, "meas.csv", "# a comment\nX,Y,Z,B,x,y,z\n" + "".join(",".join(r) + "\n" for r in rows))
    proc = cli("identify", machine, meas, check=False)
    assert proc.returncode == 2
    assert (f"error: {meas}:5: the model's tool pose is not finite at this set-up (X = -500 mm, Y = 10 mm, "
            "Z = -100 mm, B = 90 deg) with every error zero (1 set-up of 5): the machine's expressions leave their "
            "domain there") in proc.stderr


def test_identify_a_column_in_another_unit_is_named_as_the_likely_cause(tmp_path):
    """B written in rad where the machine declares deg: every B is inside the limits, so no
    warning; the fit cannot converge (the model puts the tool 100 mm away), and the message
    now says what such a residual usually is."""
    machine = write_file(tmp_path, "m.yaml", M4)
    rows = m4_nominal_rows()
    for r in rows:
        r[3] = repr(math.radians(float(r[3])))
    meas = write_file(tmp_path, "meas.csv", "X,Y,Z,B,x,y,z\n" + "".join(",".join(r) + "\n" for r in rows))
    # a fit without an answer is exit 4, apart from bad input (2); in JSON mode stdout holds the error
    proc = cli("identify", machine, meas, "--assume-zero", "EXB,EBB", check=False)
    assert proc.returncode == 4 and proc.stderr.count("\n") == 1, (proc.returncode, proc.stderr)
    err = proc.stderr
    assert "the fit did not converge" in err and "Traceback" not in err
    proc = cli("identify", machine, meas, "--assume-zero", "EXB,EBB", "--format", "json", check=False)
    got = json.loads(proc.stdout)["error"]
    assert proc.returncode == 4 and got["exit"] == 4 and got["kind"] == "no answer"
    assert "the fit did not converge" in got["message"]
    assert ("a residual this large is most often a column in another unit (the axes are read in their declared "
            "units, X in mm, Y in mm, Z in mm, B in deg; x, y, z in mm)") in err
