"""Every figure, checked as built and before it is saved: titled with the machine, the params,
the model and the axes held (with their values); every axis labelled with one unit in
brackets; every colour bar labelled; a warning on stderr when there is nothing to draw.

The expectations come from the machine files themselves (read here with yaml, not through
chaincomp): the machine's name, its axes, their units and where an axis not drawn stands
(0, or the middle of its limits when 0 is outside them)."""

from __future__ import annotations

import argparse
import glob
import os
import re

import matplotlib
import numpy as np
import pytest
import yaml

matplotlib.use("Agg")
from matplotlib.figure import Figure  # noqa: E402

from helpers import BUNDLED as MACHINES, PARAMS, ROOT, machine_path, run_cli  # noqa: E402

UNIT = re.compile(r"^[^\[\]]+ \[([^\[\]]+)\]$")   # 'quantity [unit]': exactly one unit


def _params(name):
    found = sorted(glob.glob(os.path.join(PARAMS, f"{name}-*.yaml")))
    return found[0] if found else None


def _doc(name):
    with open(machine_path(name)) as f:
        return yaml.safe_load(f)


def _axes(name):
    """[(name, unit, default position)] of a machine's axes, from its file."""
    out = []
    for s in _doc(name)["symbols"]:
        if s["role"] == "axis":
            lo, hi = s["limits"]
            out.append((s["name"], s["unit"], 0.0 if lo <= 0 <= hi else (lo + hi) / 2))
    return out


def _parser():
    """plot's and budget's own parsers (not chaincomp's main: only the verbs under test)."""
    from chaincomp.cli import budget, plot
    p = argparse.ArgumentParser()
    sub = p.add_subparsers()
    plot.add_parser(sub)
    budget.add_parser(sub)
    return p


@pytest.fixture
def figures(monkeypatch):
    """Run a verb in-process; the figures it would save, unsaved."""
    from chaincomp.cli import figures as F
    caught = []
    monkeypatch.setattr(Figure, "savefig", lambda fig, *a, **k: caught.append(fig))
    monkeypatch.setattr(F, "write_file", lambda path, data: None)   # F.save's write: no empty files left

    def run(*argv):
        caught.clear()
        args = _parser().parse_args([str(a) for a in argv])
        assert args.run(args) == 0
        assert caught, "nothing drawn"
        return caught[-1]
    return run


def _all_text(fig) -> str:
    parts = [fig._suptitle.get_text() if fig._suptitle else ""]
    parts += [ax.get_title() for ax in fig.axes]
    return "\n".join(parts)


def _check_labels(fig):
    """Every axis and colour bar labelled with one unit in brackets (a categorical axis with a
    name); legends carry no second unit."""
    from matplotlib.category import StrCategoryConverter
    checked = 0
    for ax in fig.axes:
        if ax.get_label() == "<colorbar>":
            text = ax.get_ylabel() or ax.get_xlabel()
            assert UNIT.match(text), f"colour bar label {text!r}"
            checked += 1
            continue
        axis_list = [("x", ax.xaxis), ("y", ax.yaxis)] + ([("z", ax.zaxis)] if hasattr(ax, "zaxis") else [])
        for which, axis in axis_list:
            text = axis.get_label().get_text()
            if which == "x" and not text and any(UNIT.match(o.get_xlabel())
                                                 for o in ax.get_shared_x_axes().get_siblings(ax) if o is not ax):
                continue   # panels stacked on one time axis: the bottom one names it
            if isinstance(axis.get_converter(), StrCategoryConverter):
                assert text, f"categorical {which} axis without a name"
                continue
            assert UNIT.match(text), f"{which} label {text!r} of {ax.get_title()!r}"
            checked += 1
        legend = ax.get_legend()
        for t in legend.get_texts() if legend else ():
            assert "[" not in t.get_text(), f"a unit in the legend: {t.get_text()!r}"
    return checked


def _held(name, drawn, sets=()):
    """'A = 0 deg' for each axis not drawn, at its default or --set value, as the file says."""
    given = dict(s.split("=") for s in sets)
    return [f"{a} = {float(given.get(a, d)):g} {u}" for a, u, d in _axes(name) if a not in drawn]


