"""Thermal models: the lag against its closed forms, the fit against the known model a
simulation ran, on a machine this file writes and on vmc_xyz; held-out logs; bad input.

Truth from outside the code: the first-order lag's responses to a ramp and to a sine are
solved here by hand (dy/dt = (u - y)/tau, y(0) = u(0)); the fit's truth is the model the
test hands to simulate-thermal."""

import json
import math

import numpy as np
import pytest
import yaml

from chaincomp.measure import thermal as T
from chaincomp.measure.thermal import lag
from chaincomp.model import units as U
from chaincomp.model.machine import load_machine
from helpers import ROOT, cli, machine_path, one_error_line, run_cli, run_in_process

LATHE = """\
name: lathe_zx
description: a two-axis lathe written by the test
length_unit: mm
rotation_sense: right_hand
error_block_order: txyz
symbols:
  - {name: Z, role: axis, unit: mm, limits: [-300, 0], meaning: carriage}
  - {name: X, role: axis, unit: mm, limits: [0, 100], meaning: cross slide}
  - {name: EZS, role: error, unit: um, meaning: spindle growth along z}
  - {name: EBS, role: error, unit: arcsec, meaning: headstock tilt about y}
loop:
  tool:
    - {translate: [X, 0, Z], label: slides}
  workpiece:
    - {errors: {dz: EZS, ey: EBS}, label: headstock}
tool:
  point: [0, 0, 0]
  direction: [0, 0, 1]
"""
# the truth: the headstock grows with the spindle's temperature and tilts with the bed's
LATHE_TRUE = """\
machine: lathe_zx
errors:
  EZS:
    unit: um
    terms:
      - {sensor: T_spindle, gain: 2.0, time_constant: 1500}
  EBS:
    unit: arcsec
    offset: 0.5
    terms:
      - {sensor: T_column, gain: -1.2, time_constant: 1200}
      - {sensor: T_coolant, gain: 0.8}
"""
VMC_TRUE = {"EZZ": [("T_spindle", -1.5, 900.0), ("T_column", 0.6, 3600.0)], "EYZ": [("T_column", -0.8, 2400.0)]}


@pytest.fixture(scope="module")
def lathe(tmp_path_factory):
    d = tmp_path_factory.mktemp("thermal")
    (d / "lathe.yaml").write_text(LATHE)
    (d / "true.yaml").write_text(LATHE_TRUE)
    return d


# ----------------------------------------------------------------------------- the lag

@pytest.mark.parametrize("tau", [0.5, 7.0, 60.0, 3000.0])
def test_lag_of_a_ramp_is_the_closed_form_at_uneven_times(tau):
    rng = np.random.default_rng(3)
    t = np.cumsum(np.r_[0.0, rng.uniform(0.05, 3.0, 2000)])
    r = 0.01   # K/s: linear between readings, so the lag is exact there
    y = lag(t, r * t, tau)
    exact = r * (t - tau * (1 - np.exp(-t / tau)))
    assert np.max(np.abs(y - exact)) < 1e-9 * max(1.0, r * t[-1])


def test_lag_of_a_sine_is_the_closed_form_within_the_sampling_error():
    tau, w, a = 600.0, 2 * math.pi / 3000.0, 3.0
    t = np.arange(0.0, 20000.0, 1.0)
    y = lag(t, a * np.sin(w * t), tau)
    k = 1 + (w * tau) ** 2
    exact = a / k * (np.sin(w * t) - w * tau * np.cos(w * t)) + a * w * tau / k * np.exp(-t / tau)
    # input linear between readings 1 s apart: the error is of order a (w dt)^2 / 8
    assert np.max(np.abs(y - exact)) < a * (w * 1.0) ** 2


def test_lag_zero_follows_the_input():
    t = np.arange(5.0)
    assert np.array_equal(lag(t, t ** 2, 0.0), t ** 2)


# ----------------------------------------------------------------------------- the fit

def _terms(model_path):
    doc = yaml.safe_load(open(model_path))
    return {e: [(t["sensor"], t["gain"], t.get("time_constant", 0.0)) for t in m["terms"]] for e, m in doc["errors"].items()}


def _simulate(machine, true, out, *extra):
    cli("simulate-thermal", machine, "--truth", true, "-o", out, *extra)


