"""Sphere probing (chaincomp probe plan / simulate / fit) on the bundled nutating table and on a
second five-axis kinematics written here (a B head tilting about y over a C table), with the
acceptance of issue #45: at 1 µm of noise per logged coordinate the identifiable location
errors are recovered within 2 sigma in at least 90 % of 20 seeds, the ones a sphere cannot see
are named, and a near-singular plan is refused.

What a sphere cannot see is reasoned here, not read from the code: a rotary table's zero angle
turns the part (and the sphere with it) about the table's axis, which a move of the sphere
absorbs; the nutating table's B zero is a turn about its inclined axis w = (0, -sin 45°,
cos 45°), cos 45° of it about C's axis (a turn of the part again) and sin 45° of it about a
line across C's axis: a tilt of C, so B's zero and C's tilt about y are one combination, with
the coefficient sin 45°. A head's zero angle δ turns the tool about the pivot: the tool tip
moves by R(B)·(-Lp δ, 0, 0), which is (R(B) - I)·(-Lp δ, 0, 0), the pivot's line moved along x
by -Lp δ (its sandwich), plus the constant (-Lp δ, 0, 0) of the machine frame, a move of the
table's C line along x and of the sphere: a probe touching a sphere sees the tool tip, never
the tool's direction, so the head's zero is carried by B's and C's line positions in x with
the coefficient Lp.

The truth: the errors of the simulated machine drawn at random (10 µm, 20 arcsec), the errors
a sphere cannot see zero (a choice of the part frame and the pivot: with them zero the
identifiable errors' true values are those simulated); the sphere 0.1 to 0.3 mm from where the
plan expects it.
"""

import math
import os
import re
import shutil
import subprocess

import numpy as np
import pytest
import yaml

from chaincomp.measure import probe as P
from chaincomp.model.machine import load_machine
from chaincomp.model.params import load_params

from helpers import MACHINES, cli, run_cli

NUTATING = os.path.join(MACHINES, "nutating_bc45.yaml")
UM, ARCSEC = 1e-3, math.pi / (180 * 3600)

HEAD_TABLE = {
    "name": "head_b_table_c",
    "description": "B head tilting about y over a C rotary table (a test machine)",
    "length_unit": "mm", "rotation_sense": "right_hand", "error_block_order": "txyz",
    "symbols": [
        {"name": "X", "role": "axis", "unit": "mm", "limits": [-400, 400], "meaning": "X head"},
        {"name": "Y", "role": "axis", "unit": "mm", "limits": [-400, 400], "meaning": "Y head"},
        {"name": "Z", "role": "axis", "unit": "mm", "limits": [-600, 0], "meaning": "Z head"},
        {"name": "B", "role": "axis", "unit": "deg", "limits": [-60, 60], "meaning": "B head (tool turns about y)"},
        {"name": "C", "role": "axis", "unit": "deg", "limits": [-360, 360], "meaning": "C table (turns by -C)"},
        {"name": "H", "role": "constant", "unit": "mm", "nominal": 500, "meaning": "B pivot above the table at Z=0"},
        {"name": "Lp", "role": "constant", "unit": "mm", "nominal": 150, "meaning": "pivot to tool tip"},
        {"name": "hC", "role": "constant", "unit": "mm", "nominal": 40, "meaning": "table top"},
    ] + [{"name": n, "role": "error", "unit": u, "meaning": m} for n, u, m in [
        ("EX0B", "um", "B line position in x"), ("EZ0B", "um", "B line position in z"),
        ("EA0B", "arcsec", "B line orientation about x"), ("EC0B", "arcsec", "B line orientation about z"),
        ("EB0B", "arcsec", "zero of B"), ("EX0C", "um", "C line position in x"), ("EY0C", "um", "C line in y"),
        ("EA0C", "arcsec", "C about x"), ("EB0C", "arcsec", "C about y"), ("EC0C", "arcsec", "zero of C")]],
    "loop": {
        "tool": [
            {"translate": ["X", 0, 0]}, {"translate": [0, "Y", 0]}, {"translate": [0, 0, "H + Z"]},
            {"translate": ["EX0B", 0, "EZ0B"]}, {"errors": {"ex": "EA0B", "ez": "EC0B"}},
            {"rotate": "y", "angle": "B + EB0B"},
            {"errors": {"ex": "-EA0B", "ez": "-EC0B"}, "order": "zyxt"}, {"translate": ["-EX0B", 0, "-EZ0B"]},
            {"translate": [0, 0, "-Lp"]}],
        "workpiece": [
            {"translate": ["EX0C", "EY0C", 0]}, {"errors": {"ex": "EA0C", "ey": "EB0C"}},
            {"rotate": "z", "angle": "-(C + EC0C)"},
            {"errors": {"ex": "-EA0C", "ey": "-EB0C"}, "order": "zyxt"}, {"translate": ["-EX0C", "-EY0C", 0]},
            {"translate": [0, 0, "hC"]}]},
    "tool": {"point": [0, 0, 0], "direction": [0, 0, 1]},
}

