"""identify --loss huber (#41 item 5): a robust fit that gross outliers do not drag.

Truth from outside the code: the UR5's tool point is the numpy DH product of test_identify_arm
(UR's published table), with errors drawn here; the tracker readings are that product plus
Gaussian noise, and a few of them are spoiled by millimetres (a target lost, a pose mistyped).
Least squares is pulled off the truth by them; Huber's loss (Huber 1964, k = 1.345 standard
uncertainties, iteratively reweighted) keeps every estimate within 2 of its standard
uncertainties and names the spoiled readings. Without outliers the two agree.
"""

import json

import numpy as np
import pytest

from chaincomp import load_machine
from chaincomp.cli.main import main

from test_identify_arm import ARCSEC, DEG, NOISE, UM, UR5, names, poses, ur5_pose, write_csv

FITTED = ("dth1", "dth2", "dth3", "dth4", "dth5", "dth6", "dd1", "da2", "da3", "dal2", "dal3", "dd4")
SPOILED = {5: (0, 3.0), 17: (1, -5.0), 29: (2, 4.0), 41: (0, -2.5)}    # set-up -> (coordinate, mm)


def fit(capsys, csv, *extra):
    m = load_machine(UR5)
    rc = main(["identify", UR5, str(csv), "--assume-zero",
              ",".join(n for n in names(m) if n not in FITTED), "--sigma", f"{NOISE}mm", "--format", "json",
              *extra])
    out, err = capsys.readouterr()
    assert rc == 0, err
    return json.loads(out)


@pytest.fixture(scope="module")
def data():
    m = load_machine(UR5)
    rng = np.random.default_rng(41)
    truth = {n: 0.0 for n in names(m)}
    for n in FITTED:
        truth[n] = rng.normal(0, 0.15) if m.symbol(n).unit.name == "um" else rng.normal(0, 60) * ARCSEC
    q_deg = poses(rng, 60)
    clean = ur5_pose(q_deg * DEG, truth)
    clean[:, :3] += NOISE * rng.standard_normal((60, 3))
    spoiled = clean.copy()
    for row, (c, mm) in SPOILED.items():
        spoiled[row, c] += mm
    return truth, q_deg, clean, spoiled


def off(doc, truth):
    """Each estimate's distance from the truth in its standard uncertainties."""
    return {n: abs(e["value"] - truth[n]) / e["uncertainty"] for n, e in doc["estimates"].items()}


def test_huber_holds_the_truth_where_squares_does_not(tmp_path, capsys, data):
    truth, q_deg, clean, spoiled = data
    write_csv(tmp_path / "c.csv", q_deg, clean, [0, 1, 2])
    best = fit(capsys, tmp_path / "c.csv")          # least squares without the outliers: all the noise allows
    write_csv(tmp_path / "m.csv", q_deg, spoiled, [0, 1, 2])
    squares = fit(capsys, tmp_path / "m.csv")
    huber = fit(capsys, tmp_path / "m.csv", "--loss", "huber")
    assert set(huber["estimates"]) == set(FITTED) and not huber["unidentifiable"]
    # least squares is dragged tens of its sigmas off; Huber stays within 2 sigma of the clean fit (its
    # own sigma: the outliers cost it a little precision) and as close to the truth as the clean fit is
    assert max(off(squares, truth).values()) > 20, off(squares, truth)
    clean_fit = {n: e["value"] for n, e in best["estimates"].items()}
    assert max(off(huber, clean_fit).values()) <= 2, off(huber, clean_fit)
    assert max(off(squares, clean_fit).values()) > 20
    assert max(off(huber, truth).values()) <= max(off(best, truth).values()) + 1
    assert squares["loss"] == "squares" and squares["outliers"] == []
    assert huber["loss"] == {"huber": 1.345}
    # the spoiled readings are named (CSV line: two comment/header lines, then set-up r on line r + 3),
    # the largest first, with their standardized residual: about the spoil over the noise
    worst = huber["outliers"][:len(SPOILED)]
    assert {(o["line"], o["column"]) for o in worst} == {(r + 3, "xyz"[c]) for r, (c, _) in SPOILED.items()}
    for o in worst:
        row, (c, mm) = o["line"] - 3, SPOILED[o["line"] - 3]
        assert o["standardized_residual"] == pytest.approx(mm / NOISE, rel=0.05)
        assert 0 < o["weight"] < 1.345 / abs(mm / NOISE) * 1.1
    # and the text report says so, and the params file
    rc = main(["identify", UR5, str(tmp_path / "m.csv"), "--assume-zero",
               ",".join(n for n in names(load_machine(UR5)) if n not in FITTED), "--sigma", f"{NOISE}mm",
               "--loss", "huber:2", "-o", str(tmp_path / "p.yaml")])
    text = capsys.readouterr().out
    assert "# Huber loss (k = 2): " in (tmp_path / "p.yaml").read_text()
    worst = max(SPOILED, key=lambda r: abs(SPOILED[r][1]))
    assert rc == 0 and "Huber loss (k = 2):" in text and f"line {worst + 3} y" in text


