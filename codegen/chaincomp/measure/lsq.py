"""The least-squares core every fit of measure/ shares: identify (and probe fit through it),
thermal fit and the ballbar fit.

What is common to them, and only that, lives here as plain functions on arrays:

- derivatives for a Jacobian (``step_derivatives``: the complex step, central differences
  where the model cannot take complex values);
- the linear least-squares solve (``solve``), for a linear fit, a Gauss-Newton step and the
  combination of fitted columns that carries a left-out one;
- the iterations: Gauss-Newton (``gauss_newton``: each step the linear least-squares solution
  of the linearised problem) and Levenberg-Marquardt with Marquardt's scaling
  (``levenberg_marquardt``: for a cost that is not a plain sum of model residuals, e.g. one with
  the linear parameters solved inside it);
- the rank and gauge analysis of a Jacobian: its numeric rank with the columns scaled to unit
  norm (``scaled_columns``, ``numeric_rank``), a spanning set of columns (``spanning``: the
  parameters to fit, preferred ones first, the rest by pivoting) and the null space's projector
  (which parameters the data cannot tell apart: ``ScaledColumns.null_projector``);
- uncertainties: a linear fit's estimates, residual and covariance (``linear_fit``),
  sigma^2 (J^T J)^-1 with sigma^2 from the residual (``residual_variance``, ``normal_inverse``,
  ``svd_inverse`` when the singular values are wanted too), the correlations among the
  estimates (``correlation_matrix``, ``strong_correlations``);
- weights and the goodness of fit: Huber's IRLS weights (``huber_weights``) and the chi-square
  quantile that says when chi2/dof is too large for the given uncertainties (``chi2_limit``).

The words a report prints about these numbers (which parameters, in which units) belong to
each fit's module; the numbers come from here. Each function does exactly the arithmetic its
callers did before (the fits' outputs are the same to the last digit).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

CSTEP = 1e-20     # complex step, internal units (mm, rad): any tiny value gives the same digits
STEP = 1e-6       # central-difference step, where the model cannot take complex values
RANK_TOL = 1e-9   # singular values below this, relative to the largest, are zero
UNSEEN = 1e-12    # a column shorter than this, relative to the longest, moves nothing
ADDS = 1e-6       # a unit column whose part outside the picked ones is shorter adds no direction
TIE = 1e-9        # pivoting: columns this close (relative) to the largest remaining norm tie

HUBER_K = 1.345     # Huber's k: 95 % efficiency at normal residuals (Huber 1981; Holland & Welsch 1977)
MAD_SCALE = 1.4826  # median |r| of normal residuals times this is their standard deviation
MISFIT_PROBABILITY = 0.999   # chi2/dof beyond this quantile of its distribution: the fit does not fit


# ----------------------------------------------------------------------------- derivatives

def step_derivatives(f, p: np.ndarray, steps: np.ndarray) -> np.ndarray:
    """d/dt f(p + t·s) at t = 0 for each row s of ``steps``: (len(steps), ...) by the complex step
    (f evaluated once at p + i·CSTEP·steps, a row per step: no cancellation, so no digits lost
    to the step's size), or by central differences where f cannot take complex values (numpy
    has no complex arctan2: an error inside atan2)."""
    try:
        return f(p + 1j * CSTEP * steps).imag / CSTEP
    except TypeError:
        both = f(np.vstack([p + STEP * steps, p - STEP * steps]))
        return (both[:len(steps)] - both[len(steps):]) / (2 * STEP)


# ----------------------------------------------------------------------------- the linear solve

def solve(j: np.ndarray, y: np.ndarray) -> np.ndarray:
    """The least-squares solution x of j·x = y (y a vector, or a matrix of right-hand sides); where
    j is rank-deficient the one of least norm (lstsq: SVD-based, no normal equations). With ``j``
    the kept columns of a Jacobian and ``y`` a left-out one: the combination of the kept ones
    that moves the data as it does (to first order), i.e. what carries it."""
    return np.linalg.lstsq(j, y, rcond=None)[0]


# ----------------------------------------------------------------------------- iterations

def gauss_newton(linearise, x: np.ndarray, max_iterations: int, small, progress=None):
    """Gauss-Newton from ``x``: ``linearise(x)`` gives the residual r (data minus model) and the
    model's Jacobian J there; the step is the least-squares solution of J·step = r (``solve``:
    a rank-deficient J takes the minimum-norm step rather than failing). Stops after the first
    step for which ``small(step, x, J)`` holds (x the new point). ``progress(iteration, r)`` is
    called after each step. Returns (x, iterations, converged)."""
    for iteration in range(1, max_iterations + 1):
        r, j = linearise(x)
        step = solve(j, r)
        x = x + step
        if progress is not None:
            progress(iteration, r)
        if small(step, x, j):
            return x, iteration, True
    return x, max_iterations, False


def levenberg_marquardt(linearise, cost, update, x, iterations: int, mu: float = 1e-3,
                        tries: int = 12, rtol: float = 1e-10):
    """Levenberg-Marquardt from ``x`` for a cost that is a sum of squares: ``linearise(x)`` gives
    the residual r, its Jacobian J and the cost at x; ``cost(x)`` the cost alone; ``update(x,
    step)`` the trial point (it may clip or work in logarithms). Each iteration tries steps of
    (JᵀJ + mu·diag(JᵀJ))·step = -Jᵀr (Marquardt's scaling: invariant to the parameters' units),
    raising mu fourfold until the cost drops (at most ``tries`` times; none: stop) and lowering it
    threefold after a success; done when a success lowers the cost by at most ``rtol`` of it.
    Products by einsum, not BLAS: a multithreaded BLAS on a busy machine makes these small
    products 100 times slower. Returns (x, cost at x)."""
    value = None
    for _ in range(iterations):
        r, jac, value = linearise(x)
        g = np.einsum("ij,i->j", jac, r)
        jtj = np.einsum("ij,ik->jk", jac, jac)
        improved = False
        for _ in range(tries):
            step = np.linalg.solve(jtj + mu * np.diag(np.diag(jtj) + 1e-12), -g)
            trial = update(x, step)
            trial_value = cost(trial)
            if trial_value < value:
                x, mu, improved = trial, max(mu / 3, 1e-9), True
                done = value - trial_value <= rtol * value
                value = trial_value
                if done:
                    return x, value
                break
            mu *= 4
        if not improved:
            break
    return x, (cost(x) if value is None else value)


# ----------------------------------------------------------------------------- rank and gauge

def numeric_rank(singular_values: np.ndarray) -> int:
    """How many singular values (largest first) are not zero at RANK_TOL relative to the largest."""
    s = singular_values
    return int((s > RANK_TOL * s[0]).sum()) if len(s) else 0


def seen(norms: np.ndarray) -> np.ndarray:
    """Which columns, by their lengths, move the data at all (longer than UNSEEN of the longest)."""
    return norms > UNSEEN * max(norms.max(initial=0.0), 1e-300)


@dataclass
class ScaledColumns:
    """A Jacobian's columns that move the data, scaled to unit norm (the rank then does not
    depend on the parameters' units), and their SVD: ``scaled = U diag(s) vt``."""
    cols: np.ndarray    # indices of the columns that move the data
    scale: np.ndarray   # per column of the Jacobian: 1 / its length where seen, else 0
    s: np.ndarray       # singular values of the scaled seen columns, largest first
    vt: np.ndarray      # their right singular vectors (rows): vt[rank:] spans the null space
    rank: int

    def null_projector(self) -> np.ndarray:
        """The projector on the null space of the scaled columns (its blocks do not depend on the
        basis chosen for it): a diagonal entry above zero is a parameter the data cannot separate
        from the ones its row couples it to."""
        null = self.vt[self.rank:]
        return null.T @ null


