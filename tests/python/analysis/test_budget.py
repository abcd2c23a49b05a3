"""chaincomp budget: worst case, RSS, Monte Carlo, contributors, sensitivity, tolerance files.

The reference figures here never come from the budget's own gain code: gains are central
differences of the exact model (ExactModel, the chain multiplied numerically), bounds are
read from the tolerance file by a small parser in this file, and the statistics are plain
numpy.
"""

import json
import math
import os

import numpy as np
import pytest
import yaml

from helpers import PARAMS, ROOT, cli, line_of, machine_path, run_cli

from chaincomp.analysis import budget as B
from chaincomp.model.machine import load_machine
from chaincomp.symbolic.numeric import ExactModel
from chaincomp.analysis.tolerances import load_tolerances

TOLERANCES = os.path.join(ROOT, "configs", "tolerances")
FIVE = machine_path("five_axis_ac")
FIVE_TOL = os.path.join(TOLERANCES, "five_axis_ac.yaml")
MORI = machine_path("mori_seiki_nv1500")
MORI_TOL = os.path.join(TOLERANCES, "mori_seiki_nv1500.yaml")
MORI_PARAMS = os.path.join(PARAMS, "mori_seiki_nv1500-notes.yaml")
P3 = math.erf(3 / math.sqrt(2))   # coverage of +-3 sigma
TO_INTERNAL = {"um": 1e-3, "mm": 1.0, "arcsec": math.pi / 648000.0}


def budget_json(*args: str) -> dict:
    return json.loads(run_cli("budget", *args, "--format", "json").stdout)


# ----------------------------------------------------------------------------- independent references

def read_tolerances(path: str) -> dict:
    """{error: (bound internal, distribution, sigmas)} with a parser of this test's own."""
    doc = yaml.safe_load(open(path))
    k = float(str(doc.get("normal_bound", "3 sigma")).split()[0])
    out = {}
    for name, e in doc["tolerances"].items():
        value, unit = str(e["bound"]).split()
        out[name] = (float(value) * TO_INTERNAL[unit], e["distribution"],
                     float(str(e.get("normal_bound", f"{k} sigma")).split()[0]))
    return out, k


def grid_values(machine, over, points, fixed):
    """Internal values with the grid axes as full meshgrid arrays (indexing ij)."""
    axes = [machine.symbol(n) for n in over]
    mesh = np.meshgrid(*[np.linspace(a.limits[0], a.limits[1], points) for a in axes], indexing="ij")
    v = machine.nominal_values()
    for a in machine.axes:
        v[a.name] = a.to_internal(fixed.get(a.name, 0.0))
    for a, g in zip(axes, mesh):
        v[a.name] = a.to_internal(g)
    return v


def fd_gains(machine, values, h=1e-6):
    """{component: array (n_errors, *grid)}: central differences of the exact model at zero errors."""
    exact = ExactModel(machine)
    comps = ["dx", "dy", "dz"] + (["dkx", "dky", "dkz"] if machine.tool_direction else [])
    shape = np.broadcast(*[np.asarray(values[a.name]) for a in machine.axes]).shape
    out = {c: [] for c in comps}
    for s in machine.errors:
        poses = []
        for sign in (1, -1):
            v = dict(values)
            v[s.name] = sign * h
            p, d = exact.pose(v)
            poses.append(list(p) + (list(d) if d is not None else []))
        for c, a, b in zip(comps, *poses):
            out[c].append(np.broadcast_to((np.asarray(a) - np.asarray(b)) / (2 * h), shape))
    return {c: np.array(g) for c, g in out.items()}


