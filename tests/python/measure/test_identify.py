"""``chaincomp identify`` and ``simulate-measurements``: errors recovered from tool-tip data.

Injected errors are random (fixed seeds); measurements come from the exact model. Without
noise the fit must return the injected values to 1e-9 relative; with 1 µm noise the
injected value must lie within 3 standard uncertainties for at least 99% of the estimates
of 200 trials. ThetaAs and ThetaAv enter the angle head's tool point only together (see
test_protocol.py), so ThetaAv is held at zero where values are compared.
"""

import json
import math

import numpy as np
import pytest

from chaincomp import load_machine, load_params
from chaincomp.measure.identify import identify, simulate
from chaincomp.measure.table import Table
from chaincomp.symbolic.numeric import ExactModel

from helpers import machine_path, run_cli
from test_protocol import extended_head

HEAD = machine_path("angle_head")
ZERO = ("DY", "ThetaAv")


def injected(m, rng, zero=ZERO):
    """Errors in declared units: offsets ~5 µm, angles ~20 arcsec."""
    return {s.name: 0.0 if s.name in zero else float(rng.normal() * (20.0 if s.unit.kind == "angle" else 0.005))
            for s in m.errors}


def write_params(path, m, values):
    lines = [f"machine: {m.name}", "values:"]
    lines += [f'  {k}: "{v!r} {m.symbol(k).unit.name}"' for k, v in values.items()]
    path.write_text("\n".join(lines) + "\n")


def grid_axes(m, angles=(0.0, 90.0, 180.0, 270.0)):
    a, c = np.meshgrid(np.radians(angles), np.radians(angles), indexing="ij")
    return {"Ap": a.ravel(), "Cp": c.ravel()}


@pytest.mark.slow
def test_noise_free_recovery_through_the_cli(tmp_path):
    m = load_machine(HEAD)
    truth = injected(m, np.random.default_rng(1))
    write_params(tmp_path / "truth.yaml", m, truth)
    meas, out = tmp_path / "meas.csv", tmp_path / "fit.yaml"
    run_cli("simulate-measurements", HEAD, "--params", str(tmp_path / "truth.yaml"), "--setups",
            "grid:0,90,180,270", "--noise", "0um", "-o", str(meas))
    assert open(meas).read().count("\n") == 2 + 1 + 16      # comments, header, 16 set-ups
    doc = json.loads(run_cli("identify", HEAD, str(meas), "--assume-zero", ",".join(ZERO), "--format",
                             "json", "-o", str(out)).stdout)
    assert doc["converged"] and doc["unidentifiable"] == {}
    assert set(doc["estimates"]) == {n for n in truth if n not in ZERO}
    assert doc["units"] == "internal (mm, rad, 1)"
    for name, est in doc["estimates"].items():
        assert est["unit"] == {"length": "mm", "angle": "rad"}[m.symbol(name).unit.kind]
        truth_internal = m.symbol(name).to_internal(truth[name])
        assert abs(est["value"] - truth_internal) <= 1e-9 * abs(truth_internal), name
    assert doc["condition_number"] < 10 and doc["correlations"] == []
    # the params file loads with the product's loader, values in internal units
    loaded = load_params(str(out), m)
    for name, value in truth.items():
        assert abs(loaded[name] - m.symbol(name).to_internal(value)) <= 1e-9 * abs(m.symbol(name).to_internal(value))
    assert "machine: angle_head" in out.read_text()


@pytest.mark.slow
def test_noisy_estimates_within_three_standard_uncertainties():
    m = load_machine(HEAD)
    rng = np.random.default_rng(12345)
    axes = grid_axes(m)
    noise = 1e-3                                           # 1 µm in mm
    model = ExactModel(m)                                  # compiled once for all trials
    inside = total = 0
    for _ in range(200):
        truth = {k: m.symbol(k).to_internal(v) for k, v in injected(m, rng).items()}
        table = Table("trial", axes, simulate(m, truth, axes, noise, rng, model=model), list(range(16)))
        fit = identify(m, table, ZERO, model=model)
        assert fit.converged and not fit.unidentifiable
        for name, value in fit.estimates.items():
            total += 1
            inside += abs(value - truth[name]) <= 3 * fit.uncertainties[name]
    assert total == 200 * 6
    assert inside / total >= 0.99, (inside, total)


def test_known_sigma_is_used():
    m = load_machine(HEAD)
    rng = np.random.default_rng(3)
    axes = grid_axes(m)
    truth = {k: m.symbol(k).to_internal(v) for k, v in injected(m, rng).items()}
    table = Table("t", axes, simulate(m, truth, axes, 1e-3, rng), list(range(16)))
    a, b = identify(m, table, ZERO, sigma=1e-3), identify(m, table, ZERO, sigma=2e-3)
    for name in a.uncertainties:
        assert b.uncertainties[name] == pytest.approx(2 * a.uncertainties[name], rel=1e-9)