SPHERE = {"nutating_bc45": P.Sphere((50.0, 30.0, 80.0), 12.5, 2.0),
          "head_b_table_c": P.Sphere((60.0, 20.0, 50.0), 12.5, 2.0)}
GAUGE = {"nutating_bc45": {"EB0B", "EC0C"}, "head_b_table_c": {"EB0B", "EC0C"}}   # what a sphere cannot see


@pytest.fixture(scope="module")
def machines(tmp_path_factory):
    path = tmp_path_factory.mktemp("probe") / "head_b_table_c.yaml"
    path.write_text(yaml.safe_dump(HEAD_TABLE, sort_keys=False))
    return {"nutating_bc45": load_machine(NUTATING), "head_b_table_c": load_machine(str(path))}


def _truth(machine, rng, gauge_zero=True):
    out = {}
    for s in machine.errors:
        size = 10 * UM if s.unit.kind == "length" else 20 * ARCSEC
        out[s.name] = 0.0 if gauge_zero and s.name in GAUGE[machine.name] else float(rng.normal(0, size))
    return out


def _run(machine, plan, seed, truth=None, backlash=None):
    """Simulated logs of ``plan`` on a true machine, fitted: (truth, true sphere, ProbeFit)."""
    rng = np.random.default_rng(seed)
    truth = truth if truth is not None else _truth(machine, rng)
    sphere = plan.sphere
    centre = tuple(np.array(sphere.centre) + rng.uniform(0.1, 0.3, 3) * rng.choice([-1, 1], 3))
    touches = P.plan_touches(plan)
    log = P.simulate_log(machine, touches, truth, centre, sphere, 1 * UM, rng, backlash)
    groups = P._grouped("log", machine, P.machine_axes(machine), _parse_log(machine, log), touches)
    return truth, centre, P.probe_fit(machine, groups, sphere)


def _parse_log(machine, text):
    """The log's lines as LinuxCNC writes them: nine numbers X Y Z A B C U V W (mm, degrees)."""
    letters = {"X": 0, "Y": 1, "Z": 2, "A": 3, "B": 4, "C": 5}
    out = []
    for k, line in enumerate(text.splitlines(), 1):
        nums = [float(v) for v in line.split()]
        assert len(nums) == 9 and all(len(v.split(".")[1]) == 6 for v in line.split())   # "%f"
        out.append((k, {a.name: nums[letters[a.name]] * (1.0 if a.unit.kind == "length" else math.pi / 180)
                        for a in machine.axes}))
    return out


def _coverage(machine, seeds):
    plan = P.make_plan(machine, SPHERE[machine.name])
    inside, total = 0, 0
    for seed in seeds:
        truth, centre, pf = _run(machine, plan, seed)
        f = pf.fit
        assert set(pf.gauge) == GAUGE[machine.name]
        for name, value in f.estimates.items():
            if name in P.NUISANCE:
                continue
            total += 1
            inside += abs(value - truth[name]) <= 2 * f.uncertainties[name]
        # the sphere's offset is where the simulation put it
        for k, n in enumerate(P.NUISANCE):
            assert abs(f.estimates[n] - (centre[k] - SPHERE[machine.name].centre[k])) <= 5 * f.uncertainties[n]
        assert pf.dispersion["all"][1] < 6 * UM < pf.dispersion["all"][0]
    return inside / total


