"""chaincomp laser-to-params: simulated laser runs of configs/params/five_axis_ac-laser.yaml's
tables (the truth: the tables themselves, read with the product's loader) come back within the
noise; the written file loads, reproduces the measurement in the exact model, merges without
touching other entries, and is accepted by chaincompd's own loader."""

import math
import os
import random
import subprocess

import numpy as np
import pytest

from chaincomp.cli.main import main
from chaincomp.model.machine import load_machine
from chaincomp.symbolic.numeric import ExactModel
from chaincomp.model.params import load_params
from chaincomp.model.varying import Table
from helpers import DAEMON, PARAMS, machine_path

MACHINE = machine_path("five_axis_ac")
LASER = os.path.join(PARAMS, "five_axis_ac-laser.yaml")
DEMO = os.path.join(PARAMS, "five_axis_ac-demo.yaml")
UNIT = {"length": ("um", 1e-3), "angle": ("arcsec", math.pi / 648000)}
N, SIGMA, BACKLASH = 5, 0.1, 0.8   # runs, noise (µm or arcsec), reversal


@pytest.fixture(scope="module")
def machine():
    return load_machine(MACHINE)


@pytest.fixture(scope="module")
def truth(machine):
    return load_params(LASER, machine)


def simulate(path, machine, truth, error, targets, seed=0, sign=1.0):
    """Laser runs of ``error``'s table at ``targets``: up = table + B/2 + noise, down = table - B/2 + noise,
    in µm or arcsec, times ``sign`` (what the tool relative to the workpiece does)."""
    kind = machine.symbol(error).unit.kind
    name, scale = UNIT[kind]
    axis = truth[error].axis if error in truth else "X"
    rnd = random.Random(seed)
    rows = []
    for j in range(1, N + 1):
        for d, half in (("up", 0.5), ("down", -0.5)):
            for t in map(float, targets if half > 0 else targets[::-1]):
                true = truth[error](t * machine.symbol(axis).unit.to_internal) / scale if error in truth else 0.0
                rows.append(f"{t!r},{j},{d},{sign * true + half * BACKLASH + rnd.gauss(0, SIGMA)!r}")
    path.write_text(f"target [mm],run,direction,deviation [{name}]\n" + "\n".join(rows) + "\n")
    return path


def run(capsys, *argv):
    code = main(["laser-to-params", *map(str, argv)])
    out, err = capsys.readouterr()
    return code, err


def table_at(params, error, t_internal):
    return np.array([params[error](t) for t in t_internal])


@pytest.mark.parametrize("error,axis,targets", [
    ("EXX", "X", np.linspace(-400, 400, 41)),                 # positioning, µm
    ("EYX", "X", np.linspace(-400, 400, 21)),                 # straightness, µm
    ("EBX", "X", np.array([-400, -310, -180, -95, 0, 120, 260, 333, 400.0])),   # pitch, arcsec, unequal
    ("EZZ", "Z", np.linspace(-200, 200, 26)),                 # positioning of Z
    ("EAY", "Y", np.linspace(-300, 300, 31)),                 # pitch of Y
])
def test_round_trip_within_the_noise(tmp_path, capsys, machine, truth, error, axis, targets):
    csv = simulate(tmp_path / "runs.csv", machine, truth, error, targets, seed=sum(map(ord, error)))
    code, err = run(capsys, MACHINE, csv, "--error", error, "-o", tmp_path / "p.yaml")
    assert code == 0, err
    got = load_params(str(tmp_path / "p.yaml"), machine)
    assert set(got) == {error}
    table = got[error]
    assert isinstance(table, Table) and table.axis == axis and table.interpolation == "linear"
    t = targets * machine.symbol(axis).unit.to_internal
    scale = UNIT[machine.symbol(error).unit.kind][1]
    # the bidirectional mean cancels the reversal; its noise is SIGMA / sqrt(2N); 1e-4 is the rounding
    tol = 4 * SIGMA / math.sqrt(2 * N) + 1e-4
    assert np.max(np.abs(table_at(got, error, t) - table_at(truth, error, t))) / scale < tol
    assert np.allclose(table.x, t)


def test_one_direction_keeps_its_reversal(tmp_path, capsys, machine, truth):
    targets = np.linspace(-400, 400, 17)
    csv = simulate(tmp_path / "runs.csv", machine, truth, "EXX", targets)
    t = targets
    for direction, offset in (("up", BACKLASH / 2), ("down", -BACKLASH / 2)):
        out = tmp_path / f"{direction}.yaml"
        code, err = run(capsys, MACHINE, csv, "--error", "EXX", "--direction", direction, "-o", out)
        assert code == 0, err
        got = load_params(str(out), machine)
        diff = (table_at(got, "EXX", t) - table_at(truth, "EXX", t)) / 1e-3 - offset
        assert np.max(np.abs(diff)) < 4 * SIGMA / math.sqrt(N) + 1e-4


