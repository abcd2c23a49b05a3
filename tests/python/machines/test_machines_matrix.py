"""Every verb on every bundled machine (configs/machines/*.yaml, found by glob, so a new
machine joins the matrix by being added): derive, eval, generate, check (where a check
file names the machine), protocol (or its refusal without rotary axes),
simulate-measurements -> identify, budget, simulate-log -> replay, and chaincompd end to
end in a network namespace. Each cell checks what a user relies on against something the
verb did not compute itself: the machine file read with plain YAML, the exact chain
(Python) at the set-ups, bounds or corrected axes the verb reports, the build's own copy
of the generated code, and for the daemon the targets replay computes offline.
Run time: about 40 s on the 2-core CI machine (the generate cell of five_axis_ac is 15 s).
"""

import contextlib
import csv
import glob
import io
import json
import os
import re
import subprocess

import numpy as np
import pytest
import sympy as sp
import yaml

from chaincomp import load_machine, load_params
from chaincomp.cli.main import main as chaincomp_main
from chaincomp.symbolic.numeric import ExactModel
from chaincomp.measure.pose_design import is_arm
from chaincomp.model.units import unit

from helpers import MACHINES, NETNS, PARAMS, PY, ROOT, machine_path, needs_netns

NAMES = sorted(os.path.splitext(os.path.basename(p))[0] for p in glob.glob(os.path.join(MACHINES, "*.yaml")))
TOLERANCES = os.path.join(ROOT, "configs", "tolerances")
CHECKS = os.path.join(ROOT, "configs", "checks")
BUILD = os.path.join(ROOT, "build")
E2E_CONFIG = os.path.join(ROOT, "tests", "e2e", "config_test.yaml")


class Run:
    def __init__(self, returncode, stdout, stderr):
        self.returncode, self.stdout, self.stderr = returncode, stdout, stderr


def run_cli(*args, check=True):
    """`chaincomp ARGS` in this process (the matrix makes ~100 calls: a fresh interpreter
    and sympy import each would cost a second apiece), from the repository root."""
    out, err = io.StringIO(), io.StringIO()
    cwd = os.getcwd()
    os.chdir(ROOT)
    try:
        with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
            code = chaincomp_main(list(args))
    finally:
        os.chdir(cwd)
    if check and code != 0:
        raise AssertionError(f"chaincomp {' '.join(args)} exited {code}:\n{err.getvalue()}")
    return Run(code, out.getvalue(), err.getvalue())


def raw(name):
    """The machine file as plain YAML: what the verbs are checked against."""
    with open(machine_path(name)) as f:
        return yaml.safe_load(f)


def declared(name, role):
    return [s["name"] for s in raw(name)["symbols"] if s["role"] == role]


def params_file(name):
    """The machine's first bundled params file whose values are all constants (budget and
    the round trips below take constants; five_axis_ac's tables have their own tests)."""
    for path in sorted(glob.glob(os.path.join(PARAMS, f"{name}-*.yaml"))):
        with open(path) as f:
            if all(not isinstance(v, dict) for v in yaml.safe_load(f)["values"].values()):
                return path
    raise AssertionError(f"no params file with constant values for {name}")


def rotary(name):
    return [s["name"] for s in raw(name)["symbols"] if s["role"] == "axis" and unit(s["unit"]).kind == "angle"]


def five_axis(name):
    """Point and tool axis both correctable: two rotary axes and three linear ones."""
    return len(rotary(name)) == 2 and len(declared(name, "axis")) == 5


def at(name, fraction):
    """Axis values (declared units) a fraction of the way through each axis' limits."""
    return {s["name"]: s["limits"][0] + fraction * (s["limits"][1] - s["limits"][0])
            for s in raw(name)["symbols"] if s["role"] == "axis"}


def truth(name):
    """Internal values of every symbol: constants nominal, errors from the params file."""
    m = load_machine(machine_path(name))
    v = m.nominal_values()
    v.update(load_params(params_file(name), m))
    return m, v