def _check_title(fig, name, drawn, params=None, model="first-order", sets=()):
    text = _all_text(fig)
    assert _doc(name)["name"] in text.splitlines()[0], text
    if params:
        assert os.path.basename(params) in text, text
    else:
        assert "no --params" in text
    if model:
        assert f"{model} model" in text, text
    for h in _held(name, drawn, sets):
        assert h in text, (h, text)


@pytest.mark.parametrize("name", MACHINES)
@pytest.mark.parametrize("view", ["map", "surface"])
def test_map_and_surface_on_every_machine(figures, name, view):
    params = _params(name)
    axes = _axes(name)
    fig = figures("plot", machine_path(name), *(["--params", params] if params else []), "--view", view,
                  "--grid", "5", "--component", "norm")
    _check_title(fig, name, [a for a, _, _ in axes[:2]], params)
    assert _check_labels(fig) == (6 if view == "surface" else 3)   # x, y, colour bar (+ x, y, z)
    # the map's colour bar: the component in µm (a length) here
    assert any(ax.get_ylabel() == "|tool point error| [µm]" for ax in fig.axes)


@pytest.mark.parametrize("name", MACHINES)
def test_volume_on_every_machine(figures, name):
    params = _params(name)
    axes = _axes(name)
    linear = [a for a, u, _ in axes if u == "mm"]
    fig = figures("plot", machine_path(name), *(["--params", params] if params else []), "--view", "volume",
                  "--grid", "3", "--order", "exact")
    _check_title(fig, name, (linear or [a for a, _, _ in axes])[:3], params, model="exact")
    assert _check_labels(fig) == 4                                  # x, y, z, colour bar
    ax = fig.axes[0]
    length = _doc(name).get("length_unit", "mm")
    assert [ax.get_xlabel(), ax.get_ylabel(), ax.get_zlabel()] == [f"tool point {c} [{length}]" for c in "xyz"]
    assert any(t.get_text().startswith("key: ") and t.get_text().strip().endswith(" µm") for t in ax.texts)


def test_a_held_axis_set_elsewhere_and_a_difference_of_models_are_in_the_title(figures):
    sets = ("Ap=30", "Cp=-45")
    fig = figures("plot", machine_path("five_axis_ac"), "--params", _params("five_axis_ac"), "--over", "X,Y",
                  "--set", sets[0], "--set", sets[1], "--grid", "3", "--order", "exact-2", "--component", "dkx")
    _check_title(fig, "five_axis_ac", ["X", "Y"], _params("five_axis_ac"), model="exact minus second-order",
                 sets=sets)
    assert "Z = 0 mm" in _all_text(fig) and "Ap = 30 deg" in _all_text(fig)
    assert any(ax.get_ylabel() == "dkx (tool axis tilt towards x) [arcsec]" for ax in fig.axes)
    _check_labels(fig)


def test_internal_units_on_request(figures):
    fig = figures("plot", machine_path("angle_head"), "--params", _params("angle_head"), "--grid", "3",
                  "--units", "internal")
    assert any(ax.get_ylabel() == "dy [mm]" for ax in fig.axes)


def test_volume_arrows_of_a_pure_positioning_error(figures):
    """vmc_xyz with EXX = 4.6 um alone: every arrow is (4.6, 0, 0) um; the longest arrow is
    drawn at 15 % of the tool point's travel (800 mm in x), the key is 2 um (1-2-5 below 4.6)."""
    from chaincomp.cli import plot
    args = _parser().parse_args(["plot", machine_path("vmc_xyz"), "--set", "EXX=4.6", "--view", "volume",
                                 "--grid", "3"])
    plot._normalise(args)
    d = plot.volume_data(args, args.over, args.grid)
    assert d.error.shape == (27, 3)
    assert np.allclose(d.error, [4.6, 0.0, 0.0], rtol=0, atol=1e-9)
    assert d.unit == "µm" and d.key == 2.0
    assert d.scale * 4.6 == pytest.approx(0.15 * 800.0)
    assert sorted(set(np.round(d.point[:, 0], 9))) == [-400.0, 0.0, 400.0]


