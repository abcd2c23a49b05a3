"""identify on a six-axis arm: the UR5 (standard DH, base and tool as 6-DOF error blocks, 36
errors) calibrated from laser-tracker points and from full poses (tool point and direction).

Truth from outside the code: the arm's tool point and direction are a numpy product of DH
matrices written here from UR's DH table; the measurements identify fits come from it (plus
Gaussian noise of a seeded generator); the identifiable rank is this file's own SVD of a
central-difference Jacobian of that product; held-out predictions are made by that product
with the values identify wrote to its params file.
"""

import json
import math

import numpy as np
import pytest

from chaincomp import load_machine, load_params
from chaincomp.cli.main import main

from arm_models import block, ur5
from helpers import ROOT

UR5 = f"{ROOT}/tools/bench_machines/ur5_blocks.yaml"
UM, ARCSEC, DEG = 1e-3, math.pi / 648000, math.pi / 180
NOISE = 0.02                                     # mm, the tracker's standard uncertainty per coordinate
TOOL = np.array([30.0, 0.0, 120.0, 1.0])
DIR = np.array([0.0, 0.0, 1.0, 0.0])


def ur5_pose(q, e):
    """(rows, 6): tool point x, y, z and tool direction; q: 6 joint angle arrays (rad), e: the
    36 errors by name (mm, rad)."""
    m = block(e["bx"], e["by"], e["bz"], e["ba"], e["bb"], e["bc"]) @ ur5(q, e, ("dth{}", "dd{}", "da{}", "dal{}")) \
        @ block(e["tx"], e["ty"], e["tz"], e["ta"], e["tb"], e["tc"])
    return np.concatenate([(m @ TOOL)[..., :3], (m @ DIR)[..., :3]], axis=-1)


def names(m):
    return [s.name for s in m.errors]


def internal(m, name):
    return UM if m.symbol(name).unit.name == "um" else ARCSEC


def zero(m, rows):
    return {n: np.zeros(rows) for n in names(m)}


def poses(rng, n):
    return np.round(rng.uniform(-180, 180, (6, n)), 4)        # degrees, as written to the CSV


def own_rank(m, q, columns, weights):
    """Rank of this file's central-difference Jacobian of the measured columns (each divided by
    its standard uncertainty), its columns scaled to unit norm."""
    rows = q.shape[1]
    cols = []
    for n in names(m):
        plus, minus = zero(m, rows), zero(m, rows)
        plus[n] += 1e-6
        minus[n] -= 1e-6
        diff = (ur5_pose(q, plus) - ur5_pose(q, minus))[:, columns] / 2e-6
        cols.append((diff / weights).ravel())
    j = np.array(cols).T
    s = np.linalg.svd(j / np.linalg.norm(j, axis=0), compute_uv=False)
    return int((s > 1e-6 * s[0]).sum())


def write_csv(path, q_deg, data, columns):
    heads = ["x", "y", "z", "kx", "ky", "kz"]
    lines = ["# simulated tracker data", ",".join([f"q{i}" for i in range(1, 7)] + [heads[c] for c in columns])]
    for r in range(q_deg.shape[1]):
        lines.append(",".join([repr(float(v)) for v in q_deg[:, r]] + [repr(float(data[r, c])) for c in columns]))
    path.write_text("\n".join(lines) + "\n")


def run(capsys, *args):
    rc = main([str(a) for a in args])
    out, err = capsys.readouterr()
    return rc, out, err


def fit_json(capsys, *args):
    rc, out, err = run(capsys, "identify", UR5, *args, "--format", "json")
    assert rc == 0, err
    return json.loads(out)


@pytest.fixture(scope="module")
def arm():
    m = load_machine(UR5)
    rng = np.random.default_rng(2026)
    chosen = set(rng.choice(names(m), 30, replace=False))
    truth = {n: (rng.normal(0, 0.15) if internal(m, n) == UM else rng.normal(0, 60) * ARCSEC) if n in chosen else 0.0
             for n in names(m)}                                        # internal units: mm, rad
    return m, rng, truth


