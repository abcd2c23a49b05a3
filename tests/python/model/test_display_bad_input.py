"""Estimate ± uncertainty (chaincomp.model.display) at the edges: an uncertainty finer than a double,
numpy floats."""

from __future__ import annotations

import numpy as np
import pytest

from chaincomp.model import display


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


def test_plus_minus_of_numpy_floats():
    """repr(np.float64(2.4)) is 'np.float64(2.4)' in numpy 2: no decimal text (exit 3 before)."""
    assert display.plus_minus(np.float64(4.6), np.float64(0.21)) == "4.60 ± 0.21"
    assert display.uncertain(np.float64(4.6e-3), np.float64(2.1e-4), "length") == "4.60 ± 0.21 µm"