def test_fit_recovers_the_lathe_written_here_and_compensates_a_held_out_cycle(lathe):
    m, true = lathe / "lathe.yaml", lathe / "true.yaml"
    _simulate(m, true, lathe / "warm.csv")
    _simulate(m, true, lathe / "held.csv", "--cycle", "varied", "--seed", "7", "--drift-noise", "0",
              "--temperature-noise", "0")
    res = cli("thermal", "fit", m, lathe / "warm.csv", "-o", lathe / "fit.yaml", "--check", lathe / "held.csv",
              "--json")
    doc = json.loads(res.stdout)
    fitted = _terms(lathe / "fit.yaml")
    truth = {"EZS": [("T_spindle", 2.0, 1500.0)], "EBS": [("T_column", -1.2, 1200.0), ("T_coolant", 0.8, 0.0)]}
    for error, terms in truth.items():
        got = {s: (g, tau) for s, g, tau in fitted[error]}
        assert set(got) == {s for s, _, _ in terms}, (error, fitted[error])
        for s, g, tau in terms:
            assert got[s][0] == pytest.approx(g, rel=0.05), (error, s)
            if tau:
                assert got[s][1] == pytest.approx(tau, rel=0.05), (error, s)
            else:   # the fit still gives a lag: a short one, next to the coolant's 1500 s swing
                assert got[s][1] < 60.0, (error, s, got[s])
        held = doc["check"]["errors"][error]
        assert held["after_max"] <= 0.3 * held["before_max"], (error, held)
    assert doc["errors"]["EBS"]["offset"] == pytest.approx(0.5, abs=0.2)


def test_fit_recovers_vmc_xyz_within_5_percent_with_honest_uncertainties(tmp_path):
    m = machine_path("vmc_xyz")
    true = tmp_path / "true.yaml"
    true.write_text("machine: vmc_xyz\nerrors:\n" + "".join(
        f"  {e}:\n    unit: um\n    terms:\n" + "".join(
            f"      - {{sensor: {s}, gain: {g}, time_constant: {tau}}}\n" for s, g, tau in terms)
        for e, terms in VMC_TRUE.items()))
    _simulate(m, true, tmp_path / "warm.csv")
    _simulate(m, true, tmp_path / "held.csv", "--cycle", "varied", "--seed", "2", "--drift-noise", "0")
    doc = json.loads(cli("thermal", "fit", m, tmp_path / "warm.csv", "-o", tmp_path / "fit.yaml",
                         "--check", tmp_path / "held.csv", "--json").stdout)
    for error, terms in VMC_TRUE.items():
        got = {t["sensor"]: t for t in doc["errors"][error]["terms"]}
        assert set(got) == {s for s, _, _ in terms}, (error, got)   # two of five sensors, one of five
        for s, g, tau in terms:
            t = got[s]
            assert t["gain"] == pytest.approx(g, rel=0.05) and t["time_constant"] == pytest.approx(tau, rel=0.05)
            # white noise on the drift, and the model the simulation ran: the truth within 4 u
            assert abs(t["gain"] - g) <= 4 * t["gain_u"] and abs(t["time_constant"] - tau) <= 4 * t["time_constant_u"]
        held = doc["check"]["errors"][error]
        assert held["after_max"] <= 0.3 * held["before_max"], (error, held)
    # the model written reads back, and thermal check on it agrees with fit --check
    check = json.loads(run_cli("thermal", "check", m, tmp_path / "fit.yaml", tmp_path / "held.csv", "--json").stdout)
    for error in VMC_TRUE:
        assert check["errors"][error]["after_max"] == pytest.approx(doc["check"]["errors"][error]["after_max"], rel=1e-9)


def test_fit_without_lags_and_with_a_chosen_sensor(lathe):
    m = lathe / "lathe.yaml"
    if not (lathe / "warm.csv").exists():
        _simulate(m, lathe / "true.yaml", lathe / "warm.csv")
    cli("thermal", "fit", m, lathe / "warm.csv", "-o", lathe / "nolag.yaml", "--no-lag", "--sensors", "T_spindle",
        "--errors", "EZS")
    fitted = _terms(lathe / "nolag.yaml")
    assert list(fitted) == ["EZS"] and [(s, tau) for s, _, tau in fitted["EZS"]] == [("T_spindle", 0.0)]


# ----------------------------------------------------------------------------- bad input

GOOD_LOG = "time [s],T_a [degC],EZS [um]\n" + "".join(f"{i},{20 + 0.1 * i},{0.2 * i}\n" for i in range(12))