@pytest.mark.slow
def test_unidentifiable_errors_get_no_value(tmp_path):
    """Ocz shifts the tool only along the C axis (z) at every set-up and is not seen without z;
    Rs turns the spindle about its own axis and never moves the tool tip; ThetaAs/ThetaAv
    are inseparable. None of them gets a value; the others are still recovered."""
    path = extended_head(tmp_path)
    m = load_machine(path)
    truth = injected(m, np.random.default_rng(5), zero=("DY",))
    write_params(tmp_path / "truth.yaml", m, truth)
    meas, out = tmp_path / "meas.csv", tmp_path / "fit.yaml"
    run_cli("simulate-measurements", path, "--params", str(tmp_path / "truth.yaml"), "--measure", "x,y",
            "-o", str(meas))
    doc = json.loads(run_cli("identify", path, str(meas), "--assume-zero", "DY", "--format", "json",
                             "-o", str(out)).stdout)
    un = doc["unidentifiable"]
    assert set(un) == {"Ocz", "Rs", "ThetaAs", "ThetaAv"}
    assert "does not move the measured coordinates (x, y)" in un["Ocz"]
    assert "does not move the measured coordinates" in un["Rs"]
    assert "cannot be told apart from ThetaAv" in un["ThetaAs"]
    assert not set(un) & set(doc["estimates"])
    loaded = load_params(str(out), m)
    assert not set(un) & set(loaded)
    assert "Not identifiable, no value given: " in out.read_text()
    for name in ("Ocx", "Ocy", "ThetaCh", "ThetaCv"):
        # exact to first order: the inseparable pair, left at its minimum-norm split, adds
        # only second-order terms (a few 1e-5 of each value)
        assert doc["estimates"][name]["value"] == pytest.approx(m.symbol(name).to_internal(truth[name]), rel=1e-3)
    text = run_cli("identify", path, str(meas), "--assume-zero", "DY").stdout
    assert "not identifiable from these set-ups (no value given):" in text
    assert "Rs: does not move" in text


@pytest.mark.slow
def test_simulate_random_setups_and_a_setups_file(tmp_path):
    run_cli("simulate-measurements", HEAD, "--setups", "random:7", "--seed", "4", "-o", str(tmp_path / "r.csv"))
    rows = [r for r in open(tmp_path / "r.csv").read().splitlines() if r and not r.startswith("#")]
    assert rows[0] == "Ap,Cp,x,y,z" and len(rows) == 8
    (tmp_path / "s.csv").write_text("# set-ups only\nCp,Ap\n10,20\n-30,45\n")
    run_cli("simulate-measurements", HEAD, "--setups", str(tmp_path / "s.csv"), "--measure", "z",
            "-o", str(tmp_path / "z.csv"))
    rows = [r.split(",") for r in open(tmp_path / "z.csv").read().splitlines() if not r.startswith("#")]
    assert rows[0] == ["Ap", "Cp", "z"] and [r[:2] for r in rows[1:]] == [["20", "10"], ["45", "-30"]]
    m = load_machine(HEAD)
    values = m.nominal_values()
    values.update(Ap=math.radians(20), Cp=math.radians(10))
    assert float(rows[1][2]) == pytest.approx(ExactModel(m).pose(values)[0][2], abs=1e-12)


def bad(tmp_path, csv_text, *args):
    (tmp_path / "m.csv").write_text(csv_text)
    proc = run_cli("identify", HEAD, str(tmp_path / "m.csv"), *args, check=False)
    assert proc.returncode == 2, proc.stderr
    assert "Traceback" not in proc.stderr and len(proc.stderr.strip().splitlines()) == 1, proc.stderr
    return proc.stderr.strip()


GOOD = "# measured\nAp,Cp,x,y,z\n0,0,0,-10,-28\n90,0,15,-5,-22\n"


@pytest.mark.slow
def test_malformed_row_names_its_line(tmp_path):
    err = bad(tmp_path, GOOD + "180,0,1,2\n")
    assert err.endswith("m.csv:5: 4 cells, the header has 5")
    err = bad(tmp_path, GOOD + "180,zero,1,2,3\n")
    assert err.endswith("m.csv:5: Cp: expected a number, got 'zero'")


@pytest.mark.slow
def test_unknown_axis_column(tmp_path):
    err = bad(tmp_path, "Ap,Bp,x\n0,0,1\n")
    assert err.endswith("m.csv:1: header: unknown column 'Bp' (expected the axes Ap, Cp and measured "
                        "coordinates x, y, z, kx, ky, kz)")
    err = bad(tmp_path, "Ap,x\n0,1\n")
    assert "m.csv:1: header: missing column for axis Cp" in err


@pytest.mark.slow
def test_unknown_error_in_assume_zero(tmp_path):
    err = bad(tmp_path, GOOD, "--assume-zero", "DY,Ocz")
    assert err == ("chaincomp identify: error: --assume-zero: unknown error 'Ocz' for machine 'angle_head' "
                   "(errors: ThetaAs, Oas, ThetaAv, DY, Ocx, Ocy, ThetaCh, ThetaCv)")


@pytest.mark.slow
def test_no_data_rows(tmp_path):
    assert "no measurements" in bad(tmp_path, "# nothing\nAp,Cp,x\n")
