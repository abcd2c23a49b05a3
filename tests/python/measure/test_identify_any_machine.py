"""Calibration on machines with linear axes: ``identify`` and ``simulate-measurements`` on
five_axis_ac (axes X, Y, Z, Ap, Cp next to the coordinates x, y, z) and on a three-axis
machine written here.

The truth comes from outside the code: each machine's tool point is an HTM product written
in numpy below from the chain as the machine file states it; the measurements identify fits
are written by this file from that product; which errors are identifiable comes from this
file's own central-difference Jacobian of that product (rank and null space by SVD), and
the subset of errors fitted in the exact-recovery tests is picked here (machine order,
keeping each error that raises the rank), not taken from identify's suggestion.
"""

import itertools
import json
import math

import numpy as np
import pytest

from chaincomp import load_machine, load_params
from chaincomp.cli.main import main
from chaincomp.measure.lsq import chi2_quantile

from arm_models import block, rx, ry, rz, tr
from helpers import machine_path

FIVE = machine_path("five_axis_ac")
UM, ARCSEC, DEG = 1e-3, math.pi / 180 / 3600, math.pi / 180      # to mm, rad


# ----------------------------------------------------------------- independent HTM products

def point(*matrices):
    """Leftmost matrix first, applied to the tool point (the origin) from the right."""
    m = matrices[0]
    for x in matrices[1:]:
        m = m @ x
    return m[..., :3, 3]


def five_axis_points(a, e):
    """five_axis_ac's tool point; a: axes, e: errors, internal units (mm, rad), arrays broadcast.
    Left-handed rotations (the head's main ones) are right-handed by the opposite angle."""
    G, Yp, ee = 150.0, 50 * DEG, 10.0
    X, Y, Z, Ap, Cp = (a[k] for k in ("X", "Y", "Z", "Ap", "Cp"))
    return point(
        tr(X, 0, 0), block(e["EXX"], e["EYX"], e["EZX"], e["EAX"], e["EBX"], e["ECX"]),
        tr(-Y * np.sin(e["EC0Y"]), Y * np.cos(e["EC0Y"]), 0),
        block(e["EXY"], e["EYY"], e["EZY"], e["EAY"], e["EBY"], e["ECY"]),
        tr(Z * np.cos(e["EA0Z"]) * np.sin(e["EB0Z"]), -Z * np.sin(e["EA0Z"]), Z * np.cos(e["EA0Z"]) * np.cos(e["EB0Z"])),
        block(e["EXZ"], e["EYZ"], e["EZZ"], e["EAZ"], e["EBZ"], e["ECZ"]),
        rx(e["ThetaCv"]), ry(e["ThetaCh"]), rz(Cp), tr(0, -ee, -ee / math.tan(Yp)), tr(e["Ocx"], e["Ocy"], 0),
        rx(-Yp), rz(-Ap), ry(e["ThetaAv"]), rx(-e["DY"]), rx(Yp), tr(0, e["Oas"], 0), ry(-e["ThetaAs"]),
        tr(0, 0, -G))


THREE_AXIS = """\
name: xyz_mill
description: three slides, constant slide errors, squareness and a tool offset
length_unit: mm
rotation_sense: right_hand
symbols:
  - {name: X, role: axis, unit: mm, limits: [0, 500], meaning: X slide}
  - {name: Y, role: axis, unit: mm, limits: [-200, 200], meaning: Y slide}
  - {name: Z, role: axis, unit: mm, limits: [-300, 0], meaning: Z ram}
  - {name: L, role: constant, unit: mm, nominal: 120, meaning: tool length}
  - {name: EAX, role: error, unit: arcsec, meaning: X roll}
  - {name: EBX, role: error, unit: arcsec, meaning: X pitch}
  - {name: ECX, role: error, unit: arcsec, meaning: X yaw}
  - {name: EC0Y, role: error, unit: arcsec, meaning: squareness of Y to X}
  - {name: EB0Z, role: error, unit: arcsec, meaning: squareness of Z to X}
  - {name: EA0Z, role: error, unit: arcsec, meaning: squareness of Z to Y}
  - {name: Tx, role: error, unit: um, meaning: tool offset in x}
  - {name: Ty, role: error, unit: um, meaning: tool offset in y}
  - {name: Tz, role: error, unit: um, meaning: tool length error}
chain:
  - {translate: [X, 0, 0]}
  - {rotate: x, angle: EAX}
  - {rotate: y, angle: EBX}
  - {rotate: z, angle: ECX}
  - {translate: [-Y*sin(EC0Y), Y*cos(EC0Y), 0]}
  - {translate: [Z*cos(EA0Z)*sin(EB0Z), -Z*sin(EA0Z), Z*cos(EA0Z)*cos(EB0Z)]}
  - {translate: [Tx, Ty, -L + Tz]}
tool:
  point: [0, 0, 0]
"""


