"""Errors that vary along an axis: tables and polynomials in params files, their interpolants
against independent numpy implementations written here, the CLI (eval, plot,
simulate-calibration), bad files (exit 2, or chaincompd refusing to start, with file, line and
key), and compensation through the compiled code checked against an independent HTM product."""

import csv
import json
import math
import os
import subprocess
import sys

import numpy as np
import pytest
import yaml

from helpers import DAEMON, PARAMS, ROOT, cli, machine_path, needs_netns, run_cli

FIVE = machine_path("five_axis_ac")
LASER = os.path.join(PARAMS, "five_axis_ac-laser.yaml")
DEMO = os.path.join(PARAMS, "five_axis_ac-demo.yaml")
REPLAY = os.path.join(ROOT, "build", "bin", "chaincomp_replay")
E2E_CONFIG = os.path.join(ROOT, "tests", "e2e", "config_test.yaml")
ARCSEC = math.pi / 648000.0
TO_INTERNAL = {"mm": 1.0, "um": 1e-3, "µm": 1e-3, "nm": 1e-6, "m": 1000.0, "in": 25.4, "rad": 1.0,
               "deg": math.pi / 180.0, "arcsec": ARCSEC, "mrad": 1e-3, "urad": 1e-6}


# ----------------------------------------------------------------------------- an independent PCHIP

def pchip_reference(x, y, t):
    """Monotone piecewise cubic Hermite interpolation (Fritsch & Carlson 1980; the slopes as
    Fritsch & Butland 1984 and Moler's pchip): at an interior knot the weighted harmonic mean
    of the neighbouring secant slopes when they have the same sign, else 0; at the ends the
    three-point formula, set to 0 if its sign differs from the first secant and limited to 3
    times that secant when the first two secants differ in sign. Held outside [x0, xn]."""
    x = np.asarray(x, float)
    y = np.asarray(y, float)
    n = len(x)
    h = x[1:] - x[:-1]
    delta = (y[1:] - y[:-1]) / h
    slopes = np.empty(n)
    if n == 2:
        slopes[:] = delta[0]
    else:
        for k in range(1, n - 1):
            a, b = delta[k - 1], delta[k]
            if a * b > 0:
                w1, w2 = 2 * h[k] + h[k - 1], h[k] + 2 * h[k - 1]
                slopes[k] = (w1 + w2) / (w1 / a + w2 / b)
            else:
                slopes[k] = 0.0
        for end, (h0, h1, d0, d1) in ((0, (h[0], h[1], delta[0], delta[1])),
                                      (n - 1, (h[-1], h[-2], delta[-1], delta[-2]))):
            s = ((2 * h0 + h1) * d0 - h0 * d1) / (h0 + h1)
            if np.sign(s) != np.sign(d0):
                s = 0.0
            elif np.sign(d0) != np.sign(d1) and abs(s) > 3 * abs(d0):
                s = 3 * d0
            slopes[end] = s
    t = np.clip(np.asarray(t, float), x[0], x[-1])
    k = np.clip(np.searchsorted(x, t) - 1, 0, n - 2)
    u = (t - x[k]) / h[k]
    # Hermite basis on [x_k, x_k+1]
    return ((1 + 2 * u) * (1 - u) ** 2 * y[k] + u * (1 - u) ** 2 * h[k] * slopes[k]
            + u ** 2 * (3 - 2 * u) * y[k + 1] + u ** 2 * (u - 1) * h[k] * slopes[k + 1])


def _table(x, y, interpolation, outside="hold"):
    from chaincomp import load_machine
    from chaincomp.model.varying import parse_varying
    node = dict(axis="X", units=["mm", "um"], interpolation=interpolation, outside=outside,
                table=[[float(a), float(b)] for a, b in zip(x, y)])
    return parse_varying(node, "EXX", "test.yaml", 1, load_machine(FIVE))