def _log(lathe, text, name="bad.csv"):
    p = lathe / name
    p.write_text(text)
    return p


@pytest.mark.parametrize("text, words", [
    ("T_a [degC],EZS [um]\n1,2\n", ["no 'time [s]' column"]),
    ("time [s],T_a,EZS [um]\n", ["has no unit", "T_a"]),
    ("time [min],T_a [degC],EZS [um]\n", ["seconds"]),
    ("time [s],T_a [degC],EQQ [um]\n", ["EQQ", "not an error of lathe_zx"]),
    ("time [s],T_a [degC],EBS [um]\n", ["EBS is an angle", "um"]),
    ("time [s],T_a [degC],EZS [furlong]\n", ["unknown unit 'furlong'"]),
    ("time [s],T_a [degC],T_a [degC],EZS [um]\n", ["two columns named 'T_a [degC]' (columns 2 and 3)"]),
    ("time [s],T a [degC],EZS [um]\n", ["sensor name 'T a'"]),
    ("time [s],EZS [um]\n1,2\n", ["no temperature column"]),
    (GOOD_LOG.replace("\n5,20.5,", "\n5,nan,"), [":7: T_a [degC]: expected a finite number, got 'nan'"]),
    (GOOD_LOG.replace("\n5,20.5,", "\n5,999,"), [":7: T_a [degC]: 999 degC is outside"]),
    (GOOD_LOG.replace("\n5,", "\n4,"), [":7: time [s]: time 4 s does not follow 4 s"]),
    (GOOD_LOG.replace("\n5,20.5,1.0\n", "\n5,20.5\n"), [":7: 2 cells, the header has 3"]),
    (GOOD_LOG.replace("\n5,20.5,1.0\n", "\n5,20.5,1e300\n"), ["larger than"]),
    ("time [s],T_a [degC],EZS [um]\n1,20,0\n2,21,1\n", ["2 rows: a fit needs at least 10"]),
    ("", ["no header row"]),
])
def test_bad_logs_are_refused_on_one_line_naming_the_file(lathe, text, words):
    p = _log(lathe, text)
    out = lathe / "never.yaml"
    res = run_in_process("thermal", "fit", lathe / "lathe.yaml", p, "-o", out)
    one_error_line(res, "thermal fit", str(p), *words)
    assert not out.exists()


MODEL = "machine: lathe_zx\nerrors:\n  EZS:\n    unit: um\n    terms:\n      - {sensor: T_spindle, gain: 2.0, time_constant: 1500}\n"


@pytest.mark.parametrize("old, new, words", [
    ("machine: lathe_zx", "machine: vmc_xyz", [":1: machine: the model is of machine 'vmc_xyz'"]),
    ("  EZS:", "  EQQ:", [":3: EQQ: 'EQQ' is not an error of lathe_zx"]),
    ("unit: um", "unit: arcsec", [":4: unit: EZS is a length in lathe_zx, not an angle"]),
    ("unit: um", "unit: degC", [":4: unit: expected a unit (um, arcsec, ppm, ...), got str 'degC'"]),
    ("time_constant: 1500", "time_constant: -1", [":6: time_constant: -1.0 is outside [0, 1e+06]"]),
    ("time_constant: 1500", "time_constant: .nan", [":6: time_constant: nan is outside"]),
    ("gain: 2.0", "gain: 1.0e+300", [":6: gain: 1e+300 is outside"]),
    ("gain: 2.0", "gain: 1e300", [":6: gain: expected a number", "write 1.0e+300"]),
    ("gain: 2.0", "gain: '2'", [":6: gain: expected a number"]),
    ("sensor: T_spindle", "sensor: 'T spindle'", [":6: sensor: expected a sensor name"]),
    ("    terms:", "    offsets: 1\n    terms:", [":5: offsets: unknown key 'offsets'"]),
    ("gain: 2.0, time_constant: 1500}", "gain: 2.0, time_constant: 1500}\n      - {sensor: T_spindle, gain: 1, "
     "time_constant: 1500}", [":7: terms: a second term of sensor T_spindle"]),
    ("      - {sensor: T_spindle, gain: 2.0, time_constant: 1500}\n", "".join(
        f"      - {{sensor: T{i}, gain: 1}}\n" for i in range(9)), [":5: terms: expected a list of 1 to 8 terms"]),
])
def test_bad_models_are_refused_naming_the_line_and_field(lathe, old, new, words):
    assert old in MODEL
    p = lathe / "badmodel.yaml"
    p.write_text(MODEL.replace(old, new))
    out = lathe / "never.csv"
    res = run_in_process("simulate-thermal", lathe / "lathe.yaml", "--truth", p, "-o", out)
    one_error_line(res, "simulate-thermal", str(p), *words)
    assert not out.exists()