def reference_figures(gains, tol, machine, k):
    """worst, rss and sigma from gains and the bounds, per component."""
    b = np.array([tol[s.name][0] if s.name in tol else 0.0 for s in machine.errors])
    q, sd = np.zeros_like(b), np.zeros_like(b)
    for i, s in enumerate(machine.errors):
        if s.name in tol:
            bound, dist, ki = tol[s.name]
            sd[i] = bound / math.sqrt(3) if dist == "uniform" else bound / ki
            q[i] = bound * math.erf(k / math.sqrt(2)) if dist == "uniform" else bound * k / ki
    shape = (-1,) + (1,) * (next(iter(gains.values())).ndim - 1)
    out = {}
    for c, g in gains.items():
        out[c] = (np.sum(np.abs(g) * b.reshape(shape), axis=0),
                  np.sqrt(np.sum((g * q.reshape(shape)) ** 2, axis=0)),
                  np.sqrt(np.sum((g * sd.reshape(shape)) ** 2, axis=0)))
    return out


# ----------------------------------------------------------------------------- the notes' §7

@pytest.mark.slow
def test_mori_seiki_dz3_alone_gives_4um_in_z_everywhere():
    """With only delta_z^3 = 4 um the z error is 4 um at every grid point, x and y nothing.
    The sign of the systematic error is the exact chain's (tool relative to workpiece), checked
    here against the exact model at random axis positions."""
    machine = load_machine(MORI)
    rng = np.random.default_rng(3)
    v = machine.nominal_values()
    for a in machine.axes:
        v[a.name] = a.to_internal(rng.uniform(*a.limits, 50))
    v["dz3"] = 0.004
    dp, _ = ExactModel(machine).error(v)
    chain_dz = np.asarray(dp[2])
    np.testing.assert_allclose(chain_dz, 0.004, rtol=1e-9)   # + by this machine file's chain

    for args in (("--tolerances", MORI_TOL, "--params", MORI_PARAMS), ("--params", MORI_PARAMS)):
        out = budget_json(MORI, *args, "--grid", "7", "--samples", "2000")
        dz = out["components"]["dz"]
        assert dz["worst"]["max"] == pytest.approx(0.004, rel=1e-12)
        assert dz["worst"]["min"] == pytest.approx(0.004, rel=1e-12)
        assert dz["systematic"]["min"] == pytest.approx(chain_dz.min(), rel=1e-9)
        assert dz["systematic"]["max"] == pytest.approx(chain_dz.max(), rel=1e-9)
        assert dz["rss"]["max"] == pytest.approx(P3 * 0.004, rel=1e-12)   # uniform, read at 99.73 %
        assert dz["sigma"]["max"] == pytest.approx(0.004 / math.sqrt(3), rel=1e-12)
        for c in ("dx", "dy"):
            assert out["components"][c]["worst"]["max"] == 0.0
        (top,) = dz["at_worst"]["contributors"]
        assert top["error"] == "dz3" and top["share_worst"] == 1.0
        assert top["gain"] == pytest.approx(0.001) and top["gain_unit"] == "mm/um"   # +1 um per um
        assert dz["at_worst"]["monte_carlo"]["max"] <= 0.004 * (1 + 1e-9)
        assert out["grid"]["points"] == 343


@pytest.mark.slow
def test_mori_seiki_text_says_everywhere():
    proc = run_cli("budget", MORI, "--tolerances", MORI_TOL, "--params", MORI_PARAMS, "--samples", "1000")
    dz = next(line for line in proc.stdout.splitlines() if line.strip().startswith("dz "))
    assert "4.000" in dz and "+4.000 everywhere" in dz


# ----------------------------------------------------------------------------- worst case, RSS