def test_the_model_reproduces_the_measurement(tmp_path, capsys, machine, truth):
    """With only the written table, the exact chain's tool error along x at X = P_i is the mean
    bidirectional deviation computed here from the CSV."""
    targets = np.linspace(-400, 400, 11)
    csv = simulate(tmp_path / "runs.csv", machine, truth, "EXX", targets, seed=4)
    assert run(capsys, MACHINE, csv, "--error", "EXX", "-o", tmp_path / "p.yaml")[0] == 0
    rows = [r.split(",") for r in csv.read_text().splitlines()[1:]]
    mean = [np.mean([float(r[3]) for r in rows if float(r[0]) == t]) for t in targets]
    params = load_params(str(tmp_path / "p.yaml"), machine)
    model = ExactModel(machine)
    for t, m in zip(targets, mean):
        dp, _ = model.error({**params, "X": float(t), "Y": 0.0, "Z": 0.0, "Ap": 0.0, "Cp": 0.0})
        assert dp[0] / 1e-3 == pytest.approx(m, abs=1e-4)


def _entry_range(lines, name, following):
    start = next(i for i, s in enumerate(lines) if s.startswith(f"  {name}:"))
    end = next(i for i, s in enumerate(lines) if s.startswith(f"  {following}:"))
    return start, end


@pytest.mark.slow
def test_merge_replaces_one_table_and_keeps_every_other_line(tmp_path, capsys, machine, truth):
    targets = np.linspace(-400, 400, 41)
    csv = simulate(tmp_path / "runs.csv", machine, truth, "EXX", targets)
    out = tmp_path / "merged.yaml"
    code, err = run(capsys, MACHINE, csv, "--error", "EXX", "--merge", LASER, "-o", out)
    assert code == 0, err
    with open(LASER) as f:
        old = f.read().splitlines()
    new = out.read_text().splitlines()
    a0, a1 = _entry_range(old, "EXX", "EYX")
    b0, b1 = _entry_range(new, "EXX", "EYX")
    assert new[:b0 - 1] == old[:a0]              # the header, machine, values: (and a comment line added)
    assert new[b0 - 1].startswith("  # EXX: ISO 230-2 mean bidirectional deviations")
    assert new[b1:] == old[a1:]                  # the 17 other tables and the constants, line for line
    merged = load_params(str(out), machine)
    assert set(merged) == set(truth)
    for name, value in truth.items():
        if name == "EXX":
            assert len(merged[name].x) == 41
        elif isinstance(value, Table):
            assert np.array_equal(merged[name].x, value.x) and np.array_equal(merged[name].y, value.y)
        else:
            assert merged[name] == value
    # merging the same runs again into the result gives the same text (the added comment goes too)
    again = tmp_path / "again.yaml"
    assert run(capsys, MACHINE, csv, "--error", "EXX", "--merge", out, "-o", again)[0] == 0
    assert again.read_text() == out.read_text()


def test_merge_adds_a_table_in_place_of_a_constant_and_a_new_entry(tmp_path, capsys, machine, truth):
    base = load_params(DEMO, machine)
    csv = simulate(tmp_path / "runs.csv", machine, truth, "EBX", np.linspace(-400, 400, 9))
    one = tmp_path / "one.yaml"
    assert run(capsys, MACHINE, csv, "--error", "EBX", "--merge", DEMO, "-o", one)[0] == 0
    got = load_params(str(one), machine)
    assert isinstance(got["EBX"], Table) and got["EBX"].units[1].name == "arcsec"
    assert {k: v for k, v in got.items() if k != "EBX"} == {k: v for k, v in base.items() if k != "EBX"}
    # a file without the error: the table goes after the last entry of values
    lean = tmp_path / "lean.yaml"
    lean.write_text("# my constants\nmachine: five_axis_ac\nvalues:\n  EC0Y: 4 arcsec   # squareness\n"
                    "  Ocx: 0.005 mm\n\n# the end\n")
    two = tmp_path / "two.yaml"
    assert run(capsys, MACHINE, csv, "--error", "EBX", "--merge", lean, "-o", two)[0] == 0
    text = two.read_text().splitlines()
    assert text[:5] == lean.read_text().splitlines()[:5] and text[-2:] == ["", "# the end"]
    got = load_params(str(two), machine)
    assert set(got) == {"EC0Y", "Ocx", "EBX"} and got["Ocx"] == pytest.approx(0.005)