@pytest.mark.parametrize("name", ["nutating_bc45", "head_b_table_c"])
def test_location_errors_within_two_sigma_twenty_seeds(machines, name):
    """The issue's acceptance: 20 seeds (about 3 s a machine, so in the fast tier). A correct
    standard uncertainty, estimated from 37 degrees of freedom, puts 94.7 % within 2 sigma (Student's
    t); windows of 20 seeds of seeds 0-99 gave 88.8 to 98.1 % here, the 100 seeds 94.1 % (nutating)
    and 93.6 % (head/table): test_coverage_hundred_seeds holds that."""
    assert _coverage(machines[name], range(100, 120)) >= 0.9


@pytest.mark.slow
@pytest.mark.parametrize("name", ["nutating_bc45", "head_b_table_c"])
def test_coverage_hundred_seeds(machines, name):
    assert _coverage(machines[name], range(100)) >= 0.92


def test_gauge_named_and_carried_by_the_geometry(machines):
    """B's zero on the nutating table is C's tilt about y times sin 45° (see the docstring), and
    with it and C's zero far from zero the fit still reproduces every probed centre."""
    m = machines["nutating_bc45"]
    plan = P.make_plan(m, SPHERE[m.name])
    carried = plan.valuation.fit.carried
    assert set(plan.valuation.gauge) == GAUGE[m.name]
    assert abs(abs(carried["EB0B"]["EB0C"]) - math.sin(math.radians(45))) < 1e-9
    assert not [n for n in carried["EC0C"] if n not in P.NUISANCE]     # the sphere's position alone
    truth = _truth(m, np.random.default_rng(5), gauge_zero=False)
    truth.update(EB0B=60 * ARCSEC, EC0C=-80 * ARCSEC)
    _, _, pf = _run(m, plan, 5, truth)
    assert pf.dispersion["all"][1] < 6 * UM
    assert "EB0B" in pf.gauge and "set it with the work offset" in pf.gauge["EC0C"]
    # together right: C's tilt about y carries B's zero with the geometry's coefficient
    k = carried["EB0B"]["EB0C"]
    assert abs(pf.fit.estimates["EB0C"] - (truth["EB0C"] + k * truth["EB0B"])) <= 3 * pf.fit.uncertainties["EB0C"]
    hb = machines["head_b_table_c"]
    value = P.make_plan(hb, SPHERE[hb.name]).valuation
    assert set(value.gauge) == GAUGE[hb.name]
    assert value.fit.carried["EB0B"]["EX0B"] == pytest.approx(150.0) == value.fit.carried["EB0B"]["EX0C"]


def test_backlash_from_two_approaches(machines):
    m = machines["nutating_bc45"]
    plan = P.make_plan(m, SPHERE[m.name], backlash_step=math.radians(2))
    backlash = {"B": 15 * ARCSEC, "C": 30 * ARCSEC}
    truth, _, pf = _run(m, plan, 7, backlash=backlash)
    for axis, true in backlash.items():
        value, sigma = pf.backlash[axis]
        assert abs(value - true) <= 3 * sigma and sigma < 3 * ARCSEC
    for name, value in pf.fit.estimates.items():       # the two approaches averaged: no bias
        if name not in P.NUISANCE:
            assert abs(value - truth[name]) <= 4 * pf.fit.uncertainties[name]


def _rot(axis, a):
    c, s = math.cos(a), math.sin(a)
    i, j = {"x": (1, 2), "y": (2, 0), "z": (0, 1)}[axis]
    r = np.eye(3)
    r[i, i], r[i, j], r[j, i], r[j, j] = c, -s, s, c
    return r