@pytest.mark.parametrize("args, words", [
    (["--sensors", "T_nope"], ["--sensors: no temperature column T_nope"]),
    (["--errors", "EBS"], ["--errors: no drift column of EBS"]),
    (["--drift", "EZS"], ["--drift: expected COLUMN=ERROR"]),
    (["--drift", "X=EZS"], ["--drift: no column X in the header"]),
    (["--max-sensors", "9"], ["--max-sensors"]),
    (["--min-improvement", "nan"], ["--min-improvement"]),
])
def test_bad_fit_options_are_refused(lathe, args, words):
    p = _log(lathe, GOOD_LOG, "good.csv")
    out = lathe / "never.yaml"
    res = run_in_process("thermal", "fit", lathe / "lathe.yaml", p, "-o", out, *args)
    one_error_line(res, "thermal fit", *words)
    assert not out.exists()


@pytest.mark.parametrize("args, words", [
    (["--cycle", "1:60,x"], ["--cycle: expected warmup or varied or DUTY:SECONDS"]),
    (["--cycle", "2:60"], ["the duty is from 0 to 1"]),
    (["--cycle", "1:5"], ["fewer than 10 readings"]),
    (["--rate", "100"], ["--rate"]),
])
def test_bad_simulation_options_are_refused(lathe, args, words):
    out = lathe / "never.csv"
    res = run_in_process("simulate-thermal", lathe / "lathe.yaml", "--truth", lathe / "true.yaml", "-o", out, *args)
    one_error_line(res, "simulate-thermal", *words)
    assert not out.exists()


def test_a_model_of_sensors_not_simulated_or_not_logged_is_refused(lathe):
    p = lathe / "other.yaml"
    p.write_text(MODEL.replace("T_spindle", "T_motor"))
    res = run_in_process("simulate-thermal", lathe / "lathe.yaml", "--truth", p, "-o", lathe / "never.csv")
    one_error_line(res, "simulate-thermal", "sensor T_motor is not simulated")
    log = _log(lathe, GOOD_LOG, "good.csv")
    res = run_in_process("thermal", "check", lathe / "lathe.yaml", p, log)
    one_error_line(res, "thermal check", "reads sensor T_motor, not in the log")


def test_the_output_is_not_an_input(lathe):
    log = _log(lathe, GOOD_LOG, "good.csv")
    res = run_in_process("thermal", "fit", lathe / "lathe.yaml", log, "-o", log)
    one_error_line(res, "thermal fit", "is also an input")
    assert log.read_text() == GOOD_LOG


# ----------------------------------------------------------------------------- found by a bad-input hunt

def _rows(n, temp, drift, step=1.0):
    return "time [s],T_a [degC],T_b [degC],EZS [um]\n" + "".join(
        f"{step * i!r},{temp(i)!r},{20 + 0.5 * math.sin(i / 30)!r},{drift(i)!r}\n" for i in range(n))


@pytest.mark.parametrize("drift, words", [
    (lambda i: 0.0, ["EZS: the drift is constant (0 um): nothing to fit"]),
    (lambda i: 3.0, ["EZS: the drift is constant (3 um)"]),
])
def test_a_constant_drift_is_refused(lathe, drift, words):
    p = _log(lathe, _rows(200, lambda i: 20 + i / 100, drift), "flat.csv")
    one_error_line(run_in_process("thermal", "fit", lathe / "lathe.yaml", p, "-o", lathe / "never.yaml"),
                   "thermal fit", str(p), *words)


def test_a_sensor_that_does_not_vary_is_never_taken(lathe):
    # the fit took it with a gain of -4.9e12 um/K, fitting the rounding of its lag
    p = _log(lathe, "time [s],T_a [degC],EZS [um]\n" + "".join(f"{i},21.0,{0.001 * i!r}\n" for i in range(200)),
             "const.csv")
    one_error_line(run_in_process("thermal", "fit", lathe / "lathe.yaml", p, "-o", lathe / "never.yaml"),
                   "thermal fit", "no sensor explains its drift")