@pytest.mark.parametrize("name", [n for n in MACHINES if os.path.exists(os.path.join(ROOT, "configs",
                                                                                     "tolerances", f"{n}.yaml"))])
@pytest.mark.slow
def test_budget_plot_on_every_machine_with_tolerances(figures, name, tmp_path):
    tol = os.path.join(ROOT, "configs", "tolerances", f"{name}.yaml")
    axes = _axes(name)
    over = [a for a, _, _ in axes[:2]]
    fig = figures("budget", machine_path(name), "--tolerances", tol, "--over", ",".join(over), "--grid", "3",
                  "--samples", "0", "--plot", tmp_path / "b.png")
    _check_title(fig, name, over, None)
    assert os.path.basename(tol) in _all_text(fig)
    assert _check_labels(fig) == 7   # two maps (x, y, colour bar) and the bars' x; the bars' y is categorical


def test_budget_maps_have_their_own_colour_scales(figures, tmp_path):
    fig = figures("budget", machine_path("five_axis_ac"), "--tolerances",
                  os.path.join(ROOT, "configs", "tolerances", "five_axis_ac.yaml"), "--over", "X,Ap", "--grid", "5",
                  "--samples", "0", "--plot", tmp_path / "b.png")
    meshes = [c for ax in fig.axes if ax.get_label() != "<colorbar>" for c in ax.collections
              if hasattr(c, "get_clim") and c.get_array() is not None]
    assert len(meshes) == 2
    (w0, w1), (r0, r1) = (m.get_clim() for m in meshes)
    worst, rss = (np.asarray(m.get_array()) for m in meshes)
    assert (w0, w1) == pytest.approx((worst.min(), worst.max())) and (r0, r1) == pytest.approx((rss.min(), rss.max()))
    assert r1 < w0 or r1 < 0.8 * w1   # RSS below the worst case: one scale would have flattened it


@pytest.mark.slow
def test_table_plot(figures):
    params = os.path.join(PARAMS, "five_axis_ac-laser.yaml")
    fig = figures("plot", "--table", params, "--error", "EXX", machine_path("five_axis_ac"))
    _check_title(fig, "five_axis_ac", [a for a, _, _ in _axes("five_axis_ac")], params, model=None)
    assert _check_labels(fig) == 3   # two y labels, the shared x once
    assert [ax.get_ylabel() for ax in fig.axes] == ["EXX [um]", "slope [um/mm]"]