_EXACT: dict = {}


def exact_pose(m, values, axes_declared):
    """The exact chain (chaincomp's Python model) at axes given in declared units, one row
    per command."""
    if m.name not in _EXACT:
        _EXACT[m.name] = ExactModel(m)
    axes_declared = np.asarray(axes_declared, float)
    v = dict(values)
    for i, a in enumerate(m.axes):
        v[a.name] = axes_declared[:, i] * a.unit.to_internal
    p, d = _EXACT[m.name].pose(v)

    def rows(c):  # a coordinate that does not depend on the axes comes back as a scalar
        return np.stack([np.broadcast_to(np.asarray(x, float), len(axes_declared)) for x in c], axis=1)
    return rows(p), (rows(d) if d is not None else None)


def sets(values):
    return [x for k, val in values.items() for x in ("--set", f"{k}={val!r}")]


machine = pytest.mark.parametrize("name", NAMES)


# ---------------------------------------------------------------- derive, eval, generate

@pytest.mark.slow
@machine
def test_derive(name):
    out = json.loads(run_cli("derive", machine_path(name), "--format", "json").stdout)
    errors, axes = declared(name, "error"), declared(name, "axis")
    tool = raw(name)["tool"]
    has_direction = "direction" in tool or "rotation" in tool
    has_frame = "reference" in tool or "rotation" in tool   # a tool frame: its rotation vector's rows too
    rows = ["dx", "dy", "dz"] + (["dkx", "dky", "dkz"] if has_direction else []) \
        + (["wx", "wy", "wz"] if has_frame else [])
    assert sorted(out["gain"]) == sorted(rows)
    for r in rows:  # a gain for every declared error, no other
        assert sorted(out["gain"][r]) == sorted(errors), r
    assert sorted(out["jacobian"]["x"]) == sorted(axes)


@machine
def test_eval(name):
    """At an interior point with the bundled params: the second-order error is nearer the
    exact one than the first-order, both within a second-order residual (errors ~1e-4
    relative), and the exact one is the difference of two exact poses."""
    axes = at(name, 0.3)
    out = json.loads(run_cli("eval", machine_path(name), "--params", params_file(name), *sets(axes),
                             "--json").stdout)
    first, second, exact = (np.array(out["error"][k]) for k in ("first", "second", "exact"))
    size = np.abs(exact).max()
    assert size > 1e-6  # the params move the tool at this point: the comparisons mean something
    assert np.abs(first - exact).max() <= 1e-3 * size
    assert np.abs(second - exact).max() <= np.abs(first - exact).max() + 1e-15
    m, values = truth(name)
    row = [[axes[a.name] for a in m.axes]]
    zero = {k: (0.0 if m.symbol(k).role == "error" else v) for k, v in values.items()}
    p1, _ = exact_pose(m, values, row)
    p0, _ = exact_pose(m, zero, row)
    assert np.allclose(out["position"], p0[0], rtol=0, atol=1e-9)
    assert np.allclose(exact, p1[0] - p0[0], rtol=0, atol=1e-12)


def _newest_source(name):
    paths = glob.glob(os.path.join(ROOT, "codegen", "chaincomp", "**", "*.py"), recursive=True)
    return max(os.path.getmtime(p) for p in paths + [machine_path(name)])


@pytest.mark.slow
@machine
def test_generate_is_the_compiled_model(name, tmp_path):
    """generate writes the machine's C++ in its own namespace, under a banner naming the
    file; when the build is newer than the code generator and the machine file, it is the
    C++ the build compiled into the registry, byte for byte."""
    run_cli("generate", machine_path(name), "-o", str(tmp_path))
    header = (tmp_path / f"{name}.hpp").read_text()
    assert header.startswith(f"// Generated by chaincomp generate from {name}.yaml")
    assert f"namespace chaincomp::models::{name} {{" in header
    built = os.path.join(BUILD, "generated", f"{name}.cpp")
    if not os.path.isfile(built) or os.path.getmtime(built) < _newest_source(name):
        pytest.skip("the C++ build is older than codegen/ or the machine file: cmake --build build")
    for ext in ("hpp", "cpp"):
        with open(os.path.join(BUILD, "generated", f"{name}.{ext}"), "rb") as a, \
                open(tmp_path / f"{name}.{ext}", "rb") as b:
            assert a.read() == b.read(), f"{name}.{ext} differs from the build's"