def test_sign_convention_of_the_machine_is_checked(tmp_path, capsys):
    """A slide written against ISO 230-1 (dx: -EXX): warned, the table negated, and the model then
    gives the measured deviation."""
    m = tmp_path / "naive.yaml"
    m.write_text("name: naive_x\ndescription: an X slide with its error written with the opposite sign\n"
                 "length_unit: mm\nrotation_sense: right_hand\nerror_block_order: txyz\nsymbols:\n"
                 "  - {name: X, role: axis, unit: mm, limits: [-200, 200], meaning: X slide}\n"
                 "  - {name: EXX, role: error, unit: um, meaning: X positioning error}\n"
                 "chain:\n  - {translate: [X, 0, 0]}\n  - {errors: {dx: -EXX}}\ntool:\n  point: [0, 0, 100]\n")
    machine = load_machine(str(m))
    targets = np.linspace(-200, 200, 5)
    csv = tmp_path / "runs.csv"
    csv.write_text("target [mm],run,direction,deviation [um]\n" + "".join(
        f"{t},{j},{d},{0.01 * t + (0.3 if d == 'up' else -0.3) + 0.05 * j}\n"
        for j in (1, 2, 3) for d in ("up", "down") for t in targets))
    code, err = run(capsys, m, csv, "--error", "EXX", "-o", tmp_path / "p.yaml")
    assert code == 0, err
    assert "warning" in err and "opposite sign of ISO 230-1" in err
    params = load_params(str(tmp_path / "p.yaml"), machine)
    model = ExactModel(machine)
    for t in targets:
        dp, _ = model.error({**params, "X": float(t)})
        assert dp[0] / 1e-3 == pytest.approx(0.01 * t + 0.1, abs=1e-4)   # mean over runs 1..3: +0.05*2


def _refused(capsys, *argv):
    code, err = run(capsys, *argv)
    lines = err.strip().splitlines()
    assert code == 2 and len(lines) == 1 and "Traceback" not in err, err
    return lines[0]


@pytest.mark.parametrize("options,message", [
    (("--error", "EXQ"), "--error: 'EXQ' is not a symbol of five_axis_ac"),
    (("--error", "X"), "--error: 'X' is an axis of five_axis_ac, not an error"),
    (("--error", "EXX", "--axis", "W"), "--axis: 'W' is not an axis of five_axis_ac"),
    (("--error", "EBX"), "the deviations are in um (lengths) but EBX is declared in arcsec"),
    (("--error", "EXX", "--axis", "Cp"), "targets are in mm but axis Cp is declared in deg"),
])
def test_refusals(tmp_path, capsys, machine, truth, options, message):
    csv = simulate(tmp_path / "runs.csv", machine, truth, "EXX", np.linspace(-400, 400, 5))
    line = _refused(capsys, MACHINE, csv, *options, "-o", tmp_path / "p.yaml")
    assert line.startswith("chaincomp laser-to-params: error: ") and message in line, line
    assert not (tmp_path / "p.yaml").exists()


def test_an_error_no_channel_measures_is_refused(tmp_path, capsys, machine, truth):
    """Squareness of Y to X turns Y's travel: at Y = 0 it moves nothing."""
    csv = simulate(tmp_path / "runs.csv", machine, truth, "EBX", np.linspace(-300, 300, 5))
    line = _refused(capsys, MACHINE, csv, "--error", "EC0Y", "--axis", "Y", "-o", tmp_path / "p.yaml")
    assert "--error EC0Y: at the reference pose it moves the tool relative to the workpiece by [0.0, 0.0, 0.0]" in line


def test_output_that_is_an_input_is_refused(tmp_path, capsys, machine, truth):
    csv = simulate(tmp_path / "runs.csv", machine, truth, "EXX", np.linspace(-400, 400, 5))
    p0 = tmp_path / "p0.yaml"
    p0.write_text("machine: five_axis_ac\nvalues:\n  EC0Y: 4 arcsec\n")
    line = _refused(capsys, MACHINE, csv, "--error", "EXX", "--merge", p0, "-o", p0)
    assert f"-o {p0}: is also an input ({p0}); refusing to overwrite it" in line
    assert p0.read_text() == "machine: five_axis_ac\nvalues:\n  EC0Y: 4 arcsec\n"