def test_minimal_set_from_tracker_points(tmp_path, capsys, arm):
    """30 injected errors, tracker points at 50 random poses with 0.02 mm noise: the rank is the
    independent one, every error outside the minimal set is reported with the combination that
    carries it, held-out predictions are within the noise and 20 times better than nominal."""
    m, rng, truth = arm
    q_deg = poses(rng, 50)
    q = q_deg * DEG
    measured = ur5_pose(q, truth)
    measured[:, :3] += NOISE * rng.standard_normal((50, 3))
    write_csv(tmp_path / "meas.csv", q_deg, measured, [0, 1, 2])
    out = tmp_path / "fit.yaml"
    doc = fit_json(capsys, tmp_path / "meas.csv", "--minimal", "-o", out)
    rank = own_rank(m, q, [0, 1, 2], 1.0)
    assert doc["rank"] == rank and rank < 36
    assert doc["minimal"] and len(doc["estimates"]) == rank
    held = set(doc["redundant"]) | set(doc["unidentifiable"])
    assert held == set(names(m)) - set(doc["estimates"])
    for n, r in doc["redundant"].items():        # each carried by fitted errors, named in its reason
        assert r["carried_by"] and set(r["carried_by"]) <= set(doc["estimates"]), n
        assert all(k in r["reason"] for k in r["carried_by"])
    # exactly redundant pairs of this chain: offsets along the parallel axes 2, 3, 4 add up
    for a, b in (("dd3", "dd2"), ("dd4", "dd2")):
        if a in doc["redundant"]:
            assert doc["redundant"][a]["carried_by"] == pytest.approx({b: 1.0}, rel=1e-6)

    text = out.read_text()
    assert "Minimal identifiable set" in text
    fitted = load_params(str(out), m)
    assert set(fitted) == set(names(m))                                # others written as zero
    assert all(fitted[n] == 0 for n in held)
    q_new_deg = poses(rng, 50)
    q_new = q_new_deg * DEG
    true_new = ur5_pose(q_new, truth)[:, :3]
    noisy_new = true_new + NOISE * rng.standard_normal((50, 3))
    predicted = ur5_pose(q_new, {n: np.full(50, fitted[n]) for n in names(m)})[:, :3]
    nominal = ur5_pose(q_new, zero(m, 50))[:, :3]
    assert np.abs(predicted - true_new).max() <= 3 * NOISE
    assert 0.8 * NOISE <= np.sqrt(np.mean((predicted - noisy_new) ** 2)) <= 1.25 * NOISE
    before = np.sqrt(np.mean(np.sum((nominal - true_new) ** 2, axis=1)))
    after = np.sqrt(np.mean(np.sum((predicted - true_new) ** 2, axis=1)))
    assert before >= 20 * after, (before, after)


def test_without_minimal_the_same_rank_and_a_minimal_suggestion(tmp_path, capsys, arm):
    m, rng, truth = arm
    q_deg = poses(np.random.default_rng(5), 50)
    write_csv(tmp_path / "meas.csv", q_deg, ur5_pose(q_deg * DEG, truth), [0, 1, 2])
    rc, out, err = run(capsys, "identify", UR5, tmp_path / "meas.csv", "--sigma", "20um")
    assert rc == 0, err
    assert "fit a minimal set (--minimal)" in out
    assert "cannot be told apart from" in out


def test_preferred_errors_enter_the_minimal_set_first(tmp_path, capsys, arm):
    """The tool block's offsets instead of the last joint's d and a (they move the tool point
    alike): --prefer takes them first; the rank and the residual do not change."""
    m, rng, truth = arm
    q_deg = poses(np.random.default_rng(6), 50)
    data = ur5_pose(q_deg * DEG, truth)
    data[:, :3] += NOISE * np.random.default_rng(7).standard_normal((50, 3))
    write_csv(tmp_path / "meas.csv", q_deg, data, [0, 1, 2])
    plain = fit_json(capsys, tmp_path / "meas.csv", "--minimal")
    preferred = fit_json(capsys, tmp_path / "meas.csv", "--minimal", "--prefer", "tx,ty,tz")
    assert {"tx", "ty", "tz"} <= set(preferred["estimates"]) and not {"tx", "ty", "tz"} & set(plain["estimates"])
    assert preferred["rank"] == plain["rank"] == len(preferred["estimates"])
    assert preferred["rms_residual"] == pytest.approx(plain["rms_residual"], rel=1e-6)
    rc, _, err = run(capsys, "identify", UR5, tmp_path / "meas.csv", "--prefer", "tx", "--assume-zero", "tx")
    assert rc == 2 and "--prefer tx: it is also assumed zero" in err