# ---------------------------------------------------------------- check, protocol

def _check_files():
    pairs = []
    for path in sorted(glob.glob(os.path.join(CHECKS, "*.yaml"))):
        with open(path) as f:
            pairs.append((yaml.safe_load(f)["machine"], path))
    return pairs


CHECK_PAIRS = _check_files()
# formulas written from the standards' definitions, which the chains must reproduce (the
# other files are the seeds' printed formulas, which hold known mistakes)
STANDARD_CHECKS = {"vmc_xyz_iso230.yaml", "trunnion_ac_iso230_7.yaml"}


def test_every_check_file_names_a_bundled_machine():
    assert CHECK_PAIRS and all(m in NAMES for m, _ in CHECK_PAIRS)


@pytest.mark.parametrize("name, path", CHECK_PAIRS, ids=[os.path.basename(p) for _, p in CHECK_PAIRS])
def test_check(name, path):
    """Every formula of the file compared; exit 0 (all equal) or 1 (some differ, as the
    seeds' hand-derived formulas do), as the JSON says."""
    proc = run_cli("check", machine_path(name), path, "--json", check=False)
    assert proc.returncode in (0, 1), proc.stderr
    out = json.loads(proc.stdout)
    with open(path) as f:
        n = len(yaml.safe_load(f)["formulas"])
    results = out["formulas"] if "formulas" in out else out["results"]
    assert len(results) == n
    assert proc.returncode == (0 if all(r.get("equal") for r in results) else 1)
    if os.path.basename(path) in STANDARD_CHECKS:  # derived by hand from ISO 230-1 / 230-7
        assert proc.returncode == 0, proc.stdout


@pytest.mark.slow
@machine
def test_protocol(name):
    """An arm gets a pose design, a machine without rotary axes a plan of laser runs,
    diagonals and tracker points (their ranks: test_protocol_xyz.py, test_protocol_arm.py).
    With rotary axes: every equation of every test holds for the exact chain at its set-ups
    (errors 1 % of the bundled values, so what first order leaves out is ~1e-8 mm against
    ~1e-4 mm of error terms)."""
    proc = run_cli("protocol", machine_path(name), "--format", "json", check=False)
    if is_arm(load_machine(machine_path(name))):
        assert proc.returncode == 0 and json.loads(proc.stdout)["kind"] == "pose design", proc.stderr
        return
    if not rotary(name):
        assert proc.returncode == 0, proc.stderr
        out = json.loads(proc.stdout)
        assert out["kind"] == "linear axes" and out["stages"], out
        return
    assert proc.returncode == 0, proc.stderr
    out = json.loads(proc.stdout)
    m, values = truth(name)
    small = {k: (0.01 * v if m.symbol(k).role == "error" else v) for k, v in values.items()}
    local = {s.name: s.sym for s in m.symbols}
    at_values = {s.sym: small[s.name] for s in m.symbols if s.role != "axis"}
    equations = [e for t in out["tests"] for e in t["equations"]]
    assert equations
    for eq in equations:
        coordinate = "xyz".index(eq["coordinate"])
        rows = [[{**out["fixed"], **setup}[a.name] for a in m.axes] for setup in eq["setups"]]
        p, _ = exact_pose(m, small, rows)
        measured = p[0, coordinate] + (1 if eq["operation"] == "sum" else -1) * p[1, coordinate]
        predicted = float(sp.sympify(eq["nominal"], locals=local).subs(at_values)
                          + sp.sympify(eq["error"], locals=local).subs(at_values))
        assert abs(measured - predicted) < 1e-7, (eq["lhs"], eq["equation"], measured, predicted)