def _random_table(seed, n=25):
    rng = np.random.default_rng(seed)
    x = np.cumsum(rng.uniform(0.5, 20.0, n)) - 200.0
    y = np.cumsum(rng.normal(0, 1.5, n))
    return x, y


# ----------------------------------------------------------------------------- interpolants

@pytest.mark.parametrize("interpolation", ["linear", "monotone_cubic"])
def test_tables_are_exact_at_their_knots(interpolation):
    for seed in range(5):
        x, y = _random_table(seed)
        t = _table(x, y, interpolation)
        got = t(x * 1.0)  # positions in mm are internal already
        assert np.array_equal(got, y * 1e-3), seed
        for xi, yi in zip(x, y):  # one at a time, and in 40-digit arithmetic
            assert t(float(xi)) == yi * 1e-3
            import mpmath
            assert abs(t(mpmath.mpf(float(xi))) - mpmath.mpf(yi * 1e-3)) < 1e-30


def test_linear_tables_equal_np_interp_between_knots():
    for seed in range(5):
        x, y = _random_table(seed)
        t = _table(x, y, "linear")
        q = np.random.default_rng(100 + seed).uniform(x[0] - 30, x[-1] + 30, 5000)
        want = np.interp(q, x, y) * 1e-3   # np.interp holds the end values outside, as 'hold'
        assert np.allclose(t(q), want, rtol=0, atol=1e-15 * np.abs(y).max())


def test_monotone_cubic_tables_equal_an_independent_pchip_between_knots():
    for seed in range(5):
        x, y = _random_table(seed)
        t = _table(x, y, "monotone_cubic")
        q = np.random.default_rng(200 + seed).uniform(x[0] - 30, x[-1] + 30, 5000)
        want = pchip_reference(x, y, q) * 1e-3
        assert np.allclose(t(q), want, rtol=0, atol=1e-14 * np.abs(y).max()), seed
    # three points and two points
    for x, y in (([0, 1, 3], [0, 2, 1]), ([0, 4], [1, -1])):
        q = np.linspace(-1, 5, 301)
        assert np.allclose(_table(x, y, "monotone_cubic")(q), pchip_reference(x, y, q) * 1e-3, atol=1e-17)


def test_monotone_cubic_does_not_overshoot_a_step():
    x = np.arange(10.0)
    y = np.array([0, 0, 0, 0, 5, 5, 5, 5, 5, 5.0])
    q = np.linspace(-1, 10, 20001)
    v = _table(x, y, "monotone_cubic")(q) / 1e-3
    assert v.min() >= 0.0 and v.max() <= 5.0
    assert np.all(np.diff(v) >= -1e-15)
    # a cubic spline through the same points would: the test can tell
    from numpy.polynomial import polynomial as P
    c = P.polyfit(x, y, 6)
    assert P.polyval(q[(q > 0) & (q < 9)], c).max() > 5.0


def test_slopes_are_the_derivative_and_zero_outside():
    x, y = _random_table(7)
    for interpolation in ("linear", "monotone_cubic"):
        t = _table(x, y, interpolation)
        mid = 0.5 * (x[:-1] + x[1:])
        h = 1e-6
        fd = (t(mid + h) - t(mid - h)) / (2 * h)
        assert np.allclose(t.slope(mid), fd, rtol=1e-6, atol=1e-12)
        assert t.slope(x[0] - 1) == 0 and t.slope(x[-1] + 1) == 0
        assert t(x[-1] + 50) == y[-1] * 1e-3


def test_reject_tables_give_nan_outside():
    x, y = _random_table(3)
    t = _table(x, y, "linear", outside="reject")
    v = t(np.array([x[0] - 1, x[0], x[-1], x[-1] + 1]))
    assert np.isnan(v[0]) and np.isnan(v[3]) and v[1] == y[0] * 1e-3 and v[2] == y[-1] * 1e-3


# ----------------------------------------------------------------------------- params files