@pytest.mark.parametrize("over,fixed", [
    (("X", "Ap", "Cp"), {"Y": 120.0, "Z": -250.0}),
    (("X", "Y", "Z", "Ap", "Cp"), {}),
])
def test_worst_rss_sigma_equal_independent_numpy_on_every_grid_point(over, fixed):
    machine = load_machine(FIVE)
    points = 5 if len(over) == 3 else 3
    tol, k = read_tolerances(FIVE_TOL)
    gains = fd_gains(machine, grid_values(machine, over, points, fixed))
    ref = reference_figures(gains, tol, machine, k)

    values = machine.nominal_values()
    for a in machine.axes:
        values[a.name] = a.to_internal(fixed.get(a.name, 0.0))
    grid = B.make_grid(machine, list(over), points, values)
    b = B.compute(machine, values, load_tolerances(FIVE_TOL, machine), grid, "1", samples=0)
    for c, (worst, rss, sigma) in ref.items():
        cb = b.components[c]
        scale = np.max(worst)
        np.testing.assert_allclose(cb.worst, worst, rtol=1e-6, atol=1e-9 * scale, err_msg=c)
        np.testing.assert_allclose(cb.rss, rss, rtol=1e-6, atol=1e-9 * scale, err_msg=c)
        np.testing.assert_allclose(cb.sigma, sigma, rtol=1e-6, atol=1e-9 * scale, err_msg=c)
        # the reported worst point is the numpy argmax (up to ties)
        assert worst[cb.worst_index] == pytest.approx(worst.max(), rel=1e-6)
        # sensitivity: largest |gain| over the grid, per error
        np.testing.assert_allclose(cb.max_gain, np.abs(gains[c]).reshape(len(machine.errors), -1).max(axis=1),
                                   rtol=1e-6, atol=1e-9, err_msg=c)


@pytest.mark.slow
def test_cli_json_figures_match_numpy_and_exact_and_second_order_agree():
    machine = load_machine(FIVE)
    tol, k = read_tolerances(FIVE_TOL)
    over, fixed = ("X", "Ap", "Cp"), {"Y": -300.0, "Z": -400.0}
    ref = reference_figures(fd_gains(machine, grid_values(machine, over, 5, fixed)), tol, machine, k)
    common = (FIVE, "--tolerances", FIVE_TOL, "--over", ",".join(over), "--grid", "5",
              "--set", "Y=-300", "--set", "Z=-400", "--samples", "0")
    outs = {o: budget_json(*common, "--order", o) for o in ("1", "2", "exact")}
    for c, (worst, rss, _) in ref.items():
        for o, out in outs.items():
            comp = out["components"][c]
            rel = 1e-6 if o != "2" else 1e-3   # order 2 adds its quadratic terms' bound
            assert comp["worst"]["max"] == pytest.approx(worst.max(), rel=rel), (o, c)
            assert comp["rss"]["max"] == pytest.approx(rss.max(), rel=1e-6), (o, c)
        assert outs["2"]["components"][c]["worst"]["max"] >= outs["1"]["components"][c]["worst"]["max"]
        # direction components are unitless in JSON, position ones in the machine's mm
        assert outs["1"]["components"][c]["unit"] == ("1" if c.startswith("dk") else "mm")


# ----------------------------------------------------------------------------- Monte Carlo

def _normal_file(tmp_path) -> str:
    doc = yaml.safe_load(open(FIVE_TOL))
    for e in doc["tolerances"].values():
        e["distribution"] = "normal"
    path = tmp_path / "normal.yaml"
    path.write_text(yaml.safe_dump(doc))
    return str(path)


@pytest.mark.slow
def test_monte_carlo_1e5_within_worst_and_matches_rss_for_normal_inputs(tmp_path):
    out = budget_json(FIVE, "--tolerances", _normal_file(tmp_path), "--over", "X,Ap,Cp", "--grid", "5",
                      "--set", "Y=200", "--set", "Z=-300", "--samples", "100000", "--seed", "11")
    assert out["monte_carlo"] == {"samples": 100000, "seed": 11, "model": "exact"}
    for c, comp in out["components"].items():
        at = comp["at_worst"]
        mc = at["monte_carlo"]
        assert mc["samples"] == 100000 and mc["coverage"] == pytest.approx(P3)
        assert mc["quantile"] <= at["worst"], c
        assert abs(mc["quantile"] - at["rss"]) <= 3 * mc["quantile_se"], (c, mc, at["rss"])
        assert abs(mc["sigma"] - at["sigma"]) <= 3 * mc["sigma_se"], (c, mc, at["sigma"])
        assert abs(mc["mean"]) <= 3 * mc["mean_se"], (c, mc)
        assert mc["bracketed"]
        # all normal at 3 sigma: the RSS is exactly 3 sigma of the result
        assert at["rss"] == pytest.approx(3 * at["sigma"], rel=1e-12)