# ---------------------------------------------------------------- identify

@machine
def test_simulate_measurements_identify_round_trip(name, tmp_path):
    """Noise-free measurements at random set-ups: every error identify gives a value is
    the true one, and every error is either estimated or said to be unidentifiable."""
    m, values = truth(name)
    meas = tmp_path / "meas.csv"
    setups = max(20, 2 * len(m.errors))
    run_cli("simulate-measurements", machine_path(name), "--params", params_file(name), "--setups",
            f"random:{setups}", "--seed", "3", "-o", str(meas))
    out = json.loads(run_cli("identify", machine_path(name), str(meas), "--format", "json",
                             "-o", str(tmp_path / "id.yaml")).stdout)
    assert out["setups"] == setups and out["estimates"]
    assert set(out["estimates"]) | set(out["unidentifiable"]) == {e.name for e in m.errors}
    for err, est in out["estimates"].items():
        got = unit(est["unit"]).to_internal * est["value"]
        # noise-free data: exact up to the second-order terms the first-order split leaves
        assert abs(got - values[err]) <= 1e-3 * abs(values[err]) + 1e-10, (err, est, values[err])
    identified = load_params(str(tmp_path / "id.yaml"), m)
    assert set(identified) == set(out["estimates"])


# ---------------------------------------------------------------- budget

@pytest.mark.slow
@machine
def test_budget(name):
    """At each position component's worst point, the worst case is the sum over errors of
    the exact chain's secant across +-bound (second-order terms cancel in a central
    secant), rss and sigma lie below it, and the Monte Carlo's largest deviation too."""
    tol = os.path.join(TOLERANCES, f"{name}.yaml")
    source = ["--tolerances", tol] if os.path.isfile(tol) else ["--params", params_file(name)]
    out = json.loads(run_cli("budget", machine_path(name), *source, "--grid", "3", "--samples", "2000",
                             "--format", "json").stdout)
    m = load_machine(machine_path(name))
    bounds = {e["error"]: unit(e["unit"]).to_internal * e["bound"] for e in out["tolerances"]["errors"]}
    zero = m.nominal_values()
    for i, comp in enumerate(("dx", "dy", "dz")):
        c = out["components"][comp]["at_worst"]
        row = [[c["axes"][a.name] for a in m.axes]]
        worst = 0.0
        for err, b in bounds.items():
            (p_plus,), _ = exact_pose(m, {**zero, err: b}, row)
            (p_minus,), _ = exact_pose(m, {**zero, err: -b}, row)
            worst += abs(p_plus[i] - p_minus[i]) / 2
        assert c["worst"] == pytest.approx(worst, rel=1e-6, abs=1e-12), comp
        assert c["sigma"] <= c["rss"] * (1 + 1e-12) <= c["worst"] * (1 + 1e-9) + 1e-15
        if c["worst"] > 0:  # beyond it by second-order terms only (errors up to ~5e-4 rad)
            assert c["monte_carlo"]["max"] <= c["worst"] * (1 + 1e-2), comp


# ---------------------------------------------------------------- replay, daemon

@pytest.fixture(scope="module")
def logs(tmp_path_factory):
    """A 0.2 s (200-command) simulate-log toolpath per machine, made once."""
    folder = tmp_path_factory.mktemp("logs")
    made = {}

    def get(name):
        if name not in made:
            path = str(folder / f"{name}.lcmlog")
            run_cli("simulate-log", machine_path(name), "-o", path, "--seconds", "0.2")
            made[name] = path
        return made[name]
    return get


def replay_csv(name, log, tmp_path):
    out = tmp_path / "replay.csv"
    run_cli("replay", machine_path(name), log, "--params", params_file(name), "--config", E2E_CONFIG,
            "--csv", str(out))
    with open(out) as f:
        return list(csv.DictReader(f))