def _nutating_tool_point(x, y, z, b, c):
    """The nominal nutating table written here: the workpiece is Rx(45°) Rz(-B) Rx(-45°) Rz(-C)
    T(0, 0, hC) from the reference, the tool (X, Y, H + Z - L); the tool point in the workpiece
    frame is that chain's inverse applied to it (H 450, L 100, hC 60; angles in degrees)."""
    nb = math.radians(45)
    tool = np.array([x, y, 450 + z - 100])
    p = _rot("z", math.radians(c)) @ _rot("x", nb) @ _rot("z", math.radians(b)) @ _rot("x", -nb) @ tool
    return p - [0, 0, 60]


def test_gcode_program_touches_the_sphere(tmp_path):
    """The LinuxCNC program, read as RS274/NGC (LinuxCNC's G-code overview: words, comments in
    parentheses, PROBEOPEN/PROBECLOSE logging): every G38.2 move starts clear of the sphere and
    reaches the contact distance R + r before its end point, on the nominal model written here;
    the program zeroes and selects G59.3, cancels the tool length offset and ends with M2."""
    long = tmp_path / ("x" * 200)
    long.mkdir()
    ngc, csv = long / "plan.ngc", long / "plan.csv"      # a command line longer than a G-code line
    run_cli("probe", "plan", NUTATING, "--sphere", "50,30,80", "--radius", "12.5", "--stylus", "2",
            "--gcode", str(ngc), "--csv", str(csv), "--log-name", "cal(1).txt")
    lines = ngc.read_text().splitlines()
    assert max(len(line) for line in lines) <= 252     # LinuxCNC's longest line (rs274ngc read_text, LINELEN 255)
    assert "(PROBEOPEN cal[1].txt)" in lines and lines[-1] == "M2" and "(PROBECLOSE)" in lines
    assert "G59.3" in lines and any(line.startswith("G10 L2 P9 X0 Y0 Z0 B0 C0") for line in lines)
    assert any("G49" in line.split() for line in lines)
    pos = dict(X=0.0, Y=0.0, Z=0.0, B=0.0, C=0.0)
    s0, contact, probes = np.array([50.0, 30.0, 80.0]), 14.5, 0
    for line in lines:
        words = line.split("(")[0].split()
        if not words or words[0] not in ("G0", "G38.2"):
            continue
        new = dict(pos, **{w[0]: float(w[1:]) for w in words[1:]})
        if words[0] == "G38.2":
            assert {w[0] for w in words[1:]} <= {"X", "Y", "Z"}
            path = [_nutating_tool_point(*(pos[k] + t * (new[k] - pos[k]) for k in "XYZ"), pos["B"], pos["C"])
                    for t in np.linspace(0, 1, 201)]
            gap = np.linalg.norm(np.array(path) - s0, axis=1) - contact
            assert gap[0] > 2.9 and gap[-1] < -2.9     # 3 mm clearance before, 3 mm past the surface
            probes += 1
        pos = new
    assert probes == len(P.read_plan(str(csv), load_machine(NUTATING))) == 16 * 6   # 4 x 4 positions, 6 touches


def test_cli_loop_writes_production_params(tmp_path):
    """plan -> simulate -> fit -> params: the file is the machine's (no sphere), loads, holds the
    errors of --hold as given, and eval reads it."""
    plan, log, out = tmp_path / "plan.csv", tmp_path / "probe.txt", tmp_path / "fitted.yaml"
    true, hold = tmp_path / "true.yaml", tmp_path / "hold.yaml"
    true.write_text("machine: nutating_bc45\nvalues:\n  EU0B: 6 um\n  EV0B: -4 um\n  EAU0B: 12 arcsec\n"
                    "  EX0C: 8 um\n  EY0C: -5 um\n  EA0C: 15 arcsec\n  EB0C: -9 arcsec\n")
    hold.write_text("machine: nutating_bc45\nvalues:\n  EX0C: 8 um\n  EY0C: -5 um\n")
    sphere = ["--sphere", "50,30,80", "--radius", "12.5", "--stylus", "2"]
    cli("probe", "plan", NUTATING, *sphere, "--csv", str(plan))
    cli("probe", "simulate", NUTATING, str(plan), "--sphere", "50.2,29.9,80.1", "--radius", "12.5", "--stylus", "2",
        "--params", str(true), "--seed", "3", "-o", str(log))
    r = cli("probe", "fit", NUTATING, str(log), "--plan", str(plan), *sphere, "--hold", str(hold), "-o", str(out),
            "--json")
    assert r.returncode == 0, r.stderr
    m = load_machine(NUTATING)
    values = load_params(str(out), m)
    assert not [n for n in values if n.startswith("SPHERE")]
    assert values["EX0C"] == pytest.approx(8 * UM) and values["EY0C"] == pytest.approx(-5 * UM)
    assert values["EB0B"] == 0 and values["EC0C"] == 0
    assert abs(values["EU0B"] - 6 * UM) < 2 * UM and abs(values["EAU0B"] - 12 * ARCSEC) < 3 * ARCSEC
    assert "held at a given value" in out.read_text()
    cli("eval", NUTATING, "--params", str(out), "--set", "B=30", "--set", "C=10", "--set", "X=0", "--set", "Y=0",
        "--set", "Z=-100")


