"""The fitting core (chaincomp.measure.lsq) against truth from outside it: the textbook formulas
of the straight-line fit, the normal equations solved here, noise-free curves with a known
solution, Rosenbrock's valley (Moré, Garbow & Hillstrom 1981), chi-square tables, and
rank-deficient Jacobians built here with a known null space."""

import math

import numpy as np
import pytest
from hypothesis import given, settings, strategies as st

from chaincomp.measure import lsq


def test_straight_line_matches_the_textbook_formulas():
    # y = a + b x: b = Sxy / Sxx, a = ybar - b xbar, s^2 = rss / (n - 2),
    # var b = s^2 / Sxx, var a = s^2 (1/n + xbar^2 / Sxx), cov(a, b) = -xbar s^2 / Sxx
    x = np.array([0.0, 1.0, 2.0, 3.0, 4.0, 5.0, 6.0])
    y = np.array([1.1, 2.9, 5.2, 7.1, 8.8, 11.2, 12.9])
    n = len(x)
    sxx = ((x - x.mean()) ** 2).sum()
    b = ((x - x.mean()) * (y - y.mean())).sum() / sxx
    a = y.mean() - b * x.mean()
    s2 = ((y - a - b * x) ** 2).sum() / (n - 2)
    f = lsq.linear_fit(np.column_stack([np.ones(n), x]), y)
    assert f.estimates == pytest.approx([a, b], rel=1e-12)
    assert f.dof == n - 2
    assert f.variance == pytest.approx(s2, rel=1e-12)
    assert f.covariance[1, 1] == pytest.approx(s2 / sxx, rel=1e-10)
    assert f.covariance[0, 0] == pytest.approx(s2 * (1 / n + x.mean() ** 2 / sxx), rel=1e-10)
    assert f.covariance[0, 1] == pytest.approx(-x.mean() * s2 / sxx, rel=1e-10)
    assert f.residual == pytest.approx(y - a - b * x, abs=1e-12)


@settings(derandomize=True, max_examples=30, deadline=None)
@given(st.integers(2, 6), st.integers(0, 20), st.integers(0, 2 ** 31 - 1))
def test_linear_fit_solves_the_normal_equations(n, extra, seed):
    rng = np.random.default_rng(seed)
    m = n + 1 + extra
    j = rng.standard_normal((m, n)) * 10.0 ** rng.uniform(-3, 3, n)   # columns of very different scales
    y = rng.standard_normal(m)
    f = lsq.linear_fit(j, y)
    x = np.linalg.solve(j.T @ j, j.T @ y)
    assert np.allclose(f.estimates, x, rtol=1e-6, atol=1e-9 * np.abs(x).max())
    r = y - j @ x
    s2 = (r @ r) / (m - n)
    assert f.variance == pytest.approx(s2, rel=1e-6)
    cov = s2 * np.linalg.solve(j.T @ j, np.eye(n))
    assert np.allclose(f.covariance, cov, rtol=1e-6, atol=1e-12 * np.abs(cov).max())
    inv, s = lsq.svd_inverse(j)
    assert np.allclose(inv, lsq.normal_inverse(j), rtol=1e-6, atol=1e-12 * np.abs(inv).max())
    assert s[0] / s[-1] == pytest.approx(np.linalg.cond(j), rel=1e-9)


def test_gauss_newton_recovers_an_exponential_decay_from_exact_data():
    t = np.linspace(0.0, 5.0, 40)
    amplitude, rate = 3.0, 0.7
    y = amplitude * np.exp(-rate * t)

    def linearise(x):
        e = np.exp(-x[1] * t)
        return y - x[0] * e, np.column_stack([e, -x[0] * t * e])

    x, iterations, converged = lsq.gauss_newton(linearise, np.array([1.0, 0.3]), 50,
                                                lambda step, x, j: np.linalg.norm(step) <= 1e-12 * np.linalg.norm(x))
    assert converged and iterations < 20
    assert x == pytest.approx([amplitude, rate], rel=1e-10)


def test_gauss_newton_stops_at_its_limit_without_convergence():
    calls = []
    x, iterations, converged = lsq.gauss_newton(lambda x: (np.ones(3), np.ones((3, 1))), np.zeros(1), 4,
                                                lambda step, x, j: False, lambda k, r: calls.append(k))
    assert (iterations, converged) == (4, False) and calls == [1, 2, 3, 4]
    assert x == pytest.approx([4.0])    # each step solves 1·s = 1 in least squares


def test_levenberg_marquardt_finds_the_bottom_of_rosenbrocks_valley():
    # r = (10 (x2 - x1^2), 1 - x1): the sum of squares is Rosenbrock's function, least at (1, 1),
    # from the standard start (-1.2, 1) (Moré, Garbow & Hillstrom 1981, problem 1)
    def residual(x):
        return np.array([10 * (x[1] - x[0] ** 2), 1 - x[0]])

    def linearise(x):
        r = residual(x)
        return r, np.array([[-20 * x[0], 10.0], [-1.0, 0.0]]), float(r @ r)

    def cost(x):
        r = residual(x)
        return float(r @ r)

    x, value = lsq.levenberg_marquardt(linearise, cost, lambda x, step: x + step, np.array([-1.2, 1.0]), 200,
                                       rtol=0.0)
    assert x == pytest.approx([1.0, 1.0], abs=1e-6)
    assert value == pytest.approx(cost(x)) and value < 1e-12