def three_axis_points(a, e):
    X, Y, Z = a["X"], a["Y"], a["Z"]
    return point(tr(X, 0, 0), rx(e["EAX"]), ry(e["EBX"]), rz(e["ECX"]),
                 tr(-Y * np.sin(e["EC0Y"]), Y * np.cos(e["EC0Y"]), 0),
                 tr(Z * np.cos(e["EA0Z"]) * np.sin(e["EB0Z"]), -Z * np.sin(e["EA0Z"]), Z * np.cos(e["EA0Z"]) * np.cos(e["EB0Z"])),
                 tr(e["Tx"], e["Ty"], -120.0 + e["Tz"]))


@pytest.fixture
def three_axis(tmp_path):
    path = tmp_path / "xyz_mill.yaml"
    path.write_text(THREE_AXIS)
    return str(path)


# ----------------------------------------------------------------- the test's own analysis

def internal(m, name):
    return {"um": UM, "mm": 1.0, "arcsec": ARCSEC, "deg": DEG}[m.symbol(name).unit.name]


def zero_errors(m, rows=1):
    return {s.name: np.zeros(rows) for s in m.errors}


def random_setups(m, rng, n):
    """Axis values: declared units (to write) and internal units (to evaluate)."""
    declared = {s.name: np.round(rng.uniform(*s.limits, n), 6) for s in m.axes}
    return declared, {k: v * internal(m, k) for k, v in declared.items()}


def own_analysis(m, model, axes, names):
    """Rank, unidentifiable errors and a spanning subset from this file's Jacobian (central
    differences of the numpy product, columns scaled to unit norm)."""
    rows = len(next(iter(axes.values())))
    cols = []
    for name in names:
        plus, minus = zero_errors(m, rows), zero_errors(m, rows)
        plus[name] += 1e-6
        minus[name] -= 1e-6
        cols.append(((model(axes, plus) - model(axes, minus)) / 2e-6).ravel())
    j = np.array(cols).T
    j = j / np.linalg.norm(j, axis=0)
    _, s, vt = np.linalg.svd(j, full_matrices=False)
    rank = int((s > 1e-6 * s[0]).sum())      # the gap is from ~1e-1 to ~1e-9 (difference noise)
    null = vt[rank:]
    unident = {n for k, n in enumerate(names) if (null[:, k] ** 2).sum() > 1e-6}
    kept = []
    for k, n in enumerate(names):            # machine order, each error that raises the rank
        if np.linalg.matrix_rank(j[:, [names.index(x) for x in kept] + [k]], tol=1e-6) > len(kept):
            kept.append(n)
    return rank, unident, kept


def write_csv(path, m, declared, coords, measure="xyz"):
    """A measurement file as an engineer would write it: axes as in the machine file, x, y, z."""
    names = [s.name for s in m.axes]
    lines = ["# written by the test", ",".join(names + list(measure))]
    idx = ["xyz".index(c) for c in measure]
    for r in range(len(coords)):
        lines.append(",".join([repr(float(declared[a][r])) for a in names] + [repr(float(coords[r, i])) for i in idx]))
    path.write_text("\n".join(lines) + "\n")


def cli(capsys, *args):
    rc = main([str(a) for a in args])
    out, err = capsys.readouterr()
    return rc, out, err


def fit_json(capsys, *args):
    rc, out, err = cli(capsys, "identify", *args, "--format", "json")
    assert rc == 0, err
    return json.loads(out, parse_constant=lambda c: pytest.fail(f"{c} in the JSON"))