@pytest.mark.slow
def test_monte_carlo_independent_of_the_budget_code():
    """A numpy Monte Carlo of the exact model, written here, agrees with the reported one."""
    machine = load_machine(FIVE)
    tol, k = read_tolerances(FIVE_TOL)
    out = budget_json(FIVE, "--tolerances", FIVE_TOL, "--over", "Ap,Cp", "--grid", "5", "--set", "X=400",
                      "--set", "Y=-300", "--set", "Z=-400", "--samples", "100000", "--seed", "5")
    comp = out["components"]["dx"]
    v = machine.nominal_values()
    for a in machine.axes:
        v[a.name] = a.to_internal(comp["at_worst"]["axes"][a.name])
    rng = np.random.default_rng(99)
    n = 100000
    for s in machine.errors:
        bound, dist, ki = tol[s.name]
        v[s.name] = rng.uniform(-bound, bound, n) if dist == "uniform" else rng.normal(0, bound / ki, n)
    dev = np.asarray(ExactModel(machine).error(v)[0][0])
    mc = comp["at_worst"]["monte_carlo"]
    assert dev.std() == pytest.approx(mc["sigma"], abs=4 * mc["sigma_se"] * math.sqrt(2))
    q = np.quantile(np.abs(dev), P3)
    assert q == pytest.approx(mc["quantile"], abs=4 * mc["quantile_se"] * math.sqrt(2))
    # mixed uniform/normal inputs: rss <= MC quantile <= worst
    for c, cc in out["components"].items():
        assert cc["at_worst"]["monte_carlo"]["bracketed"], c


# ----------------------------------------------------------------------------- contributors

@pytest.mark.slow
def test_ranking_stable_under_a_fixed_seed_and_equal_to_numpy_ranking():
    args = (FIVE, "--tolerances", FIVE_TOL, "--over", "X,Z,Cp", "--grid", "5", "--set", "Y=150",
            "--set", "Ap=60", "--samples", "3000")
    a = budget_json(*args, "--seed", "7")
    b = budget_json(*args, "--seed", "7")
    assert a == b
    c = budget_json(*args, "--seed", "8")
    for comp in a["components"]:
        assert [r["error"] for r in a["components"][comp]["at_worst"]["contributors"]] == \
               [r["error"] for r in c["components"][comp]["at_worst"]["contributors"]]
    assert a["components"]["dx"]["at_worst"]["monte_carlo"] != c["components"]["dx"]["at_worst"]["monte_carlo"]

    machine = load_machine(FIVE)
    tol, _ = read_tolerances(FIVE_TOL)
    names = [s.name for s in machine.errors]
    bounds = np.array([tol[n][0] for n in names])
    for comp, out in a["components"].items():
        at = out["at_worst"]
        v = machine.nominal_values()
        for ax in machine.axes:
            v[ax.name] = ax.to_internal(at["axes"][ax.name])
        g = fd_gains(machine, v)[comp]
        contrib = np.abs(g) * bounds
        order = np.argsort(-contrib, kind="stable")
        ranked = [r["error"] for r in at["contributors"]]
        assert sorted(ranked) == sorted(names)
        tiny = 1e-7 * contrib.max()
        for pos, name in enumerate(ranked):
            # the same contribution at every rank; names may differ only within ties
            assert abs(contrib[names.index(name)] - contrib[order[pos]]) <= tiny, (comp, pos, name)
        strict = [names[i] for i in order if all(abs(contrib[i] - contrib[j]) > tiny for j in order if j != i)]
        assert [n for n in ranked if n in strict] == strict
        total = contrib.sum()
        for r in at["contributors"]:
            assert r["share_worst"] == pytest.approx(contrib[names.index(r["error"])] / total, abs=1e-7)


# ----------------------------------------------------------------------------- plots, options

