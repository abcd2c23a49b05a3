"""budget with tables in --params (their largest |value| on the grid as the bound, or the
tolerance file's), and components that no error moves shown as zero, not as a failure.

Truth: vmc_xyz's EXX is X's positioning error, which moves the tool by exactly +-EXX in x and
not at all in y, z or the direction; so with EXX alone, worst dx = |EXX's bound| everywhere and
every other component is identically zero. The tables are piecewise linear, so their largest
|value| is at a knot, computed here by hand."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest
from helpers import ROOT as HELPERS_ROOT

ROOT = Path(HELPERS_ROOT)
VMC = str(ROOT / "configs/machines/vmc_xyz.yaml")

TABLE = """machine: vmc_xyz
values:
  EXX:
    axis: X
    units: [mm, um]
    interpolation: linear
    outside: {outside}
    table:
      - [{lo}, 0.0]
      - [0, 8.0]
      - [400, -3.0]
"""


def budget(tmp_path, *args, table_lo=-400, outside="hold", check=True):
    params = tmp_path / "p.yaml"
    params.write_text(TABLE.format(lo=table_lo, outside=outside))
    proc = subprocess.run([sys.executable, "-m", "chaincomp.cli.main", "budget", VMC, "--params", str(params),
                           "--samples", "2000", *args], capture_output=True, text=True, cwd=ROOT, timeout=300)
    if check:
        assert proc.returncode == 0, proc.stderr
    return proc


@pytest.mark.slow
def test_a_table_is_bounded_by_its_largest_value_over_the_grid(tmp_path):
    # grid 2: X at -400 and 400 only (0 and 3 um there), yet the table peaks at 8 um at X = 0
    out = json.loads(budget(tmp_path, "--grid", "2", "--format", "json").stdout)
    assert out["tables"] == {"EXX": pytest.approx(8.0)}
    dx = out["components"]["dx"]
    assert dx["worst"]["max"] == pytest.approx(8e-3) and dx["worst"]["min"] == pytest.approx(8e-3)
    assert dx["systematic"] == {"min": 0.0, "max": 0.0}   # a table has no one systematic value
    assert not dx["identically_zero"] and dx["at_worst"]["monte_carlo"]["bracketed"] is True
    for comp in ("dy", "dz", "dkx", "dky", "dkz"):
        c = out["components"][comp]
        assert c["identically_zero"] and c["worst"]["max"] == 0.0, comp
        assert c["at_worst"]["monte_carlo"]["bracketed"] is None, comp


@pytest.mark.slow
def test_a_table_on_a_held_axis_is_bounded_by_its_value_there(tmp_path):
    # X = 200 mm: 8 + (200 / 400) * (-3 - 8) = 2.5 um
    out = json.loads(budget(tmp_path, "--over", "Y,Z", "--set", "X=200", "--grid", "3", "--format", "json").stdout)
    assert out["tables"]["EXX"] == pytest.approx(2.5)
    assert out["components"]["dx"]["worst"]["max"] == pytest.approx(2.5e-3)


@pytest.mark.slow
def test_the_tolerance_files_bound_wins_over_the_tables_range(tmp_path):
    tol = tmp_path / "t.yaml"
    tol.write_text("machine: vmc_xyz\nnormal_bound: 3 sigma\ntolerances:\n  EXX: {bound: 2 um, distribution: uniform}\n")
    out = json.loads(budget(tmp_path, "--tolerances", str(tol), "--grid", "2", "--format", "json").stdout)
    assert out["components"]["dx"]["worst"]["max"] == pytest.approx(2e-3)


@pytest.mark.slow
def test_a_rejecting_table_shorter_than_the_grid_is_refused_with_its_line(tmp_path):
    proc = budget(tmp_path, "--grid", "2", table_lo=-100, outside="reject", check=False)
    assert proc.returncode == 2 and "Traceback" not in proc.stderr and proc.stderr.count("\n") == 1
    assert "p.yaml:3: values.EXX: X = -400 mm lies outside the table [-100, 400] mm" in proc.stderr


@pytest.mark.slow
def test_text_shows_zero_components_as_zero_not_as_a_failure(tmp_path):
    text = budget(tmp_path, "--grid", "2").stdout
    assert "EXX 8 um" in text
    rows = [line.split() for line in text.splitlines() if line.startswith("  d")]
    mc = {r[0]: r for r in rows if len(r) > 5 and "±" in r}
    assert mc["dx"][6] == "yes"   # comp, rss, q, ±, se, worst, bracketed
    for comp in ("dy", "dz", "dkx", "dky", "dkz"):
        assert mc[comp][6] == "zero", mc[comp]
    assert " NO " not in text
    assert "identically zero: no error moves dkz" in text