def declared_value(m, doc, name, key="value"):
    """An estimate of identify's JSON (internal units, named beside it) in the error's declared unit."""
    est = doc["estimates"][name]
    assert est["unit"] == {"length": "mm", "angle": "rad", "ratio": "1"}[m.symbol(name).unit.kind]
    return est[key] / m.symbol(name).unit.to_internal


def injected(m, rng, names):
    """Errors in declared units (offsets ~5 µm, angles ~20 arcsec) on ``names``, zero elsewhere."""
    return {s.name: float(rng.normal() * (20.0 if s.unit.kind == "angle" else 5.0 * UM / internal(m, s.name)))
            if s.name in names else 0.0 for s in m.errors}


def in_internal(m, values):
    return {k: v * internal(m, k) for k, v in values.items()}


def write_params(path, m, values):
    lines = [f"machine: {m.name}", "values:"] + [f'  {k}: "{v!r} {m.symbol(k).unit.name}"' for k, v in values.items()]
    path.write_text("\n".join(lines) + "\n")


# ----------------------------------------------------------------- five_axis_ac

def test_simulated_measurements_match_the_independent_product(tmp_path, capsys):
    """Default set-ups vary every axis: linear axes at both limits and mid-range, Ap (190 deg
    of travel) likewise, Cp (two turns) over the quarter turns."""
    m = load_machine(FIVE)
    truth = injected(m, np.random.default_rng(7), [s.name for s in m.errors])
    write_params(tmp_path / "truth.yaml", m, truth)
    rc, _, err = cli(capsys, "simulate-measurements", FIVE, "--params", tmp_path / "truth.yaml",
                     "-o", tmp_path / "vm.csv")
    assert rc == 0, err
    rows = [r for r in (tmp_path / "vm.csv").read_text().splitlines() if not r.startswith("#")]
    assert rows[0] == "X,Y,Z,Ap,Cp,x,y,z"
    data = np.array([[float(c) for c in r.split(",")] for r in rows[1:]])
    levels = [(-400, 0, 400), (-300, 0, 300), (-400, -200, 0), (-95, 0, 95), (0, 90, 180, 270)]
    assert sorted(map(tuple, data[:, :5].tolist())) == sorted(itertools.product(*levels))
    axes = {s.name: data[:, i] * internal(m, s.name) for i, s in enumerate(m.axes)}
    expected = five_axis_points(axes, in_internal(m, truth))
    np.testing.assert_allclose(data[:, 5:], expected, rtol=0, atol=1e-9)


@pytest.fixture(scope="module")
def five_setups():
    m = load_machine(FIVE)
    declared, axes = random_setups(m, np.random.default_rng(11), 40)
    names = [s.name for s in m.errors]
    return m, declared, axes, own_analysis(m, five_axis_points, axes, names)


def test_identifiable_errors_as_an_independent_rank_analysis_finds_them(tmp_path, capsys, five_setups):
    """All 29 errors injected, a laser tracker's x, y, z at 40 random set-ups over all five axes:
    identify reports exactly the errors this file's null space touches, gives them no value,
    and recovers the others to first order (the inseparable ones, left at their minimum-norm
    split, add second-order terms); its suggested assume-zero set leaves a full-rank rest."""
    m, declared, axes, (rank, unident, _) = five_setups
    names = [s.name for s in m.errors]
    assert 0 < rank < len(names) and unident and set(names) - unident      # both kinds exist
    truth = injected(m, np.random.default_rng(12), names)
    write_csv(tmp_path / "meas.csv", m, declared, five_axis_points(axes, in_internal(m, truth)))
    doc = fit_json(capsys, FIVE, tmp_path / "meas.csv", "-o", tmp_path / "fit.yaml")
    assert doc["rank"] == rank
    assert set(doc["unidentifiable"]) == unident
    assert set(doc["estimates"]) == set(names) - unident
    for name in doc["estimates"]:
        assert declared_value(m, doc, name) == pytest.approx(truth[name], rel=1e-3), name
    assert not unident & set(load_params(str(tmp_path / "fit.yaml"), m))
    suggested = doc["suggested_assume_zero"]
    rest = [n for n in names if n not in suggested]
    assert len(rest) == rank and own_analysis(m, five_axis_points, axes, rest)[0] == rank