def needs_build():
    if not os.path.isfile(os.path.join(BUILD, "bin", "chaincomp_replay")):
        pytest.skip("no C++ build (tools/setup)")


def arm(name):
    """Six or more joints, all rotary: the point and the direction are reachable away from
    singular poses (the turn about the tool axis is left free: issue #17 item 4)."""
    axes = declared(name, "axis")
    return len(axes) >= 6 and len(rotary(name)) == len(axes)


def point_correctable(name):
    """Three linear axes reach any point; fewer leave a residual (kResidual, status 1)."""
    return len(declared(name, "axis")) - len(rotary(name)) >= 3


@machine
def test_simulate_log_replay(name, logs, tmp_path):
    """Every command compensated. Where the axes can reach it (three linear axes), the
    exact chain at the corrected axes puts the tool where the nominal chain puts it at the
    commanded axes (the tool axis too on five axes); elsewhere the residual replay reports
    is the one the exact chain leaves."""
    needs_build()
    rows = replay_csv(name, logs(name), tmp_path)
    m, values = truth(name)
    units = [s["unit"] for s in raw(name)["symbols"] if s["role"] == "axis"]
    cmd = [[float(r[f"commanded_{a.name}_{u}"]) for a, u in zip(m.axes, units)] for r in rows]
    cor = [[float(r[f"corrected_{a.name}_{u}"]) for a, u in zip(m.axes, units)] for r in rows]
    zero = {k: (0.0 if m.symbol(k).role == "error" else v) for k, v in values.items()}
    p_act, d_act = exact_pose(m, values, cor)
    p_nom, d_nom = exact_pose(m, zero, cmd)
    miss = np.linalg.norm(p_act - p_nom, axis=1)
    assert len(rows) == 200 and all(r["result"] == "ok" for r in rows)
    assert np.abs(np.array(cmd) - np.array(cor)).max() > 0  # something was corrected
    if point_correctable(name) and (five_axis(name) or m.tool_direction is None):
        assert all(r["status"] == "0" for r in rows)
        assert miss.max() < 1e-6
        if five_axis(name):
            assert np.linalg.norm(d_act - d_nom, axis=1).max() < 1e-9
    elif point_correctable(name):  # three slides: the point corrected, the tilt left and reported
        assert miss.max() < 1e-6
        tilt = np.linalg.norm(d_act - d_nom, axis=1)
        assert np.allclose(tilt, [float(r["residual_direction_rad"]) for r in rows], rtol=1e-6, atol=1e-12)
        assert [r["status"] for r in rows] == ["1" if t > 1e-9 else "0" for t in tilt]
    elif arm(name):   # corrected (0), or near a singular pose the residual reported (1)
        ok = np.array([r["status"] == "0" for r in rows])
        assert {r["status"] for r in rows} <= {"0", "1"} and ok.sum() >= 100
        assert miss[ok].max() < 1e-6 and np.linalg.norm(d_act - d_nom, axis=1)[ok].max() < 1e-9
        reported = np.array([float(r["residual_point_mm"]) for r in rows])
        assert np.allclose(miss[~ok], reported[~ok], rtol=1e-6, atol=1e-10)
    else:
        assert all(r["status"] == "1" for r in rows)
        assert np.allclose(miss, [float(r["residual_point_mm"]) for r in rows], rtol=1e-6, atol=1e-10)


@needs_netns
@machine
def test_chaincompd_end_to_end(name, logs, tmp_path):
    """The same 200 commands through chaincompd over LCM (udpm, ttl=0, in a network
    namespace): every one answered, in order, with the very targets replay computes."""
    needs_build()
    log = logs(name)
    out = tmp_path / "daemon.json"
    proc = subprocess.run([NETNS, PY, "tests/e2e/e2e_machine.py", machine_path(name), params_file(name), E2E_CONFIG,
                           log, str(out)], capture_output=True, text=True, cwd=ROOT, timeout=60)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    with open(out) as f:
        live = json.load(f)
    assert live["complete"] and live["received"] == 200 and sum(live["rejected"]) == 0, live
    assert [t["seq"] for t in live["targets"]] == list(range(1, 201))
    offline = replay_csv(name, log, tmp_path)
    m = load_machine(machine_path(name))
    n = len(m.axes)
    names = [k for k in offline[0] if k.startswith("corrected_")]
    for t, r in zip(live["targets"], offline):
        assert t["axes"][:n] == [float(r[k]) for k in names], (t["seq"], t["axes"][:n])
        assert t["status"] == int(r["status"]) and t["flags"] == int(r["flags"])