def test_a_sensor_or_error_given_twice_is_refused(lathe):
    p = _log(lathe, GOOD_LOG, "good.csv")
    one_error_line(run_in_process("thermal", "fit", lathe / "lathe.yaml", p, "-o", lathe / "never.yaml",
                                  "--sensors", "T_a,T_a"), "thermal fit", "--sensors: T_a given twice")


def test_the_model_written_reads_back_whatever_its_values_and_names(lathe):
    # 1e+06, 1e-05 (YAML 1.1 reads them as text) and sensor names YAML reads as bool or null
    machine = load_machine(str(lathe / "lathe.yaml"))
    model = T.ThermalModel("lathe_zx", 1e-5)
    model.errors["EZS"] = T.ErrorModel("EZS", U.unit("um"), 2.5e-7, [
        T.Term("on", 1.5e5, 1e6), T.Term("No", -2e-9, 0.0), T.Term("null", 3.0, 1e-5), T.Term("True", 1.0, 120.0)])
    p = lathe / "written.yaml"
    p.write_text(T.model_text(model, ["written by the test"]))
    back = T.load_model(str(p), machine)
    assert back.reference == pytest.approx(1e-5)
    terms = [(t.sensor, t.gain, t.time_constant) for t in back.errors["EZS"].terms]
    assert terms == [("on", pytest.approx(1.5e5), pytest.approx(1e6)), ("No", pytest.approx(-2e-9), 0.0),
                     ("null", pytest.approx(3.0), pytest.approx(1e-5)), ("True", pytest.approx(1.0), pytest.approx(120.0))]


@pytest.mark.parametrize("edit, words", [
    (lambda t: t.replace("gain: 2.0", "gain: -" + "9" * 400), [":6: gain: -inf is outside"]),
    (lambda t: t.replace("time_constant: 1500", "time_constant: " + "9" * 300), [":6: time_constant: 1e+300 is outside"]),
    (lambda t: t.replace("gain: 2.0, time_constant: 1500}", "gain: 2.0, time_constant: 0}\n"
                         "      - {sensor: T_spindle, gain: 1, time_constant: -0.0}"), [":7: terms: a second term"]),
    (lambda t: t.replace("  EZS:\n    unit: um\n    terms:\n      - {sensor: T_spindle, gain: 2.0, time_constant: 1500}\n",
                         " {}\n"), ["errors: expected a mapping of error names to their models, got an empty mapping"]),
])
def test_more_bad_models(lathe, edit, words):
    p = lathe / "bad2.yaml"
    p.write_text(edit(MODEL))
    res = run_in_process("simulate-thermal", lathe / "lathe.yaml", "--truth", p, "-o", lathe / "never.csv")
    one_error_line(res, "simulate-thermal", str(p), *words)


@pytest.mark.parametrize("old, new, words", [
    ("\n5,20.5,1.0\n", "\n5,\u0662\u0660.\u0665,1.0\n", [":7: T_a [degC]: expected a plain decimal number"]),   # Arabic-Indic digits
    ("\n5,20.5,1.0\n", "\n5,\uff12\uff10.5,1.0\n", [":7: T_a [degC]: expected a plain decimal number"]),        # fullwidth
    ("\n5,20.5,1.0\n", "\n5,\u300020.5,1.0\n", [":7: T_a [degC]: expected a plain decimal number"]),            # ideographic space
    ("\n5,20.5,", "\n4.0000000001,20.5,", [":7: time [s]: time 4 s does not follow 4 s by at least 1e-06 s"]),
])
def test_more_bad_logs(lathe, old, new, words):
    assert old in GOOD_LOG
    p = _log(lathe, GOOD_LOG.replace(old, new), "bad2.csv")
    one_error_line(run_in_process("thermal", "fit", lathe / "lathe.yaml", p, "-o", lathe / "never.yaml"),
                   "thermal fit", str(p), *words)


def test_a_line_separator_in_a_comment_does_not_split_it(lathe):
    # str.splitlines split there: the rest of the comment was taken for the header, one line off
    p = _log(lathe, "# a note\u2028on two lines\n# and\x0ca form feed\n" + GOOD_LOG.replace("\n5,20.5,", "\n5,nan,"),
             "sep.csv")
    one_error_line(run_in_process("thermal", "fit", lathe / "lathe.yaml", p, "-o", lathe / "never.yaml"),
                   "thermal fit", f"{p}:9: T_a [degC]: expected a finite number, got 'nan'")


