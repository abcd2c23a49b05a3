"""The straight-line code of long chains (chaincomp.emit.straightline), its IR evaluated node by
node, on every bundled machine and every benchmark chain (tools/bench_machines): the exact and
nominal pose against the numpy exact model, error_order_k against the numeric jets (the order-k
truncated series) to 1e-12 with its residual falling as eps^(k+1), the Jacobian against central
differences of the exact model and the gain matrix against central differences in each error
at zero errors."""

import glob
import math
import os

import numpy as np
import pytest

from chaincomp import ExactModel, load_machine
from chaincomp.emit import straightline as SL
from chaincomp.emit.cpp import _Hoister
from chaincomp.symbolic.jets import JetModel
from helpers import ROOT

MACHINES = sorted(glob.glob(os.path.join(ROOT, "configs", "machines", "*.yaml"))
                  + glob.glob(os.path.join(ROOT, "tools", "bench_machines", "*.yaml")))


def _pose(model, values):
    return np.concatenate([x for x in model.pose(values) if x is not None])


class Straight:
    """The straight-line functions of a machine, evaluated as the C++ would evaluate them."""

    def __init__(self, m, order):
        self.m = m
        self.hoist = _Hoister({s.sym for s in m.symbols if s.role != "axis"})
        self.fns = {name: (b, targets) for name, _, b, targets in SL.functions(m, order, self.hoist)}

    def __call__(self, name, values):
        b, targets = self.fns[name]
        inputs = {}
        for a in self.m.axes:
            x = values[a.name]
            inputs |= {"q_" + a.name: x, "s_" + a.name: math.sin(x), "c_" + a.name: math.cos(x)}
        inputs |= {"p_" + s.name: values[s.name] for s in self.m.symbols if s.role != "axis"}
        subs = {s.sym: values[s.name] for s in self.m.symbols}
        inputs |= {str(k): float(e.xreplace(subs)) for e, k in self.hoist.table.items()}   # prepare()
        v = b.g.evaluate(inputs)
        return {t: v[n] for t, n in targets}


def _values(m, rng, scale):
    v = {s.name: s.to_internal(s.nominal) for s in m.constants}
    v |= {s.name: s.to_internal(rng.uniform(*s.limits)) for s in m.axes}
    return v | {s.name: scale * rng.normal() for s in m.errors}


@pytest.fixture(scope="module", params=MACHINES, ids=os.path.basename)
def machine(request):
    m = load_machine(request.param)
    return m, Straight(m, 2), JetModel(m, 2), ExactModel(m)


@pytest.mark.slow
def test_pose_and_truncated_errors(machine):
    m, f, jets, exact = machine
    rng = np.random.default_rng(3)
    ps = 6 if m.tool_direction else 3
    for _ in range(3):
        v = _values(m, rng, 1e-3)
        got = f("pose_exact", v)
        assert np.allclose([got[f"out[{i}]"] for i in range(ps)], _pose(exact, v), rtol=1e-13, atol=1e-12)
        nominal = {k: (0.0 if m.symbol(k).role == "error" else x) for k, x in v.items()}
        got = f("pose_nominal", v)
        assert np.allclose([got[f"out[{i}]"] for i in range(ps)], _pose(exact, nominal), rtol=1e-13, atol=1e-12)
        for k in (1, 2):
            got = f(f"error_order{k}", v)
            want = np.concatenate([x for x in jets.error(v, k) if x is not None])
            assert np.allclose([got[f"out[{i}]"] for i in range(ps)], want, rtol=1e-12, atol=1e-13)


def test_residual_falls_as_eps_to_the_order_plus_one(machine):
    m, f, _, exact = machine
    rng = np.random.default_rng(8)
    ps = 6 if m.tool_direction else 3
    v = _values(m, rng, 1.0)
    errors = {s.name: v[s.name] for s in m.errors}
    for k in (1, 2):
        res = []
        for eps in (1e-2, 5e-3, 2.5e-3):
            w = v | {n: eps * x for n, x in errors.items()}
            got = f(f"error_order{k}", w)
            ex = np.concatenate([x for x in exact.error(w) if x is not None])
            res.append(np.abs(np.array([got[f"out[{i}]"] for i in range(ps)]) - ex).max())
        if res[0] < 1e-12:   # this machine's order-k model is exact (a chain without rotations by errors)
            continue
        slopes = [math.log2(res[i] / res[i + 1]) for i in range(2)]
        assert all(abs(s - (k + 1)) < 0.25 for s in slopes), (k, res)


def test_jacobian_and_gain_against_central_differences(machine):
    m, f, _, exact = machine
    rng = np.random.default_rng(5)
    ps = 6 if m.tool_direction else 3
    v = _values(m, rng, 1e-4)
    got = f("pose_jacobian_gain", v)
    assert np.allclose([got[f"out[{i}]"] for i in range(ps)], _pose(exact, v), rtol=1e-13, atol=1e-12)
    h = 1e-6
    for j, a in enumerate(m.axes):
        up, down = dict(v), dict(v)
        up[a.name] += h
        down[a.name] -= h
        fd = (_pose(exact, up) - _pose(exact, down)) / (2 * h)
        J = np.array([got[f"J({i}, {j})"] for i in range(ps)])
        assert np.allclose(J, fd, atol=1e-6 * max(1.0, np.abs(fd).max()))
        jac = f("pose_jacobian", v)
        assert [jac[f"J({i}, {j})"] for i in range(ps)] == list(J)
    at_zero = {k: (0.0 if m.symbol(k).role == "error" else x) for k, x in v.items()}
    for c, s in enumerate(m.errors):
        up, down = dict(at_zero), dict(at_zero)
        up[s.name], down[s.name] = h, -h
        fd = (_pose(exact, up) - _pose(exact, down)) / (2 * h)
        G = np.array([got[f"G({i}, {c})"] for i in range(ps)])
        assert np.allclose(G, fd, atol=1e-6 * max(1.0, np.abs(fd).max())), s.name