TABLES = """\
machine: five_axis_ac
values:
  EXX:
    axis: X
    units: [mm, um]
    interpolation: monotone_cubic
    outside: hold
    table:
      - [-400, 0.0]
      - [-100, 2.5]
      - [0, 3.0]
      - [400, 1.0]
  EBX:
    axis: X
    units: [in, arcsec]
    polynomial: [1.0, 0.5, -0.02]
    range: [-15, 15]
    outside: reject
  ECX: 2 arcsec
"""


def _write(tmp_path, text, name="p.yaml"):
    path = tmp_path / name
    path.write_text(text)
    return str(path)


def test_load_params_reads_tables_and_polynomials_in_their_units(tmp_path):
    from chaincomp import load_machine, load_params
    from chaincomp.model.varying import Polynomial, Table
    m = load_machine(FIVE)
    p = load_params(_write(tmp_path, TABLES), m)
    exx, ebx = p["EXX"], p["EBX"]
    assert isinstance(exx, Table) and isinstance(ebx, Polynomial)
    assert exx.axis == "X" and exx.interpolation == "monotone_cubic" and exx.line == 3
    assert exx(0.0) == pytest.approx(3e-3) and exx(-1000.0) == pytest.approx(0.0)
    u = 127.0 / 25.4  # 127 mm = 5 in
    assert ebx(127.0) == pytest.approx((1 + 0.5 * u - 0.02 * u * u) * ARCSEC)
    assert ebx.slope(127.0) == pytest.approx((0.5 - 0.04 * u) * ARCSEC / 25.4)
    assert math.isnan(ebx(15 * 25.4 + 1))
    assert p["ECX"] == pytest.approx(2 * ARCSEC)


def test_the_bundled_laser_calibration(tmp_path):
    from chaincomp import load_machine, load_params
    from chaincomp.model.varying import Table
    m = load_machine(FIVE)
    p = load_params(LASER, m)
    tables = {k: v for k, v in p.items() if isinstance(v, Table)}
    assert len(tables) == 18
    for name, t in tables.items():
        a = m.symbol(t.axis)
        assert len(t.x) >= 100
        assert t.x[0] == a.to_internal(a.limits[0]) and t.x[-1] == a.to_internal(a.limits[1])
        size = np.abs(t.y).max() / t.units[1].to_internal
        assert t.units[1].name in ("um", "arcsec") and 0.3 < size < 20, (name, size)
    with open(LASER) as f:
        head = f.read(400)
    assert "SYNTHETIC" in head and "not measured on any machine" in head
    # the slides' errors: each slide's six, over its own axis
    assert {t.axis for t in tables.values()} == {"X", "Y", "Z"}
    assert all(tables[f"E{c}{ax}"].axis == ax for c in "XYZABC" for ax in "XYZ")


@pytest.mark.slow
def test_simulate_calibration_regenerates_the_bundled_file(tmp_path):
    out = tmp_path / "laser.yaml"
    run_cli("simulate-calibration", "configs/machines/five_axis_ac.yaml", "--params",
            "configs/params/five_axis_ac-demo.yaml", "-o", str(out))
    got, want = yaml.safe_load(out.read_text()), yaml.safe_load(open(LASER).read())
    assert got.keys() == want.keys() and got["values"].keys() == want["values"].keys()
    for name, w in want["values"].items():
        g = got["values"][name]
        if isinstance(w, dict):
            assert {k: v for k, v in g.items() if k != "table"} == {k: v for k, v in w.items() if k != "table"}
            assert np.allclose(np.array(g["table"]), np.array(w["table"]), rtol=0, atol=1.5e-4), name
        else:
            assert g == w


