"""chaincomp simulate-measurements' bad input: set-ups beyond the limits (a warning), where the model
is not finite, an empty --params."""

from __future__ import annotations

import subprocess
import sys

import pytest

from helpers import M4, M4_SQRT, cli, machine_path, write_file


@pytest.mark.slow
def test_simulate_measurements_refuses_an_empty_params(tmp_path):
    # '' (an unset shell variable) is a typo, not a request for every error at zero
    proc = subprocess.run([sys.executable, "-m", "chaincomp.cli.main", "simulate-measurements",
                           machine_path("vmc_xyz"), "--params", "", "-o", str(tmp_path / "m.csv")],
                          capture_output=True, text=True, timeout=120)
    assert proc.returncode == 2 and "--params: an empty value" in proc.stderr, proc.stderr
    assert not (tmp_path / "m.csv").exists()

# A four-axis machine written the way a user would: X, Y, Z slides and a B table, one error block
# after each, a tool length L.


def test_simulate_measurements_warns_of_set_ups_beyond_the_limits(tmp_path):
    """grid: values beyond the limits are left out with a note, --set beyond them is refused;
    a set-ups CSV beyond them was simulated without a word."""
    machine = write_file(tmp_path, "m.yaml", M4)
    setups = write_file(tmp_path, "s.csv", "X,Y,Z,B\n1,2,-3,4\n1,2,-3,4000\n")
    proc = cli("simulate-measurements", machine, "--setups", setups, "-o", str(tmp_path / "o.csv"))
    assert f"chaincomp simulate-measurements: warning: {setups}:3: B: 4000 deg is outside its limits [-90, 90] " \
           "(1 row of 2; is it in deg?)" in proc.stderr
    # B held by --set: the CSV's B is not used, so nothing to warn about
    proc = cli("simulate-measurements", machine, "--setups", setups, "--set", "B=0", "-o", str(tmp_path / "o.csv"))
    assert "outside its limits" not in proc.stderr


# ----------------------------------------------------------------------------- a model outside its domain

# m4 with a tool length that needs X above -400 mm (sqrt): finite within X's limits, as the loader
# checks, but not at a set-up written beyond them


def test_simulate_measurements_refuses_set_ups_where_the_model_is_not_finite(tmp_path):
    """Before: exit 0 and a row 'nan,nan,nan' in the CSV, which identify then refused."""
    machine = write_file(tmp_path, "m.yaml", M4_SQRT)
    setups = write_file(tmp_path, "s.csv", "X,Y,Z,B\n0,0,0,0\n-500,0,0,0\n")
    out = tmp_path / "o.csv"
    _refused_any = cli("simulate-measurements", machine, "--setups", setups, "-o", str(out), check=False)
    assert _refused_any.returncode == 2
    assert ("error: set-up 2 (X = -500 mm, Y = 0 mm, Z = 0 mm, B = 0 deg) gives a tool point that is not finite "
            "(1 of 2 set-ups): the machine's expressions leave their domain there") in _refused_any.stderr
    assert not out.exists()
