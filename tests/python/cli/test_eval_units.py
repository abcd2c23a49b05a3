"""eval prints errors in µm and arcsec (--units internal: mm and rad); JSON stays internal.

Truth from the machine's meaning, not from eval: on vmc_xyz, EXX is X's positioning error and
moves the tool by exactly EXX in x; EBZ turns the head about y, tilting the tool axis (along z)
by EBZ towards x, and moving the tool point by -L sin(EBZ) in x (L = 100 mm from the pivot)."""

import json
import math

import pytest

from helpers import machine_path, run_cli

VMC = machine_path("vmc_xyz")


def _lines(*args):
    return run_cli("eval", VMC, *args).stdout.splitlines()


@pytest.mark.slow
def test_a_positioning_error_reads_in_um():
    lines = _lines("--set", "EXX=4.6")
    i = lines.index("  tool point error (µm): dx, dy, dz")
    assert lines[i + 1].split() == ["first", "[", "4.600,", "0.000,", "0.000]"]
    lines = _lines("--set", "EXX=4.6", "--units", "internal")
    i = lines.index("  tool point error (mm): dx, dy, dz")
    assert lines[i + 3].split() == ["exact", "[", "0.004600000,", "0.000000000,", "0.000000000]"]


def test_a_tilt_reads_in_arcsec_as_components_and_angle():
    lines = _lines("--set", "EBZ=10")
    i = lines.index("  tool direction error (arcsec): tilt towards x, y, z; angle between actual and nominal axis")
    for row in lines[i + 1:i + 4]:
        assert row.split()[1:] == ["[", "10.000,", "0.000,", "0.000]", "angle", "10.000"], row
    dx = -100.0 * math.sin(math.radians(10 / 3600)) * 1000   # µm
    exact = lines[lines.index("  tool point error (µm): dx, dy, dz") + 3].split()
    assert exact[2] == f"{dx:.3f}," and dx < -4.8


@pytest.mark.slow
def test_json_stays_internal_and_names_its_units():
    out = json.loads(run_cli("eval", VMC, "--set", "EXX=4.6", "--set", "EBZ=10", "--json").stdout)
    assert out["units"] == {"length": "mm", "direction": "1", "angle": "rad"}
    theta = math.radians(10 / 3600)
    assert abs(out["error"]["exact"][0] - (0.0046 - 100.0 * math.sin(theta))) < 1e-12
    assert abs(out["direction_angle"]["exact"] - theta) < 1e-15
    # --units changes the text only
    same = json.loads(run_cli("eval", VMC, "--set", "EXX=4.6", "--set", "EBZ=10", "--json",
                              "--units", "internal").stdout)
    assert same == out