def test_levenberg_marquardt_moves_only_downhill():
    # a cost with a narrow curved valley (Rosenbrock's again, steeper): every point it linearises at
    # is one it accepted, so their costs must never rise
    accepted = []

    def residual(x):
        return np.array([100 * (x[1] - x[0] ** 2), 1 - x[0]])

    def linearise(x):
        r = residual(x)
        accepted.append(float(r @ r))
        return r, np.array([[-200 * x[0], 100.0], [-1.0, 0.0]]), float(r @ r)

    x, value = lsq.levenberg_marquardt(linearise, lambda x: float(residual(x) @ residual(x)),
                                       lambda x, step: x + step, np.array([-1.2, 1.0]), 60)
    assert len(accepted) > 5 and all(b <= a for a, b in zip(accepted, accepted[1:]))
    assert value <= accepted[-1]


def _rank_deficient():
    """Five columns: c2 = 2 c0 (the data cannot tell parameters 0 and 2 apart), c4 = 0 (moves
    nothing), c1 and c3 independent of the rest."""
    rng = np.random.default_rng(4)
    a, b, c = rng.standard_normal((3, 30))
    return np.column_stack([a, b, 2 * a, c, np.zeros(30)])


def test_rank_deficient_jacobian_names_the_inseparable_pair():
    j = _rank_deficient()
    g = lsq.scaled_columns(j)
    assert list(g.cols) == [0, 1, 2, 3] and g.rank == 3
    proj = g.null_projector()
    coupled = [int(g.cols[k]) for k in range(len(g.cols)) if proj[k, k] > 1e-12]
    assert coupled == [0, 2]
    # the null direction, unscaled: a change of 1 in parameter 0 with -0.5 in parameter 2 moves nothing
    v = proj[:, 0] * g.scale[g.cols]
    assert v[2] / v[0] == pytest.approx(-0.5, rel=1e-9)
    assert np.linalg.norm(j[:, [0, 2]] @ [1.0, -0.5]) < 1e-12


def test_spanning_set_takes_the_preferred_column_and_carries_the_other():
    j = _rank_deficient()
    g = lsq.scaled_columns(j)
    unit = j[:, g.cols] * g.scale[g.cols]
    by_pivot = [int(g.cols[k]) for k in lsq.spanning(unit, g.rank)]
    assert sorted(by_pivot) in ([0, 1, 3], [1, 2, 3])
    preferred = [int(g.cols[k]) for k in lsq.spanning(unit, g.rank, first=[2])]
    assert preferred[0] == 2 and sorted(preferred) == [1, 2, 3]
    # parameter 0 left out: the fitted ones move the data as it does with 0.5 of parameter 2
    c = lsq.solve(j[:, preferred], j[:, 0])
    assert c == pytest.approx([0.5, 0.0, 0.0], abs=1e-12)
    # in order, without a rank: each column that adds a direction
    assert lsq.spanning(unit, first=range(4)) == [0, 1, 3]


def test_unseen_columns_and_numeric_rank():
    assert list(lsq.seen(np.array([1.0, 1e-13, 0.0, 2e-12]))) == [True, False, False, True]
    assert lsq.numeric_rank(np.array([1.0, 1e-3, 1e-10])) == 2
    assert lsq.numeric_rank(np.zeros(0)) == 0


def test_correlations_of_a_known_covariance():
    cov = np.array([[4.0, 1.9, 0.0], [1.9, 1.0, 0.0], [0.0, 0.0, 0.0]])
    std = np.sqrt(np.diag(cov))
    corr = lsq.correlation_matrix(cov, std)
    assert corr[0, 1] == pytest.approx(0.95) and corr[2, 2] == 0.0
    assert lsq.strong_correlations(cov, std, ["a", "b", "c"], [0, 1, 2]) == [("a", "b", pytest.approx(0.95))]
    assert lsq.strong_correlations(cov, std, ["a", "b", "c"], [0, 1, 2], above=0.96) == []


def test_huber_weights():
    u = np.array([0.0, 1.0, -1.345, 2.69, -13.45])
    assert lsq.huber_weights(u, 1.345) == pytest.approx([1.0, 1.0, 1.0, 0.5, 0.1])


@pytest.mark.parametrize("dof,quantile", [(1, 10.828), (2, 13.816), (10, 29.588), (30, 59.703), (100, 149.449)])
def test_chi2_quantile_matches_the_tables(dof, quantile):
    # the 99.9 % points of the chi-square distribution (NIST/SEMATECH e-Handbook, table 1.3.6.7.4)
    assert lsq.chi2_quantile(0.999, dof) == pytest.approx(quantile, abs=1e-3)


def test_chi2_limit_only_beyond_the_quantile():
    limit = 29.588 / 10
    assert lsq.chi2_limit(2.0, 10) is None
    assert lsq.chi2_limit(3.0, 10) == pytest.approx(limit, abs=1e-4)
    assert lsq.chi2_limit(None, 10) is None and lsq.chi2_limit(5.0, 0) is None


def test_step_derivatives_complex_step_and_central_differences():
    p = np.array([0.3, -1.2])
    steps = np.eye(2)
    d = lsq.step_derivatives(lambda q: np.sin(q[..., 0]) * np.exp(q[..., 1]), p, steps)
    assert d == pytest.approx([math.cos(0.3) * math.exp(-1.2), math.sin(0.3) * math.exp(-1.2)], rel=1e-14)

    def real_only(q):        # numpy has no complex arctan2: the core falls back to central differences
        if np.iscomplexobj(q):
            raise TypeError("no complex arctan2")
        return np.arctan2(q[..., 1], q[..., 0])

    d = lsq.step_derivatives(real_only, p, steps)
    r2 = 0.3 ** 2 + 1.2 ** 2
    assert d == pytest.approx([1.2 / r2, 0.3 / r2], rel=1e-8)
