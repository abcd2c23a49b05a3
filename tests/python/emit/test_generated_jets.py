"""Generated C++ by the straight-line code (a chain past the expansion limit): the benchmark's
UR5 (tools/bench_machines/ur5.yaml: twists as parameters, 24 DH errors), built into a library by `chaincomp build`, called
through its function table with ctypes, against the Python models: the gain matrix and the
order-1/2 errors to 1e-12, the pose and Jacobian against central differences."""

import ctypes
import os
import re
import subprocess
import sys

import numpy as np
import pytest

from chaincomp import ExactModel, load_machine
from chaincomp.symbolic.derive import EXPANDED_TERMS_LIMIT
from chaincomp.emit.cpp import generate
from chaincomp.symbolic.jets import JetModel
from helpers import ROOT
from model_library import Library, arr


@pytest.fixture(scope="module")
def ur5c(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("ur5c")
    path = os.path.join(ROOT, "tools", "bench_machines", "ur5.yaml")   # twists as parameters, a tool off axis
    env = dict(os.environ, XDG_CACHE_HOME=str(tmp / "cache"))
    proc = subprocess.run([sys.executable, "-m", "chaincomp.cli.main", "build", str(path)], capture_output=True,
                          text=True, cwd=ROOT, env=env, timeout=900)
    assert proc.returncode == 0, proc.stderr
    lib = ctypes.CDLL(proc.stdout.strip().splitlines()[-1])
    lib.chaincomp_model_library.restype = ctypes.POINTER(Library)
    entry = lib.chaincomp_model_library().contents.entry.contents
    m = load_machine(str(path))
    model = ctypes.create_string_buffer(entry.model_size + entry.model_align)
    addr = (ctypes.addressof(model) + entry.model_align - 1) // entry.model_align * entry.model_align
    return m, entry, ctypes.c_void_p(addr), lib, model  # lib and model kept alive with it


@pytest.mark.slow
def test_the_chain_is_past_the_expansion_limit(ur5c):
    from chaincomp import derive
    m = ur5c[0]
    assert derive(m, 2, max_terms=EXPANDED_TERMS_LIMIT) is None   # stopped early
    assert derive(m, 1, max_terms=10**6) is not None


@pytest.mark.slow
def test_generated_jets_against_python(ur5c):
    m, entry, model, *_ = ur5c
    rng = np.random.default_rng(9)
    params = [s for s in m.symbols if s.role != "axis"]
    errs = {s.name: 1e-3 * rng.normal() for s in m.errors}
    values = [errs[s.name] if s.role == "error" else s.to_internal(s.nominal) for s in params]
    entry.prepare(arr(values), model)
    jets, exact = JetModel(m, 2), ExactModel(m)
    for _ in range(5):
        q = {a.name: rng.uniform(-np.pi, np.pi) for a in m.axes}
        qa = arr([q[a.name] for a in m.axes])
        for k in (1, 2):
            out = arr([0.0] * 6)
            assert entry.error(model, qa, k, out)
            want = np.concatenate(jets.error(q | errs, k))
            assert np.allclose(list(out), want, rtol=1e-12, atol=1e-13)
        pose, jac, gain = arr([0.0] * 6), arr([0.0] * 36), arr([0.0] * 6 * len(m.errors))
        entry.pose_jacobian_gain(model, qa, pose, jac, gain)
        g = jets.gains(q)
        want_gain = np.array([g[c] for c in ("dx", "dy", "dz", "dkx", "dky", "dkz")])   # column-major in C++
        assert np.allclose(np.array(list(gain)).reshape(len(m.errors), 6).T, want_gain, rtol=1e-12, atol=1e-12)
        p, d = exact.pose(q | errs)
        assert np.allclose(list(pose), list(p) + list(d), atol=1e-12)
        J = np.array(list(jac)).reshape(6, 6).T
        for j, a in enumerate(m.axes):
            up, down = dict(q | errs), dict(q | errs)
            up[a.name] += 1e-6
            down[a.name] -= 1e-6
            fd = (np.concatenate(exact.pose(up)) - np.concatenate(exact.pose(down))) / 2e-6
            assert np.allclose(J[:, j], fd, atol=1e-6)
        for c, s in enumerate(m.errors):   # the gain at zero errors, by central differences
            up, down = dict(q), dict(q)
            up[s.name], down[s.name] = 1e-6, -1e-6
            fd = (np.concatenate(exact.pose(up)) - np.concatenate(exact.pose(down))) / 2e-6
            assert np.allclose(np.array(list(gain)).reshape(len(m.errors), 6)[c], fd, atol=1e-6)


def test_generated_error_residual_falls_as_eps_to_the_order_plus_one(ur5c):
    m, entry, model, *_ = ur5c
    rng = np.random.default_rng(21)
    params = [s for s in m.symbols if s.role != "axis"]
    errs = {s.name: 1e-3 * rng.normal() for s in m.errors}
    q = {a.name: rng.uniform(-np.pi, np.pi) for a in m.axes}
    qa, exact = arr([q[a.name] for a in m.axes]), ExactModel(m)
    for k in (1, 2):
        res = []
        for eps in (4.0, 2.0, 1.0):
            e = {n: eps * x for n, x in errs.items()}
            entry.prepare(arr([e[s.name] if s.role == "error" else s.to_internal(s.nominal) for s in params]), model)
            out = arr([0.0] * 6)
            assert entry.error(model, qa, k, out)
            res.append(np.abs(np.array(list(out)) - np.concatenate(exact.error(q | e))).max())
        slopes = [np.log2(res[i] / res[i + 1]) for i in range(2)]
        assert all(abs(s - (k + 1)) < 0.25 for s in slopes), (k, res)


def test_generated_source_size_and_operations(ur5c):
    """Linear in the chain: the issue's expanded code was 1.49 MB with 32 139 operations in
    pose_jacobian_gain (SymForce: 2597 for the same outputs); the straight-line code is a
    fraction of that, and the same source twice."""
    first = generate(ur5c[0], 2)
    text = first["ur5.cpp"]
    assert generate(ur5c[0], 2) == first
    assert len(text) < 100_000
    ops = dict(re.findall(r"void (\w+)\(const Model& m[^{]*\{\n  // (\d+) operations", text))
    assert int(ops["pose_jacobian_gain"]) < 1500 and int(ops["error_order2"]) < 2000, ops
    assert "new " not in text.split("namespace {")[0] and "noexcept" in text


@pytest.mark.slow
def test_straight_line_code_compiles_without_warnings(tmp_path):
    """The bundled UR5's numbers fold whole functions into constants (pose_nominal reads no
    parameter): the model flags' -Wall -Wextra stay quiet all the same."""
    import json
    from chaincomp import load_machine as load
    flags = json.load(open(os.path.join(ROOT, "build", "model_build.json")))
    for name, text in generate(load(os.path.join(ROOT, "configs", "machines", "ur5.yaml")), 2).items():
        (tmp_path / name).write_text(text)
    proc = subprocess.run([flags["compiler"], *flags["flags"], "-fsyntax-only", "-Werror",
                           *[f"-I{d}" for d in flags["include_dirs"]], f"-I{tmp_path}", str(tmp_path / "ur5.cpp")],
                          capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, proc.stderr
