"""The order-k model's residual against the exact chain falls as eps^(k+1)."""

import random

import mpmath
import numpy as np
import pytest

from chaincomp.symbolic.numeric import ExactModel

from helpers import truncated

EPSILONS = [1e-2, 1e-3, 1e-4, 1e-5]


def random_values(machine, rng):
    values = machine.nominal_values()
    for s in machine.axes:
        lo, hi = s.limits
        values[s.name] = s.to_internal(rng.uniform(lo, hi))
    return values


@pytest.mark.slow
@pytest.mark.parametrize("order", [1, 2])
def test_residual_slope(bundled, order):
    mpmath.mp.dps = 50
    rng = random.Random(20031077 + order)
    exact = ExactModel(bundled)
    model = truncated(bundled.file, order)   # test_jets derived the arms' order 2 already
    for trial in range(3):
        base = random_values(bundled, rng)
        direction = {s.name: rng.uniform(-1, 1) for s in bundled.errors}
        residuals = []
        for eps in EPSILONS:
            values = {k: mpmath.mpf(v) for k, v in base.items()}
            for name, u in direction.items():
                values[name] = mpmath.mpf(u) * mpmath.mpf(eps)
            dp, dd = exact.error(values, "mpmath")
            tp, td = model.error(values, order, "mpmath")
            r = [a - b for a, b in zip(dp, tp)] + ([a - b for a, b in zip(dd, td)] if dd else [])
            residuals.append(float(mpmath.sqrt(sum(x * x for x in r))))
        assert all(r > 0 for r in residuals), residuals
        slope = np.polyfit(np.log(EPSILONS), np.log(residuals), 1)[0]
        assert abs(slope - (order + 1)) < 0.2, (bundled.name, order, trial, slope, residuals)