def test_touches_and_centres_csv_read_alike(tmp_path, machines):
    """The same touches as LinuxCNC's log and as a CSV of touched points give the same fit; a
    CSV of the centres (radius column) as well."""
    m = machines["nutating_bc45"]
    plan = P.make_plan(m, SPHERE[m.name])
    log = P.simulate_log(m, P.plan_touches(plan), _truth(m, np.random.default_rng(2)), (50.1, 30.2, 79.9),
                         plan.sphere, UM, np.random.default_rng(2))
    (tmp_path / "log.txt").write_text(log)
    a = P.probe_fit(m, P.read_logs([str(tmp_path / "log.txt")], m), plan.sphere)
    rows = ["B,C,X,Y,Z"] + [f"{r[4]},{r[5]},{r[0]},{r[1]},{r[2]}" for r in (line.split() for line in log.splitlines())]
    (tmp_path / "touches.csv").write_text("\n".join(rows) + "\n")
    b = P.probe_fit(m, P.read_logs([str(tmp_path / "touches.csv")], m), plan.sphere)
    centres = ["X,Y,Z,B,C,radius"] + [
        ",".join(repr(float(v)) for v in [*c.centre, math.degrees(c.group.rotary["B"]),
                                          math.degrees(c.group.rotary["C"]), c.radius]) for c in a.centres]
    (tmp_path / "centres.csv").write_text("\n".join(centres) + "\n")
    c = P.probe_fit(m, P.read_logs([str(tmp_path / "centres.csv")], m), plan.sphere)
    for other in (b, c):
        for n, v in a.fit.estimates.items():
            assert other.fit.estimates[n] == pytest.approx(v, abs=1e-9)


def test_near_singular_plan_and_fit_refused(tmp_path, machines):
    """B turned by 1° only: B's line is hardly moved, its errors would be uncertain by tens of µm
    per µm of the centres: refused (exit 4, nothing written), the plan and the fit of its log."""
    near = "B=0,C=0;B=0,C=90;B=0,C=180;B=0,C=270;B=1,C=0;B=1,C=90;B=1,C=180;B=1,C=270"
    ngc = tmp_path / "near.ngc"
    r = run_cli("probe", "plan", NUTATING, "--sphere", "50,30,80", "--radius", "12.5", "--stylus", "2",
                "--positions", near, "--gcode", str(ngc), check=False)
    assert r.returncode == 4 and "near-singular" in r.stderr and not ngc.exists()
    assert len(r.stderr.strip().splitlines()) == 1
    # the same positions probed on a true machine: its sphere centres, 1 µm of noise, as a centres CSV
    m = machines["nutating_bc45"]
    axes = P.machine_axes(m)
    positions = P.parse_positions(m, axes, near)
    rng = np.random.default_rng(1)
    rot = {a.name: np.array([p[a.name] for p in positions]) for a in axes.rotary}
    centres = P.inverse_kinematics(m, P.HeldModel(m, _truth(m, rng)), axes, rot, np.tile([50.1, 30.0, 80.0], (8, 1)))
    centres += UM * rng.standard_normal(centres.shape)
    rows = ["X,Y,Z,B,C,radius"] + [f"{x!r},{y!r},{z!r},{math.degrees(p['B'])!r},{math.degrees(p['C'])!r},12.5"
                                   for (x, y, z), p in zip(centres.tolist(), positions)]
    (tmp_path / "near.csv").write_text("\n".join(rows) + "\n")
    out = tmp_path / "near.yaml"
    r = cli("probe", "fit", NUTATING, str(tmp_path / "near.csv"), "--sphere", "50,30,80", "--radius", "12.5",
            "--stylus", "2", "-o", str(out), check=False)
    assert r.returncode == 4 and "near-singular" in r.stderr and not out.exists()