def scaled_columns(j: np.ndarray) -> ScaledColumns:
    """The rank analysis of the Jacobian ``j``: which columns move the data, and the SVD and
    numeric rank of those scaled to unit norm."""
    n = j.shape[1]
    norms = np.linalg.norm(j, axis=0)
    cols = np.flatnonzero(seen(norms))
    d = np.zeros(n)
    d[cols] = 1.0 / norms[cols]
    s, vt = np.zeros(0), np.zeros((0, 0))
    if len(cols):
        scaled = j[:, cols] * d[cols]
        # with fewer data than parameters the reduced vt lacks part of the null space; only then
        # is the full one needed (and small: U is data x data)
        _, s, vt = np.linalg.svd(scaled, full_matrices=len(scaled) < len(cols))
    return ScaledColumns(cols, d, s, vt, numeric_rank(s))


def spanning(a: np.ndarray, rank: int | None = None, first=()) -> list[int]:
    """Columns of ``a`` (unit norm) that span its column space: the columns ``first`` in that
    order, each that still adds a direction (its part outside those already picked longer than
    ADDS); then, while fewer than ``rank`` are picked, each time the one least explained by those
    already picked (QR with column pivoting; ties, remaining norms within TIE of the largest,
    relative, go to the first column: the callers' order). ``rank`` None: the ``first`` ones only."""
    a = a.copy()
    picked: list[int] = []
    limit = a.shape[1] if rank is None else rank

    def pick(j):
        q = a[:, j] / np.linalg.norm(a[:, j])
        a[:] -= np.outer(q, q @ a)
        picked.append(j)

    for j in first:
        if len(picked) < limit and j not in picked and np.linalg.norm(a[:, j]) > ADDS:
            pick(j)
    while rank is not None and len(picked) < rank:
        norms = np.linalg.norm(a, axis=0)
        pick(int(np.flatnonzero(norms >= norms.max() * (1 - TIE))[0]))
    return picked