# ---------------------------------------------------------------- export

@machine
def test_export_linuxcnc_tables(name, tmp_path):
    """The per-joint tables of every machine, read back as LinuxCNC reads them (the test's
    reader, linuxcnc_comp.py) and replayed on the exact chain at the check grid: the tool
    error the report says they leave, and never more than without them."""
    import linuxcnc_comp

    out = tmp_path / "comp"
    r = run_cli("export", machine_path(name), "--params", params_file(name), "--controller", "linuxcnc-comp", "-o",
                str(out), "--grid", "5", "--entries", "9", "--no-breakdown", "--format", "json", check=False)
    worse = re.search(r"leaves more tool error than no compensation .*largest tool error ([0-9.]+) um without it, "
                      r"([0-9.]+) um with it", r.stderr)
    if worse:   # never worse (design §12): per-joint tables cannot carry a nutating table's location errors
        assert r.returncode == 2 and float(worse.group(2)) > float(worse.group(1)) and not out.exists()
        return
    assert r.returncode == 0, r.stderr
    doc = json.loads(r.stdout)
    m, values = truth(name)
    # the check points the report promises: 5 per axis, and each joint between its 9 entries
    limits = [s["limits"] for s in raw(name)["symbols"] if s["role"] == "axis"]
    grids = [np.linspace(*lim, 5) for lim in limits]
    mids = [(lambda e: (e[1:] + e[:-1]) / 2)(np.linspace(*lim, 9)) for lim in limits]
    sets = [grids] + [[mids[j] if k == j else g for k, g in enumerate(grids)] for j in range(len(grids))]
    q = np.concatenate([np.stack([g.ravel() for g in np.meshgrid(*per_axis, indexing="ij")], axis=1)
                        for per_axis in sets])                                          # declared units
    tables = [linuxcnc_comp.read((out / f"joint{n}_{a.name}.comp").read_text(), 1) for n, a in enumerate(m.axes)]
    assert all(len(t) == 9 for t in tables)
    driven = q + np.stack([linuxcnc_comp.trim(t, q[:, n]) for n, t in enumerate(tables)], axis=1)
    nominal = {k: v for k, v in values.items() if m.symbol(k).role != "error"}
    actual, _ = exact_pose(m, values, driven)
    commanded, _ = exact_pose(m, nominal, q)
    residual = np.linalg.norm(actual - commanded, axis=1) * 1e3
    assert doc["after"]["max_um"] == pytest.approx(residual.max(), rel=1e-6, abs=1e-6)
    assert doc["after"]["max_um"] <= doc["before"]["max_um"] * (1 + 1e-9)


# ---------------------------------------------------------------- thermal

