"""The reversal in a LinuxCNC table, against a simulated axis with lost motion (issue #42 item 2).

Truth from outside the code: the axis is simulated here — moving up it stops 4 µm short, moving
down 4 µm past (a lost motion of 8 µm) — on top of the positioning error EXX of the tests' own
gantry (test_export.OWN). ISO 230-2:2014 defines B_i = x̄_i↑ − x̄_i↓ (here −8 µm at every
target), B = max |B_i| and the mean reversal B̄ = (1/m) Σ B_i. The table is read back by
linuxcnc_comp.py (LinuxCNC's usrmotintf.cc, command.c, control.c: the forward trim while the
joint moves forward, the reverse trim while it moves back) and replayed on the simulated axis."""

import re

import numpy as np
import pytest

import linuxcnc_comp
from helpers import run_main, write_file
from test_export import OWN, POSITIONING, exx

LOST = 8e-3     # mm: the axis stops LOST/2 short of the target moving up, LOST/2 past it moving down
TARGETS = np.linspace(0, 300, 11)


def reached(joint, up: bool):
    """Where the simulated X axis stands (mm) with its joint commanded to ``joint``."""
    return joint + exx(joint) + (-LOST / 2 if up else LOST / 2)


def runs_csv(tmp_path) -> str:
    rows = ["target [mm],run,direction,deviation [um]"]
    for t in TARGETS:
        for j in range(1, 4):
            for d in ("up", "down"):
                rows.append(f"{float(t)!r},{j},{d},{float(reached(t, d == 'up') - t) * 1e3!r}")
    return write_file(tmp_path, "x_runs.csv", "\n".join(rows) + "\n")


def table_of(capsys, tmp_path, *option):
    machine = write_file(tmp_path, "own_xyz.yaml", OWN)
    params = write_file(tmp_path, "own.yaml", POSITIONING)
    out = tmp_path / "comp"
    code, stdout, err = run_main(capsys, "export", machine, "--params", params, "--controller", "linuxcnc-comp", "-o",
                                 out, "--grid", "3", "--entries", "31", "--no-breakdown", *option)
    assert code == 0, err
    return linuxcnc_comp.read((out / "joint0_X.comp").read_text(), 1), stdout, err, out


def reversal_left(table) -> np.ndarray:
    """At each target, approached up then down: where the axis stands up minus down (mm)."""
    p = np.linspace(0, 300, 61)
    return (reached(p + linuxcnc_comp.trim(table, p, forward=True), True)
            - reached(p + linuxcnc_comp.trim(table, p, forward=False), False))


def test_the_mean_reversal_iso230_2_prints_takes_the_lost_motion_out(capsys, tmp_path):
    code, text, err = run_main(capsys, "iso230-2", runs_csv(tmp_path))
    assert code == 0, err
    b = re.search(r"B   reversal error of the axis, max \|B_i\| +(\S+) um", text)
    assert float(b.group(1)) == pytest.approx(LOST * 1e3, abs=1e-3)   # B = max |B_i| >= 0
    given = re.search(r"--mean-reversal AXIS=(\S+um)", text).group(1)
    assert float(given[:-2]) == pytest.approx(-LOST * 1e3, abs=1e-3)    # B̄: signed, negative for lost motion
    table, report, _, out = table_of(capsys, tmp_path, "--mean-reversal", f"X={given}")
    assert np.max(np.abs(reversal_left(table))) < 1e-6                      # 0, not -16 um
    p = np.linspace(0, 300, 61)   # and each direction lands on the target (the table's curvature aside)
    assert np.max(np.abs(reached(p + linuxcnc_comp.trim(table, p, forward=True), True) - p)) < 0.05e-3
    # the report and the INI say that BACKLASH no longer applies and where the reversal went
    assert "LinuxCNC ignores [JOINT_n]BACKLASH once a COMP_FILE is loaded" in report
    assert "mean reversal B̄ in the tables: X -0.008 mm" in report
    ini = (out / "compensation.ini").read_text()
    assert "ignores [JOINT_n]BACKLASH" in ini and "the table's mean reversal: -0.008 mm" in ini


def test_b_copied_as_the_reversal_doubles_it_and_the_old_option_warns(capsys, tmp_path):
    """B = max |B_i| (8 µm) where B̄ belongs: the table adds the lost motion instead of taking it
    out (-16 µm left); --reversal, which once asked for B, warns and takes B̄ as well."""
    table, _, err, _ = table_of(capsys, tmp_path, "--reversal", f"X={LOST * 1e3}um")
    assert np.allclose(reversal_left(table), -2 * LOST, atol=1e-6)
    assert "warning: --reversal is deprecated" in err and "--mean-reversal" in err
    table, _, _, _ = table_of(capsys, tmp_path, "--reversal", f"X={-LOST * 1e3}um")
    assert np.max(np.abs(reversal_left(table))) < 1e-6