@pytest.mark.slow
def test_plot_maps_and_bars(tmp_path):
    png = tmp_path / "budget.png"
    proc = run_cli("budget", FIVE, "--tolerances", FIVE_TOL, "--over", "X,Y,Cp", "--grid", "5",
                   "--samples", "0", "--plot", str(png), "--map", "Y,Cp", "--component", "dz")
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert f"wrote {png}" in proc.stderr
    line = tmp_path / "line.png"
    run_cli("budget", MORI, "--tolerances", MORI_TOL, "--over", "Z", "--samples", "0", "--plot", str(line))
    assert line.stat().st_size > 1000


@pytest.mark.parametrize("args,word", [
    (("--over", "X,Q"), "--over expects"),
    (("--grid", "1"), "--grid: must be"),
    (("--grid", "400"), "limit"),
    (("--set", "X=10"), "--set X: X is an axis of the grid"),
    (("--samples", "-1"), "--samples"),
    (("--map", "X,X", "--plot", "/dev/null"), "--map expects"),
])
def test_bad_options_exit_2(args, word):
    proc = cli("budget", FIVE, "--tolerances", FIVE_TOL, "--samples", "0", *args, check=False)  # exit path: below
    assert proc.returncode == 2 and word in proc.stderr and "Traceback" not in proc.stderr, proc.stderr


@pytest.mark.slow
def test_nothing_to_budget_exits_2():
    proc = run_cli("budget", MORI, check=False)
    assert proc.returncode == 2 and "nothing to budget" in proc.stderr


# ----------------------------------------------------------------------------- bad tolerance files

GOOD = """\
# a tolerance file for the test copy
machine: mori_seiki_nv1500
normal_bound: 3 sigma
tolerances:
  dz3: {bound: 4 um, distribution: uniform}
  ey3: {bound: 2 arcsec, distribution: normal}
  dx7: {bound: 1.5, distribution: normal, normal_bound: 2 sigma}
"""


BAD = [
    ("unknown-error", ("dz3: {bound", "dz9: {bound"), "dz9:", "tolerances.dz9", "unknown error 'dz9'"),
    ("axis", ("dz3: {bound", "X: {bound"), "X: {bound", "tolerances.X", "an axis"),
    ("constant", ("dz3: {bound", "dz23: {bound"), "dz23:", "tolerances.dz23", "a constant"),
    ("negative-bound", ("4 um", "-4 um"), "-4 um", "tolerances.dz3.bound", "cannot be negative"),
    ("wrong-unit-kind", ("2 arcsec", "2 um"), "2 um", "tolerances.ey3.bound", "length unit"),
    ("unknown-unit", ("4 um", "4 furlong"), "4 furlong", "tolerances.dz3.bound", "unknown unit"),
    ("not-a-number", ("4 um", "four"), "four", "tolerances.dz3.bound", "expected a number"),
    ("distribution", ("distribution: uniform", "distribution: triangular"), "triangular",
     "tolerances.dz3.distribution", "expected uniform or normal"),
    ("missing-distribution", ("{bound: 4 um, distribution: uniform}", "{bound: 4 um}"), "dz3:",
     "tolerances.dz3", "missing required field 'distribution'"),
    ("missing-bound", ("{bound: 4 um, distribution: uniform}", "{distribution: uniform}"), "dz3:",
     "tolerances.dz3", "missing required field 'bound'"),
    ("unknown-entry-field", ("distribution: uniform}", "distribution: uniform, mean: 1}"), "dz3:",
     "tolerances.dz3.mean", "unknown field 'mean'"),
    ("not-a-mapping", ("{bound: 4 um, distribution: uniform}", "4 um"), "dz3:", "tolerances.dz3",
     "expected a mapping"),
    ("normal-bound-on-uniform", ("distribution: uniform}", "distribution: uniform, normal_bound: 2 sigma}"),
     "dz3:", "tolerances.dz3.normal_bound", "normal distribution only"),
    ("bad-normal-bound", ("normal_bound: 3 sigma", "normal_bound: three sigma"), "normal_bound: three",
     "normal_bound", "expected 'K sigma'"),
    ("zero-sigmas", ("normal_bound: 2 sigma", "normal_bound: 0 sigma"), "normal_bound: 0",
     "tolerances.dx7.normal_bound", "K must lie in"),
    ("wrong-machine", ("machine: mori_seiki_nv1500", "machine: five_axis_ac"), "machine:", "machine",
     "not 'mori_seiki_nv1500'"),
    ("unknown-top-field", ("normal_bound: 3 sigma\n", "normal_bound: 3 sigma\ncoverage: 2\n"), "coverage:",
     "coverage", "unknown field 'coverage'"),
    ("duplicate-error", ("  ey3: {bound: 2", "  dz3: {bound: 2"), "  dz3: {bound: 2", "dz3", "duplicate key"),
    ("empty-tolerances", (GOOD[GOOD.index("tolerances:"):], "tolerances: {}\n"), "tolerances: {}", "tolerances",
     "non-empty mapping"),
]


