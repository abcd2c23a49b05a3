"""chaincomp budget on a long chain: the gains come from the numeric jets through the chain
(budget._Jets), not from the expanded series, which take minutes there. On the benchmark UR5
(tools/bench_machines/ur5.yaml) the figures equal those of central differences of the exact
model; on a short chain the jets give the expanded series' figures (an independent
derivation) at order 1 and 2, centred on nonzero errors."""

import os

import numpy as np
import pytest

from helpers import ROOT, machine_path
from test_budget import FIVE_TOL, fd_gains, grid_values, read_tolerances, reference_figures

from chaincomp.analysis import budget as B
from chaincomp.symbolic.derive import derive
from chaincomp.model.machine import load_machine
from chaincomp.analysis.tolerances import load_tolerances

UR5 = os.path.join(ROOT, "tools", "bench_machines", "ur5.yaml")
UR5_TOL = """machine: ur5
tolerances:
  dth1: {bound: 10 arcsec, distribution: uniform}
  dth3: {bound: 10 arcsec, distribution: normal}
  dd1: {bound: 20 um, distribution: uniform}
  da2: {bound: 20 um, distribution: normal}
  dal2: {bound: 15 arcsec, distribution: uniform}
  dal5: {bound: 15 arcsec, distribution: uniform}
  dd6: {bound: 5 um, distribution: uniform}
"""


def test_a_long_chain_takes_the_jets_a_short_one_the_series():
    assert isinstance(B.gain_model(load_machine(UR5), "2"), B._Jets)
    assert isinstance(B.gain_model(load_machine(machine_path("five_axis_ac")), "2"), B._Series)


def test_ur5_worst_rss_sigma_equal_central_differences_of_the_exact_model(tmp_path):
    path = tmp_path / "ur5_tol.yaml"
    path.write_text(UR5_TOL)
    machine = load_machine(UR5)
    over, points, fixed = ("q1", "q2", "q3", "q5"), 3, {"q4": 30.0, "q6": -50.0}
    tol, k = read_tolerances(str(path))
    gains = fd_gains(machine, grid_values(machine, over, points, fixed))
    ref = reference_figures(gains, tol, machine, k)
    values = machine.nominal_values()
    for a in machine.axes:
        values[a.name] = a.to_internal(fixed.get(a.name, 0.0))
    grid = B.make_grid(machine, list(over), points, values)
    b = B.compute(machine, values, load_tolerances(str(path), machine), grid, "1", samples=0)
    for c, (worst, rss, sigma) in ref.items():
        cb = b.components[c]
        scale = max(np.max(worst), 1e-6)   # a component no error moves: rounding of the jets, 1e-20
        np.testing.assert_allclose(cb.worst, worst, rtol=1e-6, atol=1e-9 * scale, err_msg=c)
        np.testing.assert_allclose(cb.rss, rss, rtol=1e-6, atol=1e-9 * scale, err_msg=c)
        np.testing.assert_allclose(cb.sigma, sigma, rtol=1e-6, atol=1e-9 * scale, err_msg=c)


@pytest.mark.slow
@pytest.mark.parametrize("order", [1, 2])
def test_jets_give_the_expanded_series_figures(order):
    machine = load_machine(machine_path("five_axis_ac"))
    tolerances = load_tolerances(FIVE_TOL, machine)
    values = machine.nominal_values()
    rng = np.random.default_rng(7)
    for s in machine.errors:   # the deviations are about these (systematic, and order 2's gradient)
        values[s.name] = 1e-3 * rng.normal() if s.unit.kind == "length" else 2e-5 * rng.normal()
    grid = B.make_grid(machine, ["X", "Ap", "Cp"], 4, values)
    series = B._Series(machine, order, derive(machine, order))
    want = B.compute(machine, values, tolerances, grid, str(order), samples=0, gains=series)
    got = B.compute(machine, values, tolerances, grid, str(order), samples=0, gains=B._Jets(machine, order))
    for c, w in want.components.items():
        g = got.components[c]
        for field in ("systematic", "worst", "rss", "sigma", "second_order_bound", "max_gain", "gains_at_worst"):
            a, b = getattr(g, field), getattr(w, field)
            np.testing.assert_allclose(a, b, rtol=1e-10, atol=1e-13 * max(1.0, np.abs(b).max()), err_msg=(c, field))
        assert g.worst_index == w.worst_index