def test_radius_off_refused(tmp_path, machines):
    """A probed radius 10 µm off the nominal (a dirty sphere, a wrong stylus): exit 4 with the
    numbers, nothing written."""
    m = machines["nutating_bc45"]
    plan = P.make_plan(m, SPHERE[m.name])
    wrong = P.Sphere(plan.sphere.centre, plan.sphere.radius + 0.010, plan.sphere.stylus)
    log = P.simulate_log(m, P.plan_touches(plan), {}, plan.sphere.centre, wrong, 0.0, np.random.default_rng(0))
    (tmp_path / "log.txt").write_text(log)
    out = tmp_path / "p.yaml"
    r = cli("probe", "fit", NUTATING, str(tmp_path / "log.txt"), "--sphere", "50,30,80", "--radius", "12.5",
            "--stylus", "2", "-o", str(out), check=False)
    assert r.returncode == 4 and "12.5100 mm" in r.stderr and "+10.0 µm" in r.stderr and not out.exists()


@pytest.mark.skipif(shutil.which("rs274") is None, reason="LinuxCNC's rs274 is not installed (tools/setup-linuxcnc)")
def test_linuxcnc_interpreter_runs_the_program(tmp_path):
    """LinuxCNC's own interpreter (rs274, the standalone RS274/NGC interpreter of the linuxcnc
    package) runs the program in batch mode without an error: one STRAIGHT_PROBE per touch of the
    CSV plan, aimed at its target at its rotary values, under a zero G59.3 offset and no tool
    length offset (so the probe log holds machine coordinates)."""
    long = tmp_path / ("x" * 200)   # the command in the first comment: lines as long as they get
    long.mkdir()
    ngc, csv, canon = long / "p.ngc", long / "p.csv", tmp_path / "canon.txt"
    run_cli("probe", "plan", NUTATING, "--sphere", "50,30,80", "--radius", "12.5", "--stylus", "2", "--backlash-step",
        "2deg", "--gcode", str(ngc), "--csv", str(csv))
    # by its name in its folder: rs274 keeps the program's path in LINELEN (255) characters
    r = subprocess.run(["rs274", "-g", ngc.name, str(canon)], stdin=subprocess.DEVNULL, capture_output=True,
                       text=True, cwd=long, timeout=300)
    text = canon.read_text()
    assert r.returncode == 0, r.stdout + r.stderr + text[-500:]
    assert "SET_G5X_OFFSET(9, 0.0000, 0.0000, 0.0000, 0.0000, 0.0000, 0.0000)" in text
    # G61: every move ends where programmed (a blended retract overshot the tool axis' limit under LinuxCNC)
    assert "SET_MOTION_CONTROL_MODE(CANON_EXACT_PATH)" in text
    assert "USE_TOOL_LENGTH_OFFSET(0.0000 0.0000 0.0000, 0.0000 0.0000 0.0000, 0.0000 0.0000 0.0000)" in text
    probes = [[float(v) for v in m.split(",")] for m in re.findall(r"STRAIGHT_PROBE\(([^)]*)\)", text)]
    touches = P.read_plan(str(csv), load_machine(NUTATING))
    assert len(probes) == len(touches) == 16 * 6 * 2
    for (x, y, z, a, b, c), t in zip(probes, touches):
        assert np.allclose([x, y, z], t.target, atol=6e-5)
        assert (b, c) == pytest.approx((math.degrees(t.start["B"]), math.degrees(t.start["C"])), abs=6e-5)
