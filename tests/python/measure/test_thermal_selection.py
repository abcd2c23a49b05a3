"""thermal fit chooses the sensors the physics uses, not the ones the noise favours (issue #43):
on the bundled truth of vmc_xyz with the noise seeds that fooled the in-sample choice (9, 21, 5)
and the default, and on a truth written here with a slow term (T_bed, 7200 s) on a log long
enough to see it. Each fit is checked on a held-out cycle in another hall climate and with
other sensor dynamics, which a model built on the wrong (correlated) sensors extrapolates badly.

Truth from outside the code: the models handed to simulate-thermal; the hall's and a sensor's
closed-form response for simulate-thermal's new options.

The logs: 0.5 readings a second (the fit's cost) and 0.1 um of drift noise, a good probe's.
With the default 0.3 um the warm-up pins T_column's time constant only to about 2.6 % (one
standard uncertainty), and 5 % is then not met on every seed (tools/bench_thermal)."""

import json
import math

import numpy as np
import pytest
import yaml

from chaincomp.measure import thermal as T
from helpers import cli, machine_path, run_in_process

VMC = {"EZZ": [("T_spindle", -1.5, 900.0), ("T_column", 0.6, 3600.0)], "EYZ": [("T_column", -0.8, 2400.0)]}
SLOW = {"EZZ": [("T_spindle", -1.0, 600.0), ("T_bed", 1.5, 7200.0)]}
# the held-out cycle: another job, another day's hall, sensors that respond 1.5 times slower
HELD_OUT = ("--cycle", "varied", "--hall", "2:50000,1.5:9000,0.5:3000", "--sensor-lags", "1.5", "--seed", "77",
            "--drift-noise", "0")


def _truth(path, truth):
    path.write_text("machine: vmc_xyz\nerrors:\n" + "".join(
        f"  {e}:\n    unit: um\n    terms:\n" + "".join(
            f"      - {{sensor: {s}, gain: {g}, time_constant: {tau}}}\n" for s, g, tau in terms)
        for e, terms in truth.items()))
    return path


def _fit_and_check(tmp_path, truth, seed, cycle, rate):
    m = machine_path("vmc_xyz")
    true = _truth(tmp_path / "true.yaml", truth)
    cli("simulate-thermal", m, "--truth", true, "-o", tmp_path / "warm.csv", "--cycle", cycle, "--rate", rate,
        "--drift-noise", "0.1", *(("--seed", str(seed)) if seed is not None else ()))
    cli("simulate-thermal", m, "--truth", true, "-o", tmp_path / "held.csv", "--rate", "0.2", *HELD_OUT)
    res = cli("thermal", "fit", m, tmp_path / "warm.csv", "-o", tmp_path / "fit.yaml", "--check",
              tmp_path / "held.csv", "--json")
    doc = json.loads(res.stdout)
    written = yaml.safe_load((tmp_path / "fit.yaml").read_text())
    for error, terms in truth.items():
        got = {t["sensor"]: t for t in doc["errors"][error]["terms"]}
        assert set(got) == {s for s, _, _ in terms}, (seed, error, got, doc["errors"][error]["notes"])
        assert [t["sensor"] for t in written["errors"][error]["terms"]] == [t["sensor"] for t in
                                                                            doc["errors"][error]["terms"]]
        for s, g, tau in terms:
            t = got[s]
            assert t["gain"] == pytest.approx(g, rel=0.05), (seed, error, t)
            assert t["time_constant"] == pytest.approx(tau, rel=0.05), (seed, error, t)
            # nothing written that the log cannot support
            assert t["gain_u"] <= 0.5 * abs(t["gain"]) and t["time_constant_u"] <= 0.5 * t["time_constant"]
        held = doc["check"]["errors"][error]
        assert held["after_max"] <= 0.3 * held["before_max"], (seed, error, held)
    return doc


# each about 5 s (2 CPU s of fit per error): the fast tier
@pytest.mark.parametrize("seed", [None, 9, 21, 5])
def test_the_bundled_truth_on_seeds_that_fooled_the_in_sample_choice(tmp_path, seed):
    _fit_and_check(tmp_path, VMC, seed, "warmup", "0.5")


@pytest.mark.parametrize("seed", [None, 9])
def test_a_slow_term_written_here_on_a_log_long_enough_to_see_it(tmp_path, seed):
    # 4 h at full duty and 10 h of cool-down: seven of the slow term's time constants
    _fit_and_check(tmp_path, SLOW, seed, "0:900,1:14400,0:36000", "0.2")


def test_a_term_the_log_cannot_support_is_not_written(tmp_path):
    m = machine_path("vmc_xyz")
    true = _truth(tmp_path / "true.yaml", {"EZZ": VMC["EZZ"]})
    # the warm-up at 0.5 Hz pins T_column's time constant to a few %, T_spindle's to far better
    cli("simulate-thermal", m, "--truth", true, "-o", tmp_path / "warm.csv", "--rate", "0.5", "--seed", "21")
    res = cli("thermal", "fit", m, tmp_path / "warm.csv", "-o", tmp_path / "fit.yaml", "--json",
              "--max-uncertainty", "0.02")
    doc = json.loads(res.stdout)["errors"]["EZZ"]
    assert [t["sensor"] for t in doc["terms"]] == ["T_spindle"], doc
    for t in doc["terms"]:
        assert t["gain_u"] <= 0.02 * abs(t["gain"]) and t["time_constant_u"] <= 0.02 * t["time_constant"], t
    assert any(n.startswith("T_column not taken, the log cannot support it") for n in doc["notes"]), doc["notes"]
    assert [t["sensor"] for t in yaml.safe_load((tmp_path / "fit.yaml").read_text())["errors"]["EZZ"]["terms"]] == \
        ["T_spindle"]
    assert any("cannot support was left out" in a for a in doc["advice"]), doc["advice"]