@pytest.mark.slow
def test_simulate_calibration_options(tmp_path):
    out = tmp_path / "c.yaml"
    run_cli("simulate-calibration", FIVE, "--knots", "11", "--seed", "4", "--interpolation", "linear",
            "--outside", "reject", "-o", str(out))
    doc = yaml.safe_load(out.read_text())
    exx = doc["values"]["EXX"]
    assert len(exx["table"]) == 11 and exx["interpolation"] == "linear" and exx["outside"] == "reject"
    assert isinstance(doc["values"]["ThetaAs"], str)  # a constant: 'VALUE UNIT'
    from chaincomp import load_machine, load_params
    load_params(str(out), load_machine(FIVE))
    proc = run_cli("simulate-calibration", FIVE, "--knots", "1", "-o", str(out), check=False)
    assert proc.returncode == 2 and "--knots: must be between 2 and 4096" in proc.stderr
    # a machine without slides: nothing to tabulate
    proc = run_cli("simulate-calibration", machine_path("angle_head"), "-o", str(out), check=False)
    assert proc.returncode == 2 and "no slide" in proc.stderr


@pytest.mark.slow
def test_eval_with_tables_equals_eval_with_their_values_set(tmp_path):
    path = _write(tmp_path, TABLES)
    axes = ["--set", "X=123.4", "--set", "Y=-50", "--set", "Z=-200", "--set", "Ap=30", "--set", "Cp=-45"]
    out = json.loads(run_cli("eval", FIVE, "--params", path, *axes, "--json").stdout)
    v = out["varying"]
    assert v["EXX"]["unit"] == "um" and v["EXX"]["axis"] == "X" and v["EBX"]["unit"] == "arcsec"
    same = json.loads(run_cli("eval", FIVE, "--params", path, *axes, "--set", f"EXX={v['EXX']['value']!r}",
                              "--set", f"EBX={v['EBX']['value']!r}", "--json").stdout)
    for model in ("first", "second", "exact"):
        assert np.allclose(out["error"][model], same["error"][model], rtol=0, atol=1e-13)
    text = run_cli("eval", FIVE, "--params", path, *axes).stdout
    assert "errors that vary along an axis, here: EXX = " in text


def test_eval_outside_a_rejecting_range_exits_2(tmp_path):
    path = _write(tmp_path, TABLES)
    proc = run_cli("eval", FIVE, "--params", path, "--set", "X=390", check=False)
    assert proc.returncode == 2
    assert f"{path}:13: values.EBX: X = 390 mm lies outside the range [-381, 381] mm of EBX (outside: reject)" \
        in proc.stderr


def test_exact_model_evaluates_tables_with_numpy_arrays_and_mpmath(tmp_path):
    import mpmath
    from chaincomp import load_machine, load_params
    from chaincomp.symbolic.numeric import ExactModel
    m = load_machine(FIVE)
    values = m.nominal_values()
    values.update(load_params(LASER, m))
    xs = np.array([-350.0, 12.5, 333.3])
    arr = dict(values, X=xs, Y=np.full(3, 20.0), Z=np.full(3, -100.0), Ap=np.full(3, 0.5), Cp=np.full(3, 0.2))
    p_np, _ = ExactModel(m).pose(arr)
    for i, x in enumerate(xs):
        mp = {k: v for k, v in values.items()}
        mp.update(X=mpmath.mpf(x), Y=mpmath.mpf(20), Z=mpmath.mpf(-100), Ap=mpmath.mpf(0.5), Cp=mpmath.mpf(0.2))
        mp = {k: (mpmath.mpf(v) if isinstance(v, float) else v) for k, v in mp.items()}
        p_mp, _ = ExactModel(m).pose(mp, "mpmath")
        assert all(abs(float(a) - b[i]) < 1e-11 for a, b in zip(p_mp, p_np))


# ----------------------------------------------------------------------------- bad files