@machine
def test_simulate_thermal_then_fit(name, tmp_path):
    """A thermal model of the machine's first length error (and first angle error, if any),
    written here: simulate-thermal's log at 0.2 Hz, then thermal fit finds each error's one
    sensor out of five, its gain and time constant within 5 %."""
    errors = [s for s in raw(name)["symbols"] if s["role"] == "error"]
    chosen = {}
    for kind, (sensor, gain, tau, u) in (("length", ("T_spindle", 1.0, 900.0, "um")),
                                         ("angle", ("T_coolant", 3.0, 600.0, "arcsec"))):
        first = next((s["name"] for s in errors if unit(s["unit"]).kind == kind), None)
        if first:
            chosen[first] = (sensor, gain, tau, u)
    true = tmp_path / "true.yaml"
    true.write_text(f"machine: {raw(name)['name']}\nerrors:\n" + "".join(
        f"  {e}:\n    unit: {u}\n    terms:\n      - {{sensor: {s}, gain: {g}, time_constant: {tau}}}\n"
        for e, (s, g, tau, u) in chosen.items()))
    log, fit = tmp_path / "log.csv", tmp_path / "fit.yaml"
    run_cli("simulate-thermal", machine_path(name), "--truth", str(true), "-o", str(log), "--rate", "0.2")
    doc = json.loads(run_cli("thermal", "fit", machine_path(name), str(log), "-o", str(fit), "--json").stdout)
    assert sorted(doc["errors"]) == sorted(chosen)
    for e, (s, g, tau, u) in chosen.items():
        terms = doc["errors"][e]["terms"]
        assert [t["sensor"] for t in terms] == [s], (e, terms)
        assert doc["errors"][e]["unit"] == u
        assert terms[0]["gain"] == pytest.approx(g, rel=0.05) and terms[0]["time_constant"] == pytest.approx(tau, rel=0.05)
    with open(fit) as f:   # the file holds what the report says
        written = yaml.safe_load(f)["errors"]
    for e in chosen:
        assert written[e]["terms"][0]["gain"] == pytest.approx(doc["errors"][e]["terms"][0]["gain"], rel=1e-5)


@machine
def test_export_isg_volcomp(name, tmp_path):
    """ISG's volumetric compensation file of every machine with linear axes X, Y, Z, read by
    the test's reader (isg_csv.py, from ISG's manual): each ISO 230-1 error of the params
    file (read with plain YAML, converted by hand) under its ISG name in mm or rad; machines
    without X, Y, Z are refused in one line and nothing is written."""
    import isg_csv

    out = tmp_path / "isg"
    linear = {s["name"] for s in raw(name)["symbols"] if s["role"] == "axis" and s["unit"] == "mm"}
    r = run_cli("export", machine_path(name), "--params", params_file(name), "--controller", "isg-volcomp", "-o",
                str(out), "--grid", "3", "--no-breakdown", "--format", "json", check=False)
    if not {"X", "Y", "Z"} <= linear:
        assert r.returncode == 2 and "needs three linear axes X, Y, Z" in r.stderr, r.stderr
        assert len(r.stderr.strip().splitlines()) == 1 and not out.exists()
        return
    with open(params_file(name)) as f:
        given = yaml.safe_load(f)["values"]
    if not any(isg_csv.COMPONENT.match(e) or isg_csv.POSITION.match(e[1:]) for e in given):
        assert r.returncode == 2 and "represents none of the errors given" in r.stderr, r.stderr
        assert len(r.stderr.strip().splitlines()) == 1 and not out.exists()
        return
    assert r.returncode == 0, r.stderr
    blocks = isg_csv.read((out / "volcomp.csv").read_text())
    per = {"um": 1e-3, "mm": 1.0, "arcsec": np.pi / 648000, "urad": 1e-6, "mrad": 1e-3, "deg": np.pi / 180}
    carried = json.loads(r.stdout)["isg"]["names"]
    for err, text in given.items():
        iso = err if isg_csv.COMPONENT.match(err) else err[1:] if isg_csv.POSITION.match(err[1:]) else None
        if iso is None or float(str(text).split()[0]) == 0:
            assert err not in carried
            continue
        number, unit_name = str(text).split()
        inclined = re.match(r"\w+ turns about \(([^)]*)\)", json.loads(r.stdout)["isg"]["left_out"].get(err, ""))
        if inclined:   # an axis along no coordinate axis (a nutating table's B): ISG has no name for its errors
            w = np.abs([float(v) for v in inclined.group(1).split(",")])
            assert err not in carried and 1e-6 < w.max() < 1 - 1e-6
            continue
        assert carried[err] == iso
        assert isg_csv.value(blocks, iso) == pytest.approx(float(number) * per[unit_name], abs=1e-12), err