def test_without_outliers_huber_is_least_squares(tmp_path, capsys, data):
    truth, q_deg, clean, _ = data
    write_csv(tmp_path / "m.csv", q_deg, clean, [0, 1, 2])
    squares = fit(capsys, tmp_path / "m.csv")
    huber = fit(capsys, tmp_path / "m.csv", "--loss", "huber")
    for n, e in squares["estimates"].items():
        assert abs(huber["estimates"][n]["value"] - e["value"]) <= 0.5 * e["uncertainty"], n
        assert e["uncertainty"] <= huber["estimates"][n]["uncertainty"] <= 1.2 * e["uncertainty"], n
    # readings of normal noise beyond k are down-weighted by k/|u| (Huber's weight), none is far out
    for o in huber["outliers"]:
        assert 1.345 < abs(o["standardized_residual"]) < 4 and o["weight"] == pytest.approx(
            1.345 / abs(o["standardized_residual"]), rel=1e-6)


@pytest.mark.parametrize("bad", ["huber:0", "huber:abc", "huber:1e3", "cauchy", "squares:2", "huber:"])
def test_a_bad_loss_is_refused(tmp_path, capsys, data, bad):
    _, q_deg, clean, _ = data
    write_csv(tmp_path / "m.csv", q_deg, clean, [0, 1, 2])
    rc = main(["identify", UR5, str(tmp_path / "m.csv"), "--loss", bad])
    err = capsys.readouterr().err
    assert rc == 2 and f"--loss {bad}" in err and err.count("\n") == 1, err


def test_without_sigma_the_scale_is_robust(tmp_path, capsys, data):
    """Without --sigma the residuals are standardized by 1.4826 x their median absolute value, which
    the outliers do not inflate: the same readings are named, the estimates as good."""
    truth, q_deg, clean, spoiled = data
    m = load_machine(UR5)
    held = ",".join(n for n in names(m) if n not in FITTED)
    write_csv(tmp_path / "c.csv", q_deg, clean, [0, 1, 2])
    write_csv(tmp_path / "m.csv", q_deg, spoiled, [0, 1, 2])
    docs = []
    for csv, loss in (("c.csv", "squares"), ("m.csv", "huber")):
        rc = main(["identify", UR5, str(tmp_path / csv), "--assume-zero", held, "--loss", loss, "--format", "json"])
        out, err = capsys.readouterr()
        assert rc == 0, err
        docs.append(json.loads(out))
    best, huber = docs
    clean_fit = {n: e["value"] for n, e in best["estimates"].items()}
    assert max(off(huber, clean_fit).values()) <= 2, off(huber, clean_fit)
    worst = huber["outliers"][:len(SPOILED)]
    assert {(o["line"], o["column"]) for o in worst} == {(r + 3, "xyz"[c]) for r, (c, _) in SPOILED.items()}
    for o in worst:   # in units of the robust scale, about the noise's 20 um
        assert o["standardized_residual"] == pytest.approx(SPOILED[o["line"] - 3][1] / NOISE, rel=0.2)