def test_the_simulated_log_is_read_every_1_over_rate_seconds(lathe):
    out = lathe / "slow.csv"
    cli("simulate-thermal", lathe / "lathe.yaml", "--truth", lathe / "true.yaml", "-o", out, "--rate", "0.09",
        "--cycle", "1:3600")
    t = np.loadtxt(out, delimiter=",", skiprows=3, usecols=0)
    assert np.diff(t) == pytest.approx(1 / 0.09, abs=1e-3) and len(t) == 325   # (written to 1 ms)


# ----------------------------------------------------------------------------- per-axis streams

SCALED_LATHE = LATHE.replace("    - {translate: [X, 0, Z], label: slides}", "    - {translate: [X*(1 + SXS), 0, Z], label: slides}").replace(
    "  - {name: EBS, role: error, unit: arcsec, meaning: headstock tilt about y}",
    "  - {name: EBS, role: error, unit: arcsec, meaning: headstock tilt about y}\n"
    "  - {name: SXS, role: error, unit: ppm, meaning: scale of the cross slide}")
SCALED_TRUE = """\
machine: lathe_zx
errors:
  EZS:
    unit: um
    terms:
      - {sensor: T_spindle, gain: 2.0, time_constant: 1500}
  SXS:
    unit: ppm
    terms:
      - {sensor: T_bed, gain: 11.5, time_constant: 3600}
"""


def _stream(path):
    """A CSV's columns by header (comment lines skipped)."""
    with open(path) as f:
        rows = [line.strip().split(",") for line in f if not line.startswith("#")]
    data = np.array(rows[1:], float)
    return {h: data[:, k] for k, h in enumerate(rows[0])}


def test_streams_are_the_error_lines_along_each_axis(tmp_path):
    """A scale error of the cross slide (ppm, the steel's expansion) is X's slope; the headstock's
    growth along z is Z's offset: both against the simulated truth (the log's drift columns), with
    the manuals' sign: the error line itself (the controller takes it out)."""
    (tmp_path / "m.yaml").write_text(SCALED_LATHE)
    (tmp_path / "true.yaml").write_text(SCALED_TRUE)
    m, true, log = tmp_path / "m.yaml", tmp_path / "true.yaml", tmp_path / "log.csv"
    cli("simulate-thermal", m, "--truth", true, "-o", log, "--drift-noise", "0", "--temperature-noise", "0",
        "--rate", "0.1")
    truth = np.loadtxt(log, delimiter=",", skiprows=3)
    ezs, sxs = truth[:, -2] * 1e-3, truth[:, -1] * 1e-6    # mm, 1 (the truth on a 1 s step; the stream on the log's 10 s)
    doc = json.loads(cli("thermal", "stream", m, true, log, "--controller", "siemens", "-o", tmp_path / "s.csv",
                         "--reference-position", "X=50", "--json").stdout)
    s = _stream(tmp_path / "s.csv")
    # X moves the tool by X (1 + SXS): the error along X is SXS X = SXS 50 + SXS (X - 50)
    assert s["X SD43910 $SA_TEMP_COMP_SLOPE [1]"] == pytest.approx(sxs, rel=1e-3, abs=1e-11)
    assert s["X SD43900 $SA_TEMP_COMP_ABS_VALUE [mm]"] == pytest.approx(sxs * 50, rel=1e-3, abs=1e-9)
    assert np.all(s["X SD43920 $SA_TEMP_COMP_REF_POSITION [mm]"] == 50)
    # the headstock (workpiece side) grows by EZS towards the tool: the tool relative to the workpiece moves -EZS in z
    assert s["Z SD43900 $SA_TEMP_COMP_ABS_VALUE [mm]"] == pytest.approx(-ezs, rel=1e-3, abs=1e-7)   # (readings 10 s apart)
    assert np.max(np.abs(s["Z SD43910 $SA_TEMP_COMP_SLOPE [1]"])) < 1e-12   # (rounding: 0.01 nm over 1 m)
    assert doc["axes"]["X"]["line_departure_max_um"] < 1e-6   # a scale is a line
    cli("thermal", "stream", m, true, log, "--controller", "isg", "-o", tmp_path / "i.csv", "--reference-position", "X=50")
    i = _stream(tmp_path / "i.csv")
    assert np.array_equal(i["X P-AXIS-00274 temp_comp_coefficient [um/m]"],
                          np.rint(s["X SD43910 $SA_TEMP_COMP_SLOPE [1]"] * 1e6))   # the same values, rounded
    assert np.array_equal(i["Z P-AXIS-00273 temp_comp_offset_0 [0.1um]"], np.rint(s["Z SD43900 $SA_TEMP_COMP_ABS_VALUE [mm]"] * 1e4))
    assert np.max(np.abs(i["X P-AXIS-00274 temp_comp_coefficient [um/m]"] - sxs * 1e6)) <= 0.5 + 1e-3
    assert np.all(i["X P-AXIS-00272 temp_comp_position_0 [0.1um]"] == 500000)