# Each edit of TABLES: (old, new, line of the edit in the new text, key, words)
BAD = [
    ("[-100, 2.5]", "[-500, 2.5]", "[-500, 2.5]", "values.EXX.table[1]", "positions must increase: -500 follows -400"),
    ("[-100, 2.5]", "[-400, 2.5]", "[-400, 2.5]", "values.EXX.table[1]", "duplicate position -400"),
    ("[-100, 2.5]", "[-100, .nan]", "[-100, .nan]", "values.EXX.table[1]", "expected finite numbers"),
    ("[0, 3.0]", "[.inf, 3.0]", "[.inf, 3.0]", "values.EXX.table[2]", "expected finite numbers"),
    ("[0, 3.0]", "[0, three]", "[0, three]", "values.EXX.table[2]", "expected a number"),
    ("      - [-100, 2.5]\n      - [0, 3.0]\n      - [400, 1.0]\n", "", "    table:", "values.EXX.table",
     "a table needs at least 2 points, got 1"),
    ("    axis: X\n    units: [mm, um]", "    axis: W\n    units: [mm, um]", "    axis: W",
     "values.EXX.axis", "'W' is not an axis of five_axis_ac (axes: X, Y, Z, Ap, Cp)"),
    ("    axis: X\n    units: [mm, um]", "    axis: G\n    units: [mm, um]", "    axis: G",
     "values.EXX.axis", "'G' is not an axis"),
    ("[mm, um]", "[deg, um]", "[deg, um]", "values.EXX.units",
     "position unit 'deg' is an angle unit, but axis X is a length"),
    ("[mm, um]", "[mm, arcsec]", "[mm, arcsec]", "values.EXX.units",
     "value unit 'arcsec' is an angle unit, but EXX is a length"),
    ("[mm, um]", "[mm, furlong]", "[mm, furlong]", "values.EXX.units", "unknown unit 'furlong'"),
    ("interpolation: monotone_cubic", "interpolation: spline", "interpolation: spline",
     "values.EXX.interpolation", "interpolation must be linear or monotone_cubic"),
    ("outside: hold", "outside: clamp", "outside: clamp", "values.EXX.outside", "outside must be hold or reject"),
    ("    outside: hold\n", "", "  EXX:", "values.EXX", "missing required field 'outside'"),
    ("    outside: hold\n", "    outside: hold\n    step: 8\n", "    step: 8", "values.EXX.step",
     "unknown field 'step'"),
    ("[1.0, 0.5, -0.02]", "[1.0, .nan]", "    polynomial: [1.0, .nan]", "values.EBX.polynomial[1]",
     "expected finite numbers"),
    ("[-15, 15]", "[15, -15]", "[15, -15]", "values.EBX.range", "must be below"),
    ("  ECX: 2 arcsec\n", "  G:\n    axis: X\n    units: [mm, mm]\n    polynomial: [1]\n", "  G:", "values.G",
     "only error symbols may vary along an axis"),
]


def _bad_file(tmp_path, i, old, new, marker):
    assert old in TABLES
    text = TABLES.replace(old, new, 1)
    line = text[:text.index(marker)].count("\n") + 1
    return _write(tmp_path, text, f"bad{i}.yaml"), line


@pytest.mark.parametrize("i", range(len(BAD)))
def test_bad_tables_exit_2_with_file_line_and_key(tmp_path, i):
    old, new, marker, key, words = BAD[i]
    path, line = _bad_file(tmp_path, i, old, new, marker)
    proc = cli("eval", FIVE, "--params", path, check=False)   # in this process; eval's exit path: a test above
    assert proc.returncode == 2, proc.stderr
    assert f"chaincomp eval: error: {path}:{line}: {key}: " in proc.stderr, proc.stderr
    assert words in proc.stderr and "Traceback" not in proc.stderr


@pytest.mark.parametrize("i", range(len(BAD)))
def test_chaincompd_refuses_bad_tables_with_file_line_and_key(tmp_path, i):
    old, new, marker, key, words = BAD[i]
    path, line = _bad_file(tmp_path, i, old, new, marker)
    # the params are loaded before LCM is opened: no network traffic
    proc = subprocess.run([DAEMON, "--machine", FIVE, "--params", path], capture_output=True, text=True,
                          timeout=20)
    assert proc.returncode == 2
    assert f"chaincompd: error: {path}:{line}: {key}: " in proc.stderr, proc.stderr
    assert words.split(" (")[0].replace("three", "") in proc.stderr, proc.stderr
    assert "ready" not in proc.stderr