def test_noise_free_recovery_to_1e9_on_five_axis_ac(tmp_path, capsys, five_setups):
    """The errors of a spanning subset (picked here) injected, the others assumed zero: every
    fitted error is identifiable and recovered to 1e-9 relative, through the params file too."""
    m, declared, axes, (rank, _, kept) = five_setups
    assert len(kept) == rank
    truth = injected(m, np.random.default_rng(13), kept)
    write_csv(tmp_path / "meas.csv", m, declared, five_axis_points(axes, in_internal(m, truth)))
    zero = [s.name for s in m.errors if s.name not in kept]
    doc = fit_json(capsys, FIVE, tmp_path / "meas.csv", "--assume-zero", ",".join(zero), "-o", tmp_path / "fit.yaml")
    assert doc["converged"] and doc["unidentifiable"] == {} and doc["suggested_assume_zero"] == []
    assert set(doc["estimates"]) == set(kept)
    for name in kept:
        assert abs(declared_value(m, doc, name) - truth[name]) <= 1e-9 * abs(truth[name]), name
    loaded = load_params(str(tmp_path / "fit.yaml"), m)
    for name in kept:
        assert loaded[name] == pytest.approx(truth[name] * internal(m, name), rel=1e-9)
    assert all(loaded[n] == 0 for n in zero)


def test_identifiable_errors_alone_are_recovered_without_assumptions(tmp_path, capsys, five_setups):
    """Only the errors that are identifiable among all 29 injected: the fit of all 29 returns
    them to 1e-9 (nothing lies in the directions it cannot see) and values no other."""
    m, declared, axes, (_, unident, _) = five_setups
    ident = [s.name for s in m.errors if s.name not in unident]
    truth = injected(m, np.random.default_rng(14), ident)
    write_csv(tmp_path / "meas.csv", m, declared, five_axis_points(axes, in_internal(m, truth)))
    doc = fit_json(capsys, FIVE, tmp_path / "meas.csv")
    assert set(doc["estimates"]) == set(ident)
    for name in ident:
        assert abs(declared_value(m, doc, name) - truth[name]) <= 1e-9 * abs(truth[name]), name


def test_noisy_five_axis_estimates_within_their_uncertainty(tmp_path, capsys, five_setups):
    m, declared, axes, (_, _, kept) = five_setups
    rng = np.random.default_rng(15)
    truth = injected(m, rng, kept)
    coords = five_axis_points(axes, in_internal(m, truth)) + 1e-3 * rng.standard_normal((40, 3))
    write_csv(tmp_path / "meas.csv", m, declared, coords)
    zero = [s.name for s in m.errors if s.name not in kept]
    doc = fit_json(capsys, FIVE, tmp_path / "meas.csv", "--assume-zero", ",".join(zero), "--sigma", "1um")
    for name in kept:
        u = declared_value(m, doc, name, "uncertainty")
        assert 0 < u and abs(declared_value(m, doc, name) - truth[name]) <= 4.5 * u, name


def test_chi2_quantile_against_the_table():
    """The 99.9 % points of chi-square (NIST/SEMATECH e-Handbook, table 1.3.6.7.4)."""
    for dof, table in ((1, 10.828), (5, 20.515), (10, 29.588), (30, 59.703), (100, 149.449)):
        assert chi2_quantile(0.999, dof) == pytest.approx(table, abs=1e-3)