def test_full_poses_weighted_by_their_sigmas(tmp_path, capsys, arm):
    """Tool points and directions at 40 poses (20 µm, 10 arcsec): the rank is this file's own
    for the two kinds weighted by their sigmas, above the rank of the points alone, and every
    fitted value is within 3 standard uncertainties of what the truth's combination gives
    (checked through the held-out poses: prediction of both kinds within 3 sigma)."""
    m, rng, truth = arm
    q_deg = poses(rng, 40)
    q = q_deg * DEG
    sig_p, sig_d = 0.02, 10 * ARCSEC
    data = ur5_pose(q, truth)
    data[:, :3] += sig_p * rng.standard_normal((40, 3))
    data[:, 3:] += sig_d * rng.standard_normal((40, 3))
    data[:, 3:] /= np.linalg.norm(data[:, 3:], axis=1, keepdims=True)
    write_csv(tmp_path / "meas.csv", q_deg, data, range(6))
    out = tmp_path / "fit.yaml"
    doc = fit_json(capsys, tmp_path / "meas.csv", "--minimal", "--sigma", "20um,10arcsec", "-o", out)
    weights = np.array([sig_p] * 3 + [sig_d] * 3)
    assert doc["rank"] == own_rank(m, q, list(range(6)), weights) > own_rank(m, q, [0, 1, 2], 1.0)
    assert doc["sigma"]["kx"] == {"value": pytest.approx(sig_d, rel=1e-12), "unit": "rad"}
    assert 0.6 < doc["chi2_per_dof"] < 1.5
    fitted = load_params(str(out), m)
    q_new = poses(rng, 50) * DEG
    true_new = ur5_pose(q_new, truth)
    predicted = ur5_pose(q_new, {n: np.full(50, fitted[n]) for n in names(m)})
    assert np.abs(predicted[:, :3] - true_new[:, :3]).max() <= 3 * sig_p
    assert np.abs(predicted[:, 3:] - true_new[:, 3:]).max() <= 3 * sig_d


def test_points_and_directions_need_both_sigmas(tmp_path, capsys, arm):
    m, rng, truth = arm
    q_deg = poses(rng, 10)
    write_csv(tmp_path / "meas.csv", q_deg, ur5_pose(q_deg * DEG, truth), range(6))
    rc, _, err = run(capsys, "identify", UR5, tmp_path / "meas.csv")
    assert rc == 2 and "give --sigma LENGTH,ANGLE" in err and len(err.strip().splitlines()) == 1
    rc, _, err = run(capsys, "identify", UR5, tmp_path / "meas.csv", "--sigma", "20um")
    assert rc == 2 and "no standard uncertainty for the measured columns kx, ky, kz" in err
    bad = (tmp_path / "meas.csv").read_text().splitlines()
    bad[2] = ",".join(bad[2].split(",")[:-1] + ["0.5"])
    (tmp_path / "bad.csv").write_text("\n".join(bad) + "\n")
    rc, _, err = run(capsys, "identify", UR5, tmp_path / "bad.csv", "--sigma", "20um,10arcsec")
    assert rc == 2 and "bad.csv:3: kx: the measured tool direction" in err and "not a unit vector" in err


def test_people_units_and_digits(tmp_path, capsys, arm):
    """Estimates printed in µm and arcsec, the uncertainty to 2 significant digits and the
    estimate to the same decimal place; --units internal in mm and rad."""
    m, rng, truth = arm
    q_deg = poses(rng, 50)
    data = ur5_pose(q_deg * DEG, truth)
    data[:, :3] += NOISE * rng.standard_normal((50, 3))
    write_csv(tmp_path / "meas.csv", q_deg, data, [0, 1, 2])
    doc = fit_json(capsys, tmp_path / "meas.csv", "--minimal")
    rc, out, _ = run(capsys, "identify", UR5, tmp_path / "meas.csv", "--minimal")
    rows = {line.split()[0]: line.split()[1:] for line in out.splitlines() if line.startswith("  ") and "±" in line}
    for n, est in doc["estimates"].items():
        value, pm, unc, unit = rows[n]
        declared = m.symbol(n).unit                                   # um or arcsec: as printed
        assert pm == "±" and unit == {"um": "µm", "arcsec": "arcsec"}[declared.name]
        assert est["unit"] == {"um": "mm", "arcsec": "rad"}[declared.name]       # JSON: internal
        est = {k: est[k] / declared.to_internal for k in ("value", "uncertainty")}
        digits = unc.replace(".", "").lstrip("0")
        assert len(digits) == 2 or (len(digits) == 1 and "." not in unc), unc   # 2 significant digits
        assert len(value.partition(".")[2]) == len(unc.partition(".")[2])
        assert float(unc) == pytest.approx(est["uncertainty"], rel=0.05)
        assert float(value) == pytest.approx(est["value"], abs=float(unc) / 10 + 1e-12)
    rc, out, _ = run(capsys, "identify", UR5, tmp_path / "meas.csv", "--minimal", "--units", "internal")
    assert " mm" in out and " rad" in out and "µm" not in out