def test_replay_refuses_a_bad_table(tmp_path):
    path, line = _bad_file(tmp_path, 0, *BAD[0][:3])
    proc = subprocess.run([REPLAY, "--machine", FIVE, "--params", path, "--in", str(tmp_path / "x.lcmlog")],
                          capture_output=True, text=True)
    assert proc.returncode == 2 and f"{path}:{line}: values.EXX.table[1]: positions must increase" in proc.stderr


# ----------------------------------------------------------------------------- plot

@pytest.mark.slow
def test_plot_a_table_and_a_polynomial(tmp_path):
    out = tmp_path / "exx.png"
    proc = run_cli("plot", "--table", LASER, "--error", "EXX", "-o", str(out))
    assert out.stat().st_size > 10000 and "wrote" in proc.stderr
    path = _write(tmp_path, TABLES)
    run_cli("plot", FIVE, "--table", path, "--error", "EBX", "-o", str(tmp_path / "ebx.png"))
    assert (tmp_path / "ebx.png").stat().st_size > 10000
    proc = run_cli("plot", "--table", path, "--error", "ECX", "-o", str(out), check=False)
    assert proc.returncode == 2 and "ECX is a constant here" in proc.stderr
    proc = run_cli("plot", "--table", path, "-o", str(out), check=False)
    assert proc.returncode == 2 and "go together" in proc.stderr


# ----------------------------------------------------------------------------- compensation

def _independent_errors(path, axes_internal):
    """Every error of a params file at the axes, read with yaml alone and interpolated with
    np.interp (linear) or pchip_reference (monotone cubic); internal units."""
    doc = yaml.safe_load(open(path).read())["values"]
    out = {}
    for name, v in doc.items():
        if isinstance(v, dict):
            pu, vu = (TO_INTERNAL[u] for u in v["units"])
            rows = np.array(v["table"], float)
            x, y = rows[:, 0] * pu, rows[:, 1] * vu
            t = axes_internal[v["axis"]]
            out[name] = np.interp(t, x, y) if v["interpolation"] == "linear" else pchip_reference(x, y, t)
        else:
            value, unit = str(v).split()
            out[name] = float(value) * TO_INTERNAL[unit]
    return out


def _htm_tool_point(machine, values):
    """The tool point by a product of 4x4 homogeneous transforms, one per elementary
    transform of the chain (numpy; each entry's expression evaluated with lambdify)."""
    import sympy as sp
    from chaincomp.model.machine import Rotation
    names = [s.name for s in machine.symbols]
    args = [values[n] for n in names]
    n = len(np.atleast_1d(values["X"]))
    T = np.broadcast_to(np.eye(4), (n, 4, 4)).copy()
    f = lambda e: np.broadcast_to(np.asarray(sp.lambdify(names, e, "numpy")(*args), float), (n,))  # noqa: E731
    for el in machine.chain:
        M = np.broadcast_to(np.eye(4), (n, 4, 4)).copy()
        if isinstance(el, Rotation):
            a = f(el.angle)
            c, s = np.cos(a), np.sin(a)
            i, j = {"x": (1, 2), "y": (2, 0), "z": (0, 1)}[el.axis]
            M[:, i, i], M[:, i, j], M[:, j, i], M[:, j, j] = c, -s, s, c
        else:
            for k in range(3):
                M[:, k, 3] = f(el.vector[k])
        T = T @ M
    p = np.stack([f(e) for e in machine.tool_point] + [np.ones(n)], axis=1)
    return np.einsum("nij,nj->ni", T, p)[:, :3]