def test_a_fit_that_does_not_fit_is_named(tmp_path, capsys, five_setups):
    """1 um of noise: with --sigma 1um chi2/dof is about 1 and nothing is said; told 0.2 um, chi2/dof
    is about 25, beyond its 99.9 % quantile: a warning (and the JSON's misfit) naming the set-ups with
    the largest residuals, and under --strict exit 1 with nothing written. One set-up 30 um off is
    named first."""
    m, declared, axes, (_, _, kept) = five_setups
    rng = np.random.default_rng(15)
    truth = injected(m, rng, kept)
    coords = five_axis_points(axes, in_internal(m, truth)) + 1e-3 * rng.standard_normal((40, 3))
    write_csv(tmp_path / "meas.csv", m, declared, coords)
    zero = ["--assume-zero", ",".join(s.name for s in m.errors if s.name not in kept)]
    rc, out, err = cli(capsys, "identify", FIVE, tmp_path / "meas.csv", *zero, "--sigma", "1um", "--format", "json")
    assert rc == 0 and "warning" not in err and json.loads(out)["misfit"] is None, err
    rc, out, err = cli(capsys, "identify", FIVE, tmp_path / "meas.csv", *zero, "--sigma", "0.2um", "--format", "json")
    doc = json.loads(out)
    assert rc == 0 and 15 < doc["chi2_per_dof"] < 40 and "beyond its 99.9% quantile" in doc["misfit"]
    assert err.count("warning: chi2/dof") == 1 and "the largest residuals: line " in err
    rc, out, err = cli(capsys, "identify", FIVE, tmp_path / "meas.csv", *zero, "--sigma", "0.2um", "--strict",
                       "-o", tmp_path / "p.yaml")
    assert rc == 1 and "--strict: no values given" in err and not (tmp_path / "p.yaml").exists()
    # an outlier: one set-up 30 um off in x is the first named
    coords[7, 0] += 0.030
    write_csv(tmp_path / "meas.csv", m, declared, coords)
    rc, out, err = cli(capsys, "identify", FIVE, tmp_path / "meas.csv", *zero, "--sigma", "1um")
    lines = (tmp_path / "meas.csv").read_text().splitlines()
    row7 = next(i for i, text in enumerate(lines) if not text.startswith("#")) + 2 + 7  # header, then rows
    assert rc == 0 and f"the largest residuals: line {row7} (" in err, err


# ----------------------------------------------------------------- a three-axis machine

def test_three_axis_machine_default_setups_and_recovery(tmp_path, capsys, three_axis):
    m = load_machine(three_axis)
    rc, _, err = cli(capsys, "simulate-measurements", three_axis, "-o", tmp_path / "auto.csv")
    assert rc == 0, err
    rows = [r for r in (tmp_path / "auto.csv").read_text().splitlines() if not r.startswith("#")]
    assert rows[0] == "X,Y,Z,x,y,z"
    got = sorted(tuple(float(c) for c in r.split(",")[:3]) for r in rows[1:])
    assert got == sorted(itertools.product((0, 250, 500), (-200, 0, 200), (-300, -150, 0)))
    # a grid turns rotary axes: refused here rather than one set-up at the origin
    rc, _, err = cli(capsys, "simulate-measurements", three_axis, "--setups", "grid:0,90", "-o", tmp_path / "g.csv")
    assert rc == 2 and "xyz_mill has none" in err and "use auto or random:N" in err
    assert not (tmp_path / "g.csv").exists()

    declared = {k: np.array([float(r.split(",")[i]) for r in rows[1:]]) for i, k in enumerate("XYZ")}
    names = [s.name for s in m.errors]
    rank, unident, kept = own_analysis(m, three_axis_points, declared, names)
    truth = injected(m, np.random.default_rng(21), names)
    write_csv(tmp_path / "all.csv", m, declared, three_axis_points(declared, in_internal(m, truth)))
    doc = fit_json(capsys, three_axis, tmp_path / "all.csv")
    assert doc["rank"] == rank and set(doc["unidentifiable"]) == unident and unident
    truth = injected(m, np.random.default_rng(22), kept)
    write_csv(tmp_path / "kept.csv", m, declared, three_axis_points(declared, in_internal(m, truth)))
    zero = [n for n in names if n not in kept]
    doc = fit_json(capsys, three_axis, tmp_path / "kept.csv", "--assume-zero", ",".join(zero))
    assert doc["unidentifiable"] == {} and set(doc["estimates"]) == set(kept)
    for name in kept:
        assert abs(declared_value(m, doc, name) - truth[name]) <= 1e-9 * abs(truth[name]), name


# ----------------------------------------------------------------- columns and refusals

def refused(capsys, *args):
    rc, out, err = cli(capsys, *args)
    assert rc == 2 and out == "" and len(err.strip().splitlines()) == 1 and "Traceback" not in err, (rc, out, err)
    return err.strip()