def _controller_line(stream, axis, fmt, p):
    """The compensation value at axis position ``p`` (mm), read from the stream as each manual
    defines its parameters: SINUMERIK Extended Functions K3, 'Temperature compensation':
    Delta K = SD43900 + SD43910 * (P - SD43920), the approximated error line; ISG: the
    temperature offset P-AXIS-00273 (0.1 um) at the basic position P-AXIS-00272 (0.1 um) plus
    the pitch P-AXIS-00274 (um/m)."""
    col = {k.split(" ", 2)[1]: v for k, v in stream.items() if k.startswith(axis + " ")}
    if fmt == "siemens":
        return col["SD43900"] + col["SD43910"] * (p - col["SD43920"])
    return col["P-AXIS-00273"] * 1e-4 + col["P-AXIS-00274"] * 1e-6 * (p - col["P-AXIS-00272"] * 1e-4)


@pytest.mark.parametrize("fmt", ["siemens", "isg"])
def test_the_controller_applying_the_stream_as_its_manual_says_removes_the_bundled_warm_up_drift(tmp_path, fmt):
    """vmc_xyz warmed up by the bundled model: the axis' actual position is the command plus the
    error, and the controller takes its compensation value as that error and moves the axis by
    minus it (K3: a positive compensation value moves the axis negative). On vmc_xyz EZZ and EYZ
    are tool-side offsets (dz, dy), the head moves the tool by +Z and the saddle by +Y
    relative to the workpiece (configs/machines/vmc_xyz.yaml): the error along Z is EZZ and along
    Y is EYZ, at every position. What is left must be a small part of the drift, not double it."""
    m, true, log = machine_path("vmc_xyz"), f"{ROOT}/configs/thermal/vmc_xyz-true.yaml", tmp_path / "log.csv"
    cli("simulate-thermal", m, "--truth", true, "-o", log, "--drift-noise", "0", "--temperature-noise", "0",
        "--rate", "0.1")
    drift = _stream(log)
    cli("thermal", "stream", m, true, log, "--controller", fmt, "-o", tmp_path / "s.csv")
    s = _stream(tmp_path / "s.csv")
    for axis, error, (lo, hi) in (("Z", "EZZ", (-400, 0)), ("Y", "EYZ", (-250, 250))):
        e = drift[f"{error} [um]"] * 1e-3   # mm: the axis' actual position minus its command, uncompensated
        before = np.max(np.abs(e))
        assert before > (0.015 if axis == "Z" else 0.0005)   # a warm-up worth compensating
        for p in (lo, (lo + hi) / 2, hi):
            left = e - _controller_line(s, axis, fmt, p)     # the axis commanded to p - Delta K
            assert np.max(np.abs(left)) < 0.02 * before + 0.1e-3, (axis, p, np.max(np.abs(left)), before)
    assert np.all(_controller_line(s, "X", fmt, 400.0) == 0)   # neither error moves the tool along x


def test_stream_bad_options(lathe):
    log = _log(lathe, GOOD_LOG, "good.csv")
    out = lathe / "never.csv"
    p = lathe / "tmodel.yaml"
    p.write_text(MODEL)
    one_error_line(run_in_process("thermal", "stream", lathe / "lathe.yaml", p, log, "--controller", "isg", "-o", out),
                   "thermal stream", "reads sensor T_spindle, not in the log")
    p.write_text(MODEL.replace("T_spindle", "T_a"))
    for bad in ("Q=1", "X", "X=abc"):
        one_error_line(run_in_process("thermal", "stream", lathe / "lathe.yaml", p, log, "--controller", "isg", "-o", out,
                                      "--reference-position", bad), "thermal stream", "--reference-position")
    assert not out.exists()