@pytest.fixture(scope="module")
def replay_csv(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("replay")
    log, table = tmp / "axes.lcmlog", tmp / "replay.csv"
    five = machine_path("five_axis_ac")
    run_cli("simulate-log", five, "-o", str(log), "--seconds", "0.3")
    run_cli("replay", five, str(log), "--params", _params("five_axis_ac"), "--csv", str(table))
    return str(table)


@pytest.mark.slow
def test_replay_plot_one_unit_per_panel_and_the_error_with_and_without(figures, replay_csv):
    params = _params("five_axis_ac")
    fig = figures("plot", machine_path("five_axis_ac"), "--params", params, "--replay", replay_csv)
    _check_title(fig, "five_axis_ac", [a for a, _, _ in _axes("five_axis_ac")], params, model="exact")
    assert _check_labels(fig) == 6 + 1   # six panels' y labels, time on the last
    ylabels = [ax.get_ylabel() for ax in fig.axes]
    assert ylabels == ["commanded [mm]", "commanded [deg]", "correction [µm]", "correction [arcsec]",
                       "|tool point error| [µm]", "tool axis error [arcsec]"]
    panel = fig.axes[4]
    labels = [line.get_label() for line in panel.get_lines()]
    assert labels[0] == "without compensation" and labels[1].startswith("with compensation")
    without, with_ = (line.get_ydata() for line in panel.get_lines())
    # with compensation: Python's exact model at the corrected axes, which must agree with the
    # compiled compensator's own residual in the CSV (1 pm), ramp included
    import csv
    with open(replay_csv, newline="") as f:
        residual = np.array([float(r["residual_point_mm"]) for r in csv.DictReader(f)]) * 1000.0
    assert np.allclose(with_, residual, rtol=0, atol=1e-6)
    # the ramp starts from next to no correction; afterwards the compensated error is far below
    assert without[0] == pytest.approx(with_[0], rel=0.05)
    assert np.max(with_[len(with_) // 2:]) < 1e-3 * np.min(without)


@pytest.mark.slow
def test_replay_plot_of_a_three_axis_machine_leaves_the_tilt(figures, tmp_path):
    """vmc_xyz's slides cannot turn the tool axis: its tilt is the same with and without
    compensation, while the tool point error drops."""
    log, table = tmp_path / "axes.lcmlog", tmp_path / "replay.csv"
    vmc, params = machine_path("vmc_xyz"), _params("vmc_xyz")
    run_cli("simulate-log", vmc, "-o", str(log), "--seconds", "0.1")
    run_cli("replay", vmc, str(log), "--params", params, "--csv", str(table))
    fig = figures("plot", vmc, "--params", params, "--replay", table)
    assert [ax.get_ylabel() for ax in fig.axes] == ["commanded [mm]", "correction [µm]", "|tool point error| [µm]",
                                                    "tool axis error [arcsec]"]
    (p_without, p_with), (d_without, d_with) = ([line.get_ydata() for line in ax.get_lines()] for ax in fig.axes[2:])
    assert np.allclose(d_with, d_without, rtol=1e-9) and d_with.min() > 1.0
    assert p_with[-1] < 1e-3 * p_without[-1]


def test_replay_title_names_the_params_the_compensation_used(figures, replay_csv, capsys):
    """The CSV does not name its params; its residual column is the compensator's. With the params
    replay was given the title names them; with other values (ThetaCh 150 -> 10 arcsec: tens of
    µm at these poses) it says they were not those, by how much, and warns."""
    params = _params("five_axis_ac")
    first = figures("plot", machine_path("five_axis_ac"), "--params", params, "--replay", replay_csv)
    assert f"compensated with params {os.path.basename(params)}" in first._suptitle.get_text().split("\n")[0]
    other = figures("plot", machine_path("five_axis_ac"), "--params", params, "--set", "ThetaCh=10",
                    "--replay", replay_csv)
    title = other._suptitle.get_text().replace("\n", " ")
    assert f"compensated with values other than params {os.path.basename(params)}, --set ThetaCh=10" in title
    assert "the replay compensated with other values" in capsys.readouterr().err


def test_replay_plot_without_a_machine_warns(figures, replay_csv, capsys):
    figures("plot", "--replay", replay_csv)
    assert "without compensation needs MACHINE.yaml and --params" in capsys.readouterr().err


def test_nothing_to_draw_is_a_warning(figures, capsys):
    figures("plot", machine_path("five_axis_ac"), "--grid", "3")
    assert "no error values" in capsys.readouterr().err
    # an error that moves x only: a map of dz has nothing to draw
    figures("plot", machine_path("vmc_xyz"), "--set", "EXX=5", "--component", "dz", "--grid", "3")
    assert "dz is zero everywhere on this grid" in capsys.readouterr().err
    figures("plot", machine_path("vmc_xyz"), "--set", "EXX=5", "--component", "dx", "--grid", "3")
    assert "warning" not in capsys.readouterr().err


@pytest.mark.slow
def test_plot_option_mistakes_exit_2(tmp_path):
    m = machine_path("five_axis_ac")
    for argv, word in ((["--view", "volume", "--grid", "13"], "volume view takes 2 to 12"),
                       (["--view", "volume", "--over", "X,Y,Z,Ap"], "one to three different axes"),
                       (["--style", "heatmap", "--view", "surface"], "disagree"),
                       (["--html", str(tmp_path / "x.png")], "must end in .html"),
                       (["--html", str(tmp_path / "x.html"), "--replay", "r.csv"], "not with --replay")):
        proc = run_cli("plot", m, *argv, check=False)
        assert proc.returncode == 2 and word in proc.stderr and "Traceback" not in proc.stderr, (argv, proc.stderr)