def test_columns_are_matched_exactly(tmp_path, capsys):
    path = tmp_path / "m.csv"
    path.write_text("X,Y,Z,ap,Cp,x\n0,0,0,0,0,1\n")
    assert refused(capsys, "identify", FIVE, path).endswith(
        "m.csv:1: header: unknown column 'ap' (expected the axes X, Y, Z, Ap, Cp and measured coordinates "
        "x, y, z, kx, ky, kz); names are case-sensitive: did you mean 'Ap'?")
    path.write_text("X,Y,Z,Ap,Cp,X\n0,0,0,0,0,1\n")
    assert "m.csv:1: two columns named 'X' (columns 1 and 6)" in refused(capsys, "identify", FIVE, path)
    # a spreadsheet's byte-order mark is not part of the first column's name
    m = load_machine(FIVE)
    declared, axes = random_setups(m, np.random.default_rng(5), 20)
    write_csv(path, m, declared, five_axis_points(axes, zero_errors(m)))
    path.write_text("\ufeff" + path.read_text().split("\n", 1)[1])      # drop the comment, add the mark
    assert fit_json(capsys, FIVE, path)["setups"] == 20


def test_an_axis_named_like_a_coordinate_is_reported_with_both_meanings(tmp_path, capsys):
    machine = tmp_path / "lower.yaml"
    machine.write_text(THREE_AXIS.replace("name: X,", "name: x,").replace("[X, 0, 0]", "[x, 0, 0]"))
    (tmp_path / "m.csv").write_text("x,Y,Z,y\n0,0,0,1\n")
    err = refused(capsys, "identify", machine, tmp_path / "m.csv")
    assert err.endswith(f"m.csv:1: header: column 'x' is ambiguous: it is both the axis x ({machine}:6) and "
                        "the measured tool-tip coordinate x; rename the axis in the machine file")
    err = refused(capsys, "simulate-measurements", machine, "-o", tmp_path / "s.csv")
    assert f"{machine}:6: symbols: axis 'x' has the name of the measured coordinate x" in err


def test_a_single_measured_coordinate_identifies_nothing_and_writes_nothing(tmp_path, capsys):
    head = machine_path("angle_head")
    (tmp_path / "one.csv").write_text("Ap,Cp,x\n90,0,15\n")
    err = refused(capsys, "identify", head, tmp_path / "one.csv", "-o", tmp_path / "p.yaml")
    assert "no error can be identified from these 1 coordinate (x) at 1 set-up" in err
    assert not (tmp_path / "p.yaml").exists()
    # as many data as independent unknowns: no redundancy for the uncertainty without --sigma
    (tmp_path / "two.csv").write_text("Ap,Cp,z\n0,0,-28\n0,90,-28\n")
    err = refused(capsys, "identify", head, tmp_path / "two.csv", "-o", tmp_path / "p.yaml")
    assert "no redundancy" in err and "--sigma" in err and not (tmp_path / "p.yaml").exists()


@pytest.mark.parametrize("args, message", [
    (("--sigma", "0um"), "--sigma: must be positive, got '0um'"),
    (("--sigma=-1um",), "--sigma: must be positive, got '-1um'"),
    (("--sigma", "nan"), "--sigma: "),
    (("--sigma", "1 deg"), "--sigma gives an angle, the standard uncertainty of the measured tool direction "
                           "or orientation, but the measurements have no kx, ky, kz (or qw, qx, qy, qz) column"),
    (("--sigma", "1 ppm"), "--sigma: unit 'ppm' is a ratio unit"),
    (("--assume-zero", "X"), "--assume-zero: 'X' is an axis, not an error"),
])
def test_identify_options_are_validated(tmp_path, capsys, args, message):
    (tmp_path / "m.csv").write_text("X,Y,Z,Ap,Cp,x,y,z\n0,0,0,0,0,0,-10,-158\n")
    assert message in refused(capsys, "identify", FIVE, tmp_path / "m.csv", *args)