@pytest.mark.slow
@pytest.mark.parametrize("interpolation", ["monotone_cubic", "linear"])
def test_compensation_with_tables_puts_the_tool_point_on_the_nominal_one(tmp_path, interpolation):
    """chaincomp_replay (the daemon's compensator) on a toolpath with the laser tables; the
    actual tool point at each corrected command, by the HTM product with the errors
    interpolated here, equals the nominal one at the command within 1 nm."""
    from chaincomp import load_machine
    params = tmp_path / "laser.yaml"
    params.write_text(open(LASER).read().replace("interpolation: monotone_cubic", f"interpolation: {interpolation}"))
    log, table = tmp_path / "axes.lcmlog", tmp_path / "replay.csv"
    run_cli("simulate-log", FIVE, "-o", str(log), "--seconds", "1")
    proc = run_cli("replay", FIVE, str(log), "--params", str(params), "--config", E2E_CONFIG,
                   "--csv", str(table))
    assert "1000 corrected, 0 rejected" in proc.stderr
    assert "18 errors vary along an axis: 18 tables (1818 points)" in proc.stderr
    with open(table, newline="") as f:
        rows = list(csv.DictReader(f))
    m = load_machine(FIVE)
    units = {a.name: a.unit for a in m.axes}
    def axes(prefix):
        return {a: np.array([float(r[f"{prefix}_{a}_{units[a].name}"]) for r in rows]) * units[a].to_internal
                for a in units}
    cmd, cor = axes("commanded"), axes("corrected")
    consts = {s.name: s.to_internal(s.nominal) for s in m.constants}
    actual = _htm_tool_point(m, {**consts, **cor, **_independent_errors(str(params), cor)})
    nominal = _htm_tool_point(m, {**consts, **cmd, **{s.name: 0.0 for s in m.errors}})
    dp = np.linalg.norm(actual - nominal, axis=1)
    # the errors are really there and really vary: µm-sized corrections, different per record
    corr = np.linalg.norm(np.stack([cor[a] - cmd[a] for a in ("X", "Y", "Z")]), axis=0)
    assert corr.max() > 5e-3 and np.ptp(corr) > 1e-3
    assert dp.max() < 1e-6, dp.max()
    # with the constants the point would be off by µm: the tables matter here
    frozen = _independent_errors(str(params), {a: np.zeros(len(rows)) for a in units})
    off = _htm_tool_point(m, {**consts, **cor, **frozen})
    assert np.linalg.norm(off - nominal, axis=1).max() > 1e-3


@pytest.mark.slow
@needs_netns
def test_daemon_with_tables_streams_exact_targets_without_allocating(monkeypatch):
    """tests/e2e/e2e_stream.py with the laser tables: chaincompd (in a network namespace)
    checked target by target against the exact model with the tables; zero allocations."""
    monkeypatch.setenv("CHAINCOMP_E2E_PARAMS", LASER)
    proc = subprocess.run([os.path.join(ROOT, "tests", "e2e", "netns.sh"), sys.executable,
                           "tests/e2e/e2e_stream.py", "1000", "3000"], capture_output=True, text=True, cwd=ROOT,
                          timeout=180)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    assert "heap allocations after warm-up 0" in proc.stdout


@pytest.mark.slow
@needs_netns
def test_daemon_with_tables_equals_replay_bit_for_bit(tmp_path, monkeypatch):
    monkeypatch.setenv("CHAINCOMP_E2E_PARAMS", LASER)
    log = tmp_path / "axes.lcmlog"
    run_cli("simulate-log", FIVE, "-o", str(log), "--seconds", "1")
    proc = subprocess.run([os.path.join(ROOT, "tests", "e2e", "netns.sh"), sys.executable,
                           "tests/e2e/e2e_replay.py", str(log)], capture_output=True, text=True, cwd=ROOT,
                          timeout=180)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    assert "targets differing: 0" in proc.stdout


@pytest.mark.slow
def test_budget_takes_tables_as_bounds():
    # their largest |value| on the grid as the bound (test_budget_tables.py checks the numbers)
    proc = run_cli("budget", FIVE, "--params", LASER, "--grid", "2", "--samples", "0", check=False)
    assert proc.returncode == 0, proc.stderr
    assert "tables in --params, not systematic" in proc.stdout and "EXX " in proc.stdout
