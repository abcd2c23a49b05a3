"""The Jacobian generate emits for long chains (each shared subexpression differentiated once)
equals sympy's diff, and central differences of the exact model, on every bundled machine."""

import glob
import os

import numpy as np
import pytest
import sympy as sp

from chaincomp import ExactModel, load_machine
from chaincomp.emit import _diff, exact_pose

ROOT = os.path.abspath(os.path.join(os.path.dirname(__file__), "..", ".."))


@pytest.mark.parametrize("path", sorted(glob.glob(os.path.join(ROOT, "configs", "machines", "*.yaml"))),
                         ids=os.path.basename)
def test_shared_subexpression_diff_equals_sympy_and_finite_differences(path):
    m = load_machine(path)
    exact = exact_pose(m, True)
    axes = [a.sym for a in m.axes]
    syms = [s.sym for s in m.symbols]
    deps: dict = {}
    ours = sp.lambdify(syms, [[_diff(e, a, {}, deps) for a in axes] for e in exact], "numpy", cse=True)
    theirs = sp.lambdify(syms, [[sp.diff(e, a) for a in axes] for e in exact], "numpy", cse=True)
    rng = np.random.default_rng(5)
    model = ExactModel(m)
    for _ in range(3):
        v = {s.name: s.to_internal(rng.uniform(*s.limits)) for s in m.axes}
        v |= {s.name: 1e-4 * rng.normal() for s in m.errors} | {s.name: s.to_internal(s.nominal) for s in m.constants}
        args = [v[s.name] for s in m.symbols]
        a, b = np.array(ours(*args), float), np.array(theirs(*args), float)
        assert np.allclose(a, b, rtol=1e-12, atol=1e-12)
        for j, ax in enumerate(m.axes):
            up, down = dict(v), dict(v)
            up[ax.name] += 1e-6
            down[ax.name] -= 1e-6
            fd = (np.concatenate([x for x in model.pose(up) if x is not None])
                  - np.concatenate([x for x in model.pose(down) if x is not None])) / 2e-6
            assert np.allclose(a[:, j], fd, atol=1e-5 * max(1.0, np.abs(fd).max()))