def test_identify_refuses_unreadable_input_and_an_output_that_is_an_input(tmp_path, capsys):
    meas = tmp_path / "m.csv"
    meas.write_bytes(b"X,Y,Z,Ap,Cp,z\n0,0,0,0,0,-158\n0,0,0,0,90,\xff\n")
    assert refused(capsys, "identify", FIVE, meas).endswith("m.csv:3: not UTF-8 text (byte 0xff)")
    meas.write_text("X,Y,Z,Ap,Cp,z\n0,0,0,0,0,1e300\n")
    assert "m.csv:2: z: expected a number of magnitude at most 1e+15, got '1e300'" in refused(
        capsys, "identify", FIVE, meas)
    before = "X,Y,Z,Ap,Cp,z\n0,0,0,0,0,-158\n0,0,0,0,90,-158\n0,0,0,90,0,-150\n"
    meas.write_text(before)
    assert "is also an input" in refused(capsys, "identify", FIVE, meas, "-o", meas)
    assert meas.read_text() == before
    assert "is also an input" in refused(capsys, "identify", FIVE, meas, "-o", FIVE)


@pytest.mark.parametrize("args, message", [
    (("--seed", "-1"), "--seed: must be between 0 and"),
    (("--setups", "random:0"), "--setups: expected random:N with 1 <= N <= 20000"),
    (("--setups", "random:many"), "--setups: expected random:N"),
    (("--setups", "grid:"), "--setups: expected 'auto', 'grid:A,B,...', 'random:N'"),
    (("--setups", "grid:0,nan"), "--setups: expected a finite number"),
    (("--setups", "grid:500"), "no value within Ap's limits [-95, 95]"),
    (("--set", "X=9999"), "--set X: 9999 mm is outside the axis' limits [-400, 400]"),
    (("--set", "G=1"), "--set: 'G' is not an axis"),
    (("--measure", "x,x"), "--measure: 'x' named twice"),
    (("--noise=-1um",), "--noise: must be zero or positive"),
])
def test_simulate_options_are_validated(tmp_path, capsys, args, message):
    assert message in refused(capsys, "simulate-measurements", FIVE, *args, "-o", tmp_path / "s.csv")
    assert not (tmp_path / "s.csv").exists()


def test_simulate_refuses_to_overwrite_its_inputs(tmp_path, capsys):
    setups = tmp_path / "setups.csv"
    setups.write_text("X,Y,Z,Ap,Cp\n0,0,0,0,0\n")
    assert "is also an input" in refused(capsys, "simulate-measurements", FIVE, "--setups", setups, "-o", setups)
    assert setups.read_text() == "X,Y,Z,Ap,Cp\n0,0,0,0,0\n"


ATAN2 = """\
name: atan_mill
description: a slide and a table with a tilt whose angle enters through atan2
length_unit: mm
rotation_sense: right_hand
symbols:
  - {name: X, role: axis, unit: mm, limits: [-100, 100], meaning: X slide}
  - {name: C, role: axis, unit: deg, limits: [-360, 360], meaning: table}
  - {name: Ed, role: error, unit: um, meaning: offset in y}
  - {name: Eh, role: error, unit: um, meaning: rise of a 100 mm tilt lever}
  - {name: Ex, role: error, unit: um, meaning: offset in x}
chain:
  - {translate: [X + Ex, 0, 0]}
  - {rotate: z, angle: C}
  - {rotate: y, angle: "atan2(Eh, 100)"}
  - {translate: [80, Ed, 50]}
tool:
  point: [0, 0, 0]
"""


def test_an_error_inside_atan2_is_fitted_too(tmp_path, capsys):
    """numpy has no complex arctan2, so the complex-step Jacobian cannot run through this chain:
    the fit takes central differences instead and still recovers the errors."""
    path = tmp_path / "atan.yaml"
    path.write_text(ATAN2)
    m = load_machine(str(path))
    declared, axes = random_setups(m, np.random.default_rng(31), 12)
    truth = {"Ed": 3.0, "Eh": 7.0, "Ex": -4.0}
    e = in_internal(m, truth)
    coords = point(tr(axes["X"] + e["Ex"], 0, 0), rz(axes["C"]), ry(math.atan2(e["Eh"], 100.0)), tr(80.0, e["Ed"], 50.0))
    write_csv(tmp_path / "meas.csv", m, declared, coords)
    doc = fit_json(capsys, path, tmp_path / "meas.csv")
    for name, value in truth.items():
        assert declared_value(m, doc, name) == pytest.approx(value, rel=1e-9), name
