"""First-order error gain matrix against central finite differences of the exact chain."""

import random

import numpy as np
import sympy as sp

from chaincomp.symbolic.numeric import ExactModel

import pytest

from helpers import derived
from test_truncation import random_values


@pytest.mark.slow
def test_gain_matrix_equals_finite_differences(bundled):
    rng = random.Random(7)
    exact = ExactModel(bundled)
    d = derived(bundled.file, 1)
    gains = d.gain_matrix()
    symbols = [s.sym for s in d.machine.symbols]
    rows = ["dx", "dy", "dz"] + (["dkx", "dky", "dkz"] if d.direction is not None else [])
    # each gain lambdified once, not once per trial
    gain_fns = [[sp.lambdify(symbols, gains[r][j]) for r in rows] for j in range(len(bundled.errors))]
    h = 1e-6
    for _ in range(4):
        values = random_values(bundled, rng)
        args = [values[s.name] for s in d.machine.symbols]
        for j, err in enumerate(bundled.errors):
            plus, minus = dict(values), dict(values)
            plus[err.name], minus[err.name] = h, -h
            (pp, dp), (pm, dm) = exact.pose(plus), exact.pose(minus)
            fd = [(a - b) / (2 * h) for a, b in zip(pp, pm)]
            if dp is not None:
                fd += [(a - b) / (2 * h) for a, b in zip(dp, dm)]
            analytic = [float(f(*args)) for f in gain_fns[j]]
            scale = 1 + np.max(np.abs(fd))
            # central differences: truncation ~h^2, rounding ~1e-16*|p|/h (|p| up to ~1e3 mm)
            assert np.allclose(analytic, fd, rtol=0, atol=1e-6 * scale), (bundled.name, err.name, analytic, fd)