@pytest.mark.parametrize("term, why", [
    (T.Term("T_a", 1.0, 100.0, 0.6, 1.0), "gain"),
    (T.Term("T_a", 1.0, 100.0, 0.1, 60.0), "time constant"),
    (T.Term("T_a", 1.0, 2000.0, 0.1, 1.0), "longer than the log"),
    (T.Term("T_a", 1.0, 100.0, 0.4, 40.0), None),
    (T.Term("T_a", -1.0, 0.0, 0.4, 0.0), None),
])
def test_unsupported_is_half_the_value_or_beyond_the_log(term, why):
    got = T.unsupported(term, 1000.0, 0.5)
    assert (got is None) if why is None else why in got


def test_the_hall_and_the_sensor_lags_of_simulate_thermal(tmp_path):
    m = machine_path("vmc_xyz")
    true = _truth(tmp_path / "true.yaml", {"EZZ": [("T_spindle", -1.0, 0.0)]})
    out = tmp_path / "still.csv"
    # a hall without swings stays at 20 degC; a spindle sensor, once the spindle starts at 1 s, rises as
    # 15 K (1 - exp(-(t - 1 s) / (2 * 1200 s)))
    cli("simulate-thermal", m, "--truth", true, "-o", out, "--cycle", "0:1,1:3000", "--hall", "0:86400",
        "--sensor-lags", "2", "--temperature-noise", "0", "--drift-noise", "0")
    rows = np.array([[float(c) for c in line.split(",")] for line in out.read_text().splitlines()
                     if line and not line.startswith(("#", "time"))])
    head = [line for line in out.read_text().splitlines() if line.startswith("time")][0].split(",")
    t = rows[:, 0]
    assert np.allclose(rows[:, head.index("T_ambient [degC]")], 20.0, atol=1e-6)
    spindle = rows[:, head.index("T_spindle [degC]")]
    assert np.allclose(spindle, 20.0 + 15.0 * (1 - np.exp(-np.maximum(t - 1.0, 0.0) / 2400.0)), atol=2e-3)
    for bad, words in (("1:10", "period from 60"), ("x", "AMPLITUDE:PERIOD"), ("30:3600", "amplitude is from 0")):
        res = run_in_process("simulate-thermal", m, "--truth", true, "-o", tmp_path / "no.csv", "--hall", bad)
        assert res.returncode == 2 and words in res.stderr and "--hall" in res.stderr, res.stderr
    assert not (tmp_path / "no.csv").exists()
    assert math.isclose(T.sensors_with_lags(3)[1].ambient_lag, 3 * T.DEFAULT_SENSORS[1].ambient_lag)


def test_when_every_term_is_unsupported_nothing_is_written(tmp_path):
    m = machine_path("vmc_xyz")
    true = _truth(tmp_path / "true.yaml", {"EZZ": [("T_spindle", -1.0, 600.0)]})
    log = tmp_path / "short.csv"
    cli("simulate-thermal", m, "--truth", true, "-o", log, "--cycle", "0:600,1:6600", "--rate", "0.2")
    out = tmp_path / "never.yaml"
    res = run_in_process("thermal", "fit", m, log, "-o", out, "--max-uncertainty", "0.0001")
    # the fit's progress lines come first on stderr; the error is the last line, and the only one
    assert res.returncode == 2 and "Traceback" not in res.stderr, res.stderr
    lines = res.stderr.strip().splitlines()
    assert [line for line in lines if "error:" in line] == lines[-1:]
    for words in (f"chaincomp thermal fit: error: {log}: EZZ: no sensor explains its drift",
                  "T_spindle not taken, the log cannot support it (T_spindle: gain", "nothing to write"):
        assert words in lines[-1], (words, lines[-1])
    assert not out.exists()


def test_two_sensors_that_read_the_same_are_said_to_predict_equally():
    # two sensors on the same part (their own noise only): the log cannot tell which the drift follows
    rng = np.random.default_rng(4)
    t = np.arange(0.0, 20000.0, 5.0)
    part = 20.0 + 5.0 * (1 - np.exp(-t / 3000.0)) + 0.5 * np.sin(2 * np.pi * t / 7000.0)
    temps = {"T_a": part + rng.normal(0, 0.02, len(t)), "T_b": part + rng.normal(0, 0.02, len(t))}
    drift = 2.0 * (T.lag(t, part, 600.0) - 20.0) + rng.normal(0, 0.2, len(t))
    log = T.Log("two.csv", t, temps, {"EZZ": drift}, {"EZZ": T.U.unit("um")}, {})
    f = T.fit(log, "EZZ", ["T_a", "T_b"], min_improvement=0.01)
    assert len(f.model.terms) == 1 and f.model.terms[0].gain == pytest.approx(2.0, rel=0.05)
    assert any("T_a" in n and "T_b" in n and "equally well" in n for n in f.notes), f.notes


def test_collinearity_is_the_multiple_correlation_with_the_other_columns():
    rng = np.random.default_rng(5)
    x, y = rng.normal(size=500), rng.normal(size=500)
    ones = np.ones(500)
    # y + 3x: 3x explains 90 % of its variance about the mean (correlation sqrt(0.9)); y alone: none
    assert T._collinearity(np.column_stack([ones, x, 3 * x + y]), 2) == pytest.approx(math.sqrt(0.9), abs=0.02)
    assert T._collinearity(np.column_stack([ones, x, y]), 2) < 0.15
    assert T._collinearity(np.column_stack([ones, x, 2 * x + 1]), 2) == pytest.approx(1.0)