@pytest.mark.parametrize("edit,at,field,word", [pytest.param(*c[1:], id=c[0]) for c in BAD])
def test_bad_tolerance_file_exits_2_with_file_line_field(tmp_path, edit, at, field, word):
    old, new = edit
    assert GOOD.count(old) == 1
    text = GOOD.replace(old, new)
    path = tmp_path / "bad.yaml"
    path.write_text(text)
    proc = cli("budget", MORI, "--tolerances", str(path), "--samples", "0", check=False)
    err = proc.stderr
    assert proc.returncode == 2, err
    assert "Traceback" not in err and len(err.strip().splitlines()) == 1, err
    where = f"{path}:{line_of(text, at)}: {field}: "
    assert where in err, (where, err)
    assert word in err, err


def test_good_tolerance_file_reads_every_field(tmp_path):
    path = tmp_path / "good.yaml"
    path.write_text(GOOD)
    machine = load_machine(MORI)
    t = load_tolerances(str(path), machine).by_name()
    assert t["dz3"].bound == pytest.approx(0.004) and t["dz3"].sigma == pytest.approx(0.004 / math.sqrt(3))
    assert t["ey3"].sigma == pytest.approx(2 * math.pi / 648000 / 3)
    assert t["dx7"].bound == pytest.approx(0.0015) and t["dx7"].sigma == pytest.approx(0.00075)


def test_bundled_tolerance_files_cover_their_machines():
    for name in ("five_axis_ac", "mori_seiki_nv1500"):
        machine = load_machine(machine_path(name))
        tol = load_tolerances(os.path.join(TOLERANCES, name + ".yaml"), machine)
        assert tol.items
    five = load_tolerances(FIVE_TOL, load_machine(FIVE))
    assert len(five.items) == 29


@pytest.mark.slow
def test_systematic_error_at_the_params_values_is_the_exact_models():
    """With --params error values, the systematic figure at the worst point is the tool error
    of the exact model there (order exact), and the second-order model's within its own order."""
    machine = load_machine(FIVE)
    params = os.path.join(PARAMS, "five_axis_ac-demo.yaml")
    from chaincomp.model.params import load_params
    errors = load_params(params, machine)
    common = (FIVE, "--tolerances", FIVE_TOL, "--params", params, "--over", "X,Ap,Cp", "--grid", "4",
              "--set", "Y=100", "--set", "Z=-300", "--samples", "0")
    for order, tol in (("exact", 1e-12), ("2", 1e-7)):
        out = budget_json(*common, "--order", order)
        assert out["centre"] and out["params_errors"]
        for c in ("dx", "dy", "dz"):
            at = out["components"][c]["at_worst"]
            v = machine.nominal_values()
            for a in machine.axes:
                v[a.name] = a.to_internal(at["axes"][a.name])
            v.update(errors)
            ref = float(ExactModel(machine).error(v)[0]["xyz".index(c[1])])
            assert at["systematic"] == pytest.approx(ref, abs=tol), (order, c)
