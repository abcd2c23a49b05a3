"""The second bad-input hunt over this session's new verbs (ballbar, plot --view volume/--html,
eval --units, display): each case a fault found by hand, with the message and exit code the
contract asks for written here (exit 2 and one line naming file, line and field; never exit 3,
never a silent wrong value)."""

from __future__ import annotations

import numpy as np
import pytest

from chaincomp import display
from chaincomp.cli.main import main
from conftest import machine_path

VMC = machine_path("vmc_xyz")


def _run(capsys, *argv) -> tuple[int, str]:
    capsys.readouterr()
    code = main([str(a) for a in argv])
    return code, capsys.readouterr().err


def _refused(capsys, *argv, match: str) -> str:
    code, err = _run(capsys, *argv)
    assert code == 2, err
    assert match in err, err
    assert "Traceback" not in err and "internal error" not in err
    return err


# ----------------------------------------------------------------------------- plot

def test_volume_view_of_an_error_table(tmp_path):
    """An error given as a table crashed the volume view (exit 3: 0.0 times a Table). EXX as a
    straight table 0 -> 4 um over X's travel: the arrows are (EXX(X), 0, 0), read off the table
    here (linear between its three knots)."""
    from chaincomp.cli import plot
    from chaincomp.cli.main import build_parser
    p = tmp_path / "p.yaml"
    p.write_text("machine: vmc_xyz\nvalues:\n  EXX:\n    axis: X\n    units: [mm, um]\n"
                 "    interpolation: linear\n    outside: hold\n    table:\n      - [-400, 0]\n      - [0, 2]\n      - [400, 4]\n")
    args = build_parser().parse_args(["plot", VMC, "--params", str(p), "--view", "volume", "--grid", "3"])
    plot._normalise(args)
    d = plot.volume_data(args, args.over, args.grid)
    x = d.point[:, 0]
    assert np.allclose(d.error[:, 0], (x + 400) / 200, rtol=0, atol=1e-9)
    assert np.allclose(d.error[:, 1:], 0, atol=1e-9)
    assert main(["plot", VMC, "--params", str(p), "--view", "volume", "--grid", "3",
                 "-o", str(tmp_path / "v.png"), "--html", str(tmp_path / "v.html")]) == 0


# ----------------------------------------------------------------------------- display

@pytest.mark.parametrize("value,u,text", [
    # more digits than decimal's 28-digit context: InvalidOperation (identify's exit 3) before
    (1e300, 1.0, "1e+300 ± 1.0e+00"),
    (5.0, 1e-320, "5.0 ± 1.0e-320"),
    (-3e-7, 1e-25, "-3e-07 ± 1.0e-25"),
    # 17 significant digits still round as always
    (1.2345678901234567, 1e-16, "1.23456789012345670 ± 0.00000000000000010"),
    (0.0, 1e-300, "(0.0 ± 1.0)e-300"),
])
def test_plus_minus_of_an_uncertainty_finer_than_a_double(value, u, text):
    assert display.plus_minus(value, u) == text
