"""chaincomp plot's bad input: option faults, ranges beyond the limits, an error table in the volume
view, a one-axis machine, and failed image or HTML writes named in one line."""

from __future__ import annotations

import numpy as np
import pytest

from chaincomp.cli.main import main
from helpers import VMC, refused, run_main


@pytest.mark.slow
def test_volume_view_of_an_error_table(tmp_path):
    """An error given as a table crashed the volume view (exit 3: 0.0 times a Table). EXX as a
    straight table 0 -> 4 um over X's travel: the arrows are (EXX(X), 0, 0), read off the table
    here (linear between its three knots)."""
    from chaincomp.cli import plot
    from chaincomp.cli.main import build_parser
    p = tmp_path / "p.yaml"
    p.write_text("machine: vmc_xyz\nvalues:\n  EXX:\n    axis: X\n    units: [mm, um]\n"
                 "    interpolation: linear\n    outside: hold\n"
                 "    table:\n      - [-400, 0]\n      - [0, 2]\n      - [400, 4]\n")
    args = build_parser().parse_args(["plot", VMC, "--params", str(p), "--view", "volume", "--grid", "3"])
    plot._normalise(args)
    d = plot.volume_data(args, args.over, args.grid)
    x = d.point[:, 0]
    assert np.allclose(d.error[:, 0], (x + 400) / 200, rtol=0, atol=1e-9)
    assert np.allclose(d.error[:, 1:], 0, atol=1e-9)
    assert main(["plot", VMC, "--params", str(p), "--view", "volume", "--grid", "3",
                 "-o", str(tmp_path / "v.png"), "--html", str(tmp_path / "v.html")]) == 0


@pytest.mark.parametrize("options,match", [
    # '' was taken as the default (-o '': no file written at all, exit 0)
    (["--view", "volume", "--over", ""], "--over: an empty value"),
    (["-o", ""], "-o: an empty value"),
    (["--html", ""], "--html: an empty value"),
    # 1e308 reached the model (a 'not finite' error naming no option); the bound of every value
    (["--view", "volume", "--range", "-1e308:1e308"], "--range: values are at most 1e+15 in magnitude"),
    (["--range2", "0:1e16"], "--range2: values are at most 1e+15 in magnitude"),
])
def test_plot_option_faults(capsys, tmp_path, monkeypatch, options, match):
    monkeypatch.chdir(tmp_path)
    refused(capsys, "plot", VMC, "--set", "EXX=1", "--grid", "3", *options, match=match)
    assert not list(tmp_path.iterdir())


def test_plot_range_beyond_the_limits_warns(capsys, tmp_path):
    """vmc_xyz's X travels -400..400 mm: a map out to -500 shows where the machine cannot go."""
    code, _, err = run_main(capsys, "plot", VMC, "--set", "EXX=1", "--grid", "3", "--over", "X,Y", "--range", "-500:100",
                     "--range2", "-10:10", "-o", tmp_path / "m.png")
    assert code == 0 and (tmp_path / "m.png").exists()
    assert "warning: --range -500:100: beyond the limits of X [-400, 400] mm" in err
    assert "--range2" not in err


@pytest.mark.parametrize("argv", [
    ["plot", VMC, "--set", "EXX=1", "--component", "dx", "--grid", "3", "-o", "/dev/full"],
    ["plot", VMC, "--set", "EXX=1", "--grid", "3", "--view", "volume", "-o", "/dev/full"],
    ["ballbar", VMC, "--set", "EXX=1", "--plane", "XY", "--radius", "10", "--plot", "/dev/full"],
])
def test_a_failed_image_write_is_an_error_naming_the_file(capsys, argv):
    """A full disk (/dev/full: ENOSPC on every write) was an internal error (exit 3), or an image
    silently cut short; refused before the work where the folder is not writable."""
    err = refused(capsys, *argv, match="/dev/full")
    assert err.count("\n") == 1


def test_a_failed_html_write_is_an_error_naming_the_file(capsys):
    """--html where no file can be made (/proc takes none, even from root): exit 2 naming the file,
    not exit 3."""
    err = refused(capsys, "plot", VMC, "--set", "EXX=1", "--component", "dx", "--grid", "3",
                   "--html", "/proc/chaincomp-test.html", match="/proc/chaincomp-test.html")
    assert err.count("\n") == 1


def test_plot_of_a_one_axis_machine(capsys, tmp_path):
    """A map needs two axes: '--over expects two different axes ..., got None' before."""
    m = tmp_path / "one.yaml"
    m.write_text("name: one_axis\nlength_unit: mm\nsymbols:\n  - {name: X, role: axis, unit: mm, limits: [-300, 300]}\n"
                 "  - {name: EXX, role: error, unit: um}\nchain:\n  - {translate: [X + EXX, 0, 0]}\n"
                 "tool: {point: [0, 0, 0]}\n")
    for view in (["-o", tmp_path / "m.png"], ["--view", "surface", "-o", tmp_path / "m.png"],
                 ["--html", tmp_path / "m.html"]):
        refused(capsys, "plot", m, "--set", "EXX=1", *view,
                 match="one_axis has one axis (X): a map, a surface and --html draw over two")
    code, _, err = run_main(capsys, "plot", m, "--set", "EXX=1", "--view", "volume", "-o", tmp_path / "v.png")
    assert code == 0, err
