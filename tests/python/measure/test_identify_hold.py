"""identify --hold P.yaml: errors known from elsewhere held at their values while the others are
fitted. On the trunnion (points from the numpy product of test_new_machines, written from ISO
230-7, not from chaincomp's chain): held at their true values the rest are recovered to 1e-9
relative and the held ones are written as given; a table along an axis (a laser calibration's)
is held along the axis and written back as its entry was."""

import numpy as np
import pytest

from chaincomp import load_machine, load_params
from chaincomp.model.varying import Varying

from helpers import machine_path
from test_identify_any_machine import cli, declared_value, fit_json, injected, in_internal, random_setups, write_csv
from test_identify_trunnion import trunnion_points

TRUNNION = machine_path("trunnion_ac")
# seen by a tracker at random set-ups (test_identify_trunnion's own analysis)
SEEN = ["EY0A", "EZ0A", "EB0A", "EC0A", "EA0A", "EX0C", "EY0C", "EA0C", "EB0C"]


def test_held_errors_stay_and_the_rest_are_recovered(tmp_path, capsys):
    m = load_machine(TRUNNION)
    declared, axes = random_setups(m, np.random.default_rng(31), 30)
    truth = injected(m, np.random.default_rng(32), SEEN)
    write_csv(tmp_path / "meas.csv", m, declared, trunnion_points(m, axes, in_internal(m, truth)))
    (tmp_path / "hold.yaml").write_text(f'machine: trunnion_ac\nvalues:\n  EY0A: "{truth["EY0A"]!r} um"\n'
                                        f'  EB0A: "{truth["EB0A"]!r} arcsec"\n')
    out = tmp_path / "p.yaml"
    doc = fit_json(capsys, TRUNNION, str(tmp_path / "meas.csv"), "--hold", str(tmp_path / "hold.yaml"),
                   "--assume-zero", "EC0C", "-o", str(out))
    assert doc["held"] == ["EB0A", "EY0A"] and "EY0A" not in doc["estimates"] and doc["assumed_zero"] == ["EC0C"]
    for name in SEEN:
        if name not in ("EY0A", "EB0A"):
            assert declared_value(m, doc, name) == pytest.approx(truth[name], rel=1e-9, abs=1e-9)
    values = load_params(str(out), m)
    assert values["EY0A"] == pytest.approx(truth["EY0A"] * 1e-3, rel=1e-12)
    assert "held at a given value (--hold)" in out.read_text()
    # held at a wrong value, the same data no longer fit to rounding: the held value is used
    (tmp_path / "wrong.yaml").write_text('machine: trunnion_ac\nvalues:\n  EY0A: "50 um"\n')
    wrong = fit_json(capsys, TRUNNION, str(tmp_path / "meas.csv"), "--hold", str(tmp_path / "wrong.yaml"),
                     "--assume-zero", "EC0C")
    assert wrong["rms_residual"] > 1e-4 > doc["rms_residual"]


def test_a_held_table_is_used_along_its_axis_and_written_back(tmp_path, capsys):
    five = machine_path("five_axis_ac")
    m = load_machine(five)
    hold = tmp_path / "hold.yaml"
    hold.write_text("machine: five_axis_ac\nvalues:\n  EXX:   # a laser's\n    axis: X\n    units: [mm, um]\n"
                    "    interpolation: linear\n    outside: hold\n    table:\n      - [-400, 0]\n      - [0, 12]\n"
                    "      - [400, -5]\n")
    meas = tmp_path / "meas.csv"
    rc, _, err = cli(capsys, "simulate-measurements", five, "--params", str(hold), "-o", str(meas), "--seed", "4")
    assert rc == 0, err
    out = tmp_path / "p.yaml"
    doc = fit_json(capsys, five, str(meas), "--hold", str(hold), "--minimal", "-o", str(out))
    assert "EXX" not in doc["estimates"] and doc["rms_residual"] < 1e-9    # the table explains the data
    written = load_params(str(out), m)["EXX"]
    held = load_params(str(hold), m)["EXX"]
    assert isinstance(written, Varying)
    x = np.linspace(-450, 450, 37)
    assert np.allclose(written(x), held(x), rtol=0, atol=1e-15)