# ----------------------------------------------------------------------------- uncertainties

def residual_variance(r: np.ndarray, dof: float) -> float:
    """sigma^2 estimated from the residual: its sum of squares per degree of freedom."""
    return float(r @ r) / dof


def normal_inverse(j: np.ndarray) -> np.ndarray:
    """(JᵀJ)^-1: times sigma^2, the covariance of a least-squares estimate (LinAlgError where JᵀJ
    is singular: a parameter the data do not determine)."""
    return np.linalg.inv(j.T @ j)


def svd_inverse(j: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(JᵀJ)^-1 of a J of full column rank from its SVD (accurate to the condition number, not its
    square), and J's singular values, largest first (the condition number is s[0] / s[-1])."""
    _, s, vt = np.linalg.svd(j, full_matrices=False)
    return (vt.T / s ** 2) @ vt, s


@dataclass
class LinearFit:
    estimates: np.ndarray
    residual: np.ndarray    # data minus the fitted model
    dof: int
    variance: float         # sigma^2 from the residual
    covariance: np.ndarray


def linear_fit(j: np.ndarray, y: np.ndarray) -> LinearFit:
    """The least-squares solution of j·x = y with its covariance sigma^2 (JᵀJ)^-1, sigma^2 from
    the residual. The caller makes sure there are more rows than columns."""
    x = solve(j, y)
    r = y - j @ x
    dof = len(y) - j.shape[1]
    var = residual_variance(r, dof)
    return LinearFit(x, r, dof, var, var * normal_inverse(j))


def correlation_matrix(cov: np.ndarray, std: np.ndarray) -> np.ndarray:
    """The correlations of estimates with covariance ``cov`` and standard uncertainties ``std``
    (0 where an uncertainty is 0)."""
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.nan_to_num(cov / np.outer(std, std))


def strong_correlations(cov: np.ndarray, std: np.ndarray, names: list[str], among: list[int],
                        above: float = 0.9) -> list[tuple[str, str, float]]:
    """(name, name, correlation) of each pair of the estimates ``among`` whose correlation is
    beyond ±``above``: the data hardly tell those two apart."""
    out = []
    for a, b in ((a, b) for i, a in enumerate(among) for b in among[i + 1:]):
        if std[a] > 0 and std[b] > 0:
            c = cov[a, b] / (std[a] * std[b])
            if abs(c) > above:
                out.append((names[a], names[b], float(c)))
    return out


# ----------------------------------------------------------------------------- weights and misfit

def huber_weights(u: np.ndarray, k: float) -> np.ndarray:
    """IRLS weights of Huber's loss at standardized residuals u: 1 within k, k/|u| beyond
    (rho(u) = u^2/2 within k, k|u| - k^2/2 beyond; weight = rho'(u)/u)."""
    a = np.abs(u)
    return np.where(a <= k, 1.0, k / np.maximum(a, 1e-300))


def chi2_quantile(probability: float, dof: float) -> float:
    """The chi-square distribution's quantile: x with P(X <= x) = probability for ``dof``
    degrees of freedom, from the regularized incomplete gamma function (mpmath), by bisection."""
    import mpmath

    def upper(x):  # P(X > x)
        return float(mpmath.gammainc(dof / 2, 0, x / 2, regularized=True))
    lo, hi = 0.0, max(1.0, dof)
    while upper(hi) < probability:
        hi *= 2
    for _ in range(200):
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if upper(mid) < probability else (lo, mid)
        if hi - lo <= 1e-12 * hi:
            break
    return 0.5 * (lo + hi)


def chi2_limit(chi2: float | None, dof: float) -> float | None:
    """With the uncertainties given (chi2 = weighted residual sum of squares / dof), the largest
    chi2/dof its distribution allows at MISFIT_PROBABILITY, when ``chi2`` is beyond it (the
    residuals are larger than the uncertainties allow); else None."""
    if chi2 is None or not dof > 0:
        return None
    limit = chi2_quantile(MISFIT_PROBABILITY, dof) / dof
    return limit if chi2 > limit else None