def test_a_broken_merge_file_is_reported_as_itself(tmp_path, capsys, machine, truth):
    csv = simulate(tmp_path / "runs.csv", machine, truth, "EXX", np.linspace(-400, 400, 5))
    p0 = tmp_path / "p0.yaml"
    p0.write_text("machine: five_axis_ac\nvalues:\n  EC0Y: 4 furlong\n")
    line = _refused(capsys, MACHINE, csv, "--error", "EXX", "--merge", p0, "-o", tmp_path / "p.yaml")
    assert line.startswith(f"chaincomp laser-to-params: error: {p0}:3: values.EC0Y: ")
    p0.write_text("machine: five_axis_ac\nvalues: {EC0Y: 4 arcsec}\n")
    line = _refused(capsys, MACHINE, csv, "--error", "EXX", "--merge", p0, "-o", tmp_path / "p.yaml")
    assert f"{p0}:2: values: --merge: 'values' must be a block mapping" in line


@pytest.mark.slow
@pytest.mark.skipif(not os.path.exists(DAEMON), reason="chaincompd is not built")
def test_daemon_loads_the_merged_file(tmp_path, capsys, machine, truth):
    """chaincompd reads the machine, then the params, then opens LCM: with an LCM URL nobody can
    open it stops there, so reaching that error means its own loader took the file (a broken
    table stops it earlier, naming the file)."""
    csv = simulate(tmp_path / "runs.csv", machine, truth, "EXX", np.linspace(-400, 400, 41))
    out = tmp_path / "merged.yaml"
    assert run(capsys, MACHINE, csv, "--error", "EXX", "--merge", LASER, "-o", out)[0] == 0
    config = tmp_path / "r.yaml"
    config.write_text('lcm_url: "bogus://nowhere"\n')
    broken = tmp_path / "broken.yaml"
    broken.write_text(out.read_text().replace("      - [-380,", "      - [-500,", 1))

    def daemon(params):
        return subprocess.run([DAEMON, "--machine", MACHINE, "--params", str(params), "--config", str(config)],
                              capture_output=True, text=True, timeout=60)
    bad = daemon(broken)
    assert bad.returncode == 2 and "positions must increase" in bad.stderr, bad.stderr
    good = daemon(out)
    assert good.returncode == 2 and "cannot open LCM at 'bogus://nowhere'" in good.stderr, good.stderr


def test_rotary_axis_angular_positioning(tmp_path, capsys):
    """ISO 230-2 on a rotary table: trunnion_ac's zero position error of C as a table over C (deg,
    arcsec); the exact chain's tool point then turns about the C axis line by the measured mean."""
    path = machine_path("trunnion_ac")
    machine = load_machine(path)
    targets = [0.0, 30.0, 60.0, 90.0, 135.0, 180.0, 270.0, 330.0]
    true = {t: 3.0 * math.sin(math.radians(2 * t)) + 1.0 for t in targets}   # arcsec
    csv = tmp_path / "c.csv"
    csv.write_text("target [deg],run,direction,deviation [arcsec]\n" + "".join(
        f"{t},{j},{d},{true[t] + (0.4 if d == 'up' else -0.4) + 0.01 * j}\n"
        for j in (1, 2, 3, 4) for d in ("up", "down") for t in targets))
    code, err = run(capsys, path, csv, "--error", "EC0C", "--axis", "C", "-o", tmp_path / "p.yaml")
    assert code == 0, err
    params = load_params(str(tmp_path / "p.yaml"), machine)
    table = params["EC0C"]
    assert table.axis == "C" and [u.name for u in table.units] == ["deg", "arcsec"]
    arcsec = math.pi / 648000
    assert np.allclose(table.y / arcsec, [true[t] + 0.025 for t in targets], atol=1e-4)
    model = ExactModel(machine)
    base = {a.name: a.to_internal(a.default_position) for a in machine.axes}
    for t in targets:
        at = {**base, "X": 120.0, "Y": -50.0, "C": math.radians(t)}   # off the C axis line
        p0, _ = model.pose(at)
        dp, _ = model.error({**params, **at})
        r = math.hypot(p0[0], p0[1])   # the C axis line is z through the origin at zero errors
        assert r > 100
        # dp = θ z × p0 for a turn by θ about +z of the tool relative to the workpiece (ISO 230-1's sign)
        turn = (p0[0] * dp[1] - p0[1] * dp[0]) / r**2
        assert turn / arcsec == pytest.approx(true[t] + 0.025, abs=6e-5)   # the table's 4 decimals
