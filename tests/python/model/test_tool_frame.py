"""Six-DOF tool frames (issue #17 item 3): `tool: {point, direction, reference}` or
`tool: {point, rotation}`, and the orientation error as a rotation vector ω with
R_actual = exp([ω]×)·R_nominal (base frame) in the models, derive, eval, budget and the
generated code.

Truth from outside the code: a numpy model of the UR5 (UR's DH table with Hayati's beta after
joints 2 and 3, as tests/python/machines/test_demo_arm.py writes it) and of a small two-axis head,
written here; scipy's Rotation for the log of R_actual·R_nominalᵀ; central differences of them
for the gains; the order of Taylor truncation for the order-2 models.
"""

from __future__ import annotations

import ctypes
import json
import math
import os
import subprocess
import sys

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from chaincomp import load_machine
from chaincomp.symbolic.derive import derive
from chaincomp.emit.cpp import generate
from chaincomp.symbolic.jets import JetModel
from chaincomp.symbolic.numeric import ExactModel, TruncatedModel

from helpers import ROOT, machine_path
from arm_models import UR5_FRAME, rot, ur5_frame
from helpers import head_file, no_frame_file, run_verb, ur5_frame_file
from model_library import Library, arr

# the frame the UR5 variant gets: x along (1, 1, 0.3) made orthogonal to z = (0, 0, 1)
ARCSEC = math.pi / (180 * 3600)


def rotvec(R_actual, R_nominal):
    """log(R_actual·R_nominalᵀ) by scipy (N x 3)."""
    return Rotation.from_matrix(R_actual @ np.swapaxes(R_nominal, -1, -2)).as_rotvec()


def random_q(rng, n):
    return rng.uniform(-math.pi, math.pi, (n, 6))


def random_errors(machine, rng, scale=1.0):
    return {s.name: scale * rng.normal() * (1e-1 if s.unit.kind == "length" else 50 * ARCSEC)
            for s in machine.errors}


def by_name(machine, q):
    return {a.name: q[:, i] for i, a in enumerate(machine.axes)}


# ---------------------------------------------------------------- the machine format

def test_reference_is_made_orthogonal_and_rotation_gives_the_same_frame(tmp_path):
    m = load_machine(str(ur5_frame_file(tmp_path)))
    x, y, z = (np.array(v, float) for v in m.tool_frame)
    assert np.allclose(np.column_stack([x, y, z]), UR5_FRAME, atol=1e-15)
    rows = ", ".join("[" + ", ".join(repr(float(v)) for v in row) + "]" for row in UR5_FRAME)
    m2 = load_machine(str(ur5_frame_file(tmp_path, f"  point: [40, 0, 100]\n  rotation: [{rows}]\n")))
    assert np.allclose(np.array(m2.tool_frame, float), np.array(m.tool_frame, float), atol=1e-15)
    plain = load_machine(str(no_frame_file(tmp_path, "ur5")))
    assert plain.tool_frame is None and plain.tool_reference is None
    bundled = load_machine(machine_path("ur5"))   # the bundled UR5's frame is DH frame 6 itself
    assert np.array_equal(np.array(bundled.tool_frame, float), np.eye(3))


@pytest.mark.parametrize("tool, line, field, words", [
    ("  point: [40, 0, 100]\n  direction: [0, 0, 1]\n  reference: [0, 0, -3]\n", 3, "tool.reference", "parallel"),
    ("  point: [40, 0, 100]\n  reference: [1, 0, 0]\n", 2, "tool.reference", "needs a tool direction"),
    ("  point: [40, 0, 100]\n  direction: [0, 0, 1]\n  reference: [1, 0, q1]\n", 3, "tool.reference", "constant"),
    ("  point: [40, 0, 100]\n  rotation: [[1, 0, 0], [0, 1, 0], [0, 0.1, 1]]\n", 2, "tool.rotation", "orthonormal"),
    ("  point: [40, 0, 100]\n  rotation: [[1, 0, 0], [0, 1, 0], [0, 0, -1]]\n", 2, "tool.rotation", "reflection"),
    ("  point: [40, 0, 100]\n  rotation: [[1, 0, 0], [0, 1, 0]]\n", 2, "tool.rotation", "three rows"),
    ("  point: [40, 0, 100]\n  rotation: [[1, 0, 0], [0, 1, 0], [0, 0, 1]]\n  direction: [0, 0, 1]\n", 3,
     "tool.direction", "not both"),
])
def test_a_bad_frame_is_refused_with_its_line_and_field(tmp_path, tool, line, field, words):
    path = ur5_frame_file(tmp_path, tool)
    first = path.read_text().splitlines().index("tool:") + 1
    code, out, err = run_verb("eval", path, "--set", "q1=0")
    assert code == 2 and "Traceback" not in err, err
    assert f"{path}:{first + line}: {field}:" in err and words in err, err


# ---------------------------------------------------------------- the Python models

@pytest.fixture(scope="module")
def ur5f(tmp_path_factory):
    return load_machine(str(ur5_frame_file(tmp_path_factory.mktemp("ur5f"))))


def test_exact_model_frame_and_rotation_vector_against_the_numpy_ur5(ur5f):
    rng = np.random.default_rng(3)
    q, e = random_q(rng, 200), random_errors(ur5f, rng, 100)   # large errors: the log is not linear here
    p, d, x = ExactModel(ur5f).frame(by_name(ur5f, q) | e)
    R, point = ur5_frame(q, e)
    assert np.abs(np.array(p).T - point).max() < 1e-9
    assert np.abs(np.array(d).T - R[:, :, 2]).max() < 1e-13 and np.abs(np.array(x).T - R[:, :, 0]).max() < 1e-13
    w = np.array(ExactModel(ur5f).orientation_error(by_name(ur5f, q) | e)).T
    want = rotvec(R, ur5_frame(q)[0])
    assert np.abs(want).max() > 1e-2   # degrees: the series of the log matter
    assert np.abs(w - want).max() < 1e-12


def test_rotation_vector_gains_against_central_differences_of_the_numpy_ur5(ur5f):
    rng = np.random.default_rng(5)
    q = random_q(rng, 20)
    g = JetModel(ur5f, 1).gains(by_name(ur5f, q))
    R0 = ur5_frame(q)[0]
    h = 1e-6
    for i, s in enumerate(ur5f.errors):
        fd = (rotvec(ur5_frame(q, {s.name: h})[0], R0) - rotvec(ur5_frame(q, {s.name: -h})[0], R0)) / (2 * h)
        for c, row in enumerate(("wx", "wy", "wz")):
            assert np.allclose(np.broadcast_to(g[row][i], (len(q),)), fd[:, c], atol=1e-8), (s.name, row)


def head_frame(A, B, e1=0.0, e2=0.0, e3=0.0):
    def R(axis, a):
        return rot(axis, np.asarray(a, float))[..., :3, :3]
    tool = np.array([[0, -1, 0], [1, 0, 0], [0, 0, 1.0]])   # x = (0, 1, 0), y = z × x = (-1, 0, 0), z
    return R("z", A) @ R("x", e1) @ R("y", B + e2) @ R("z", e3) @ tool


def test_short_chain_derivation_gain_and_order_two_against_numpy(tmp_path):
    m = load_machine(str(head_file(tmp_path)))
    d = derive(m, 2)
    gain = d.gain_matrix()
    rng = np.random.default_rng(7)
    A, B = rng.uniform(-3, 3, 10), rng.uniform(-2, 2, 10)
    R0, h = head_frame(A, B), 1e-6
    for i, name in enumerate(("e1", "e2", "e3", "d1")):
        plus = head_frame(A, B, **({name: h} if name != "d1" else {}))
        minus = head_frame(A, B, **({name: -h} if name != "d1" else {}))
        fd = (rotvec(plus, R0) - rotvec(minus, R0)) / (2 * h)
        col = m.errors.index(m.symbol(name))
        for c, row in enumerate(("wx", "wy", "wz")):
            f = [float(gain[row][col].subs({m.symbol("A").sym: a, m.symbol("B").sym: b})) for a, b in zip(A, B)]
            assert np.allclose(f, fd[:, c], atol=1e-8), (name, row)
    # order 2: the truncation error falls as the errors cubed (sympy and jets alike)
    e = {"e1": 2e-3, "e2": -1.5e-3, "e3": 2.5e-3, "d1": 0.0}
    trunc, jets = TruncatedModel(d), JetModel(m, 2)
    for model in (lambda v: trunc.orientation_error(v, 2), lambda v: jets.orientation_error(v, 2)):
        miss = []
        for scale in (4, 2, 1):
            v = {"A": A, "B": B, **{k: scale * x for k, x in e.items()}}
            want = rotvec(head_frame(A, B, *(scale * e[k] for k in ("e1", "e2", "e3"))), R0)
            miss.append(np.abs(np.array(model(v)).T - want).max())
        assert 6 < miss[0] / miss[1] < 10 and 6 < miss[1] / miss[2] < 10, miss


@pytest.mark.slow
def test_eval_shows_the_rotation_vector_in_arcsec(tmp_path):
    path = head_file(tmp_path)
    sets = ["--set", "A=20", "--set", "B=30", "--set", "e1=100", "--set", "e2=-50", "--set", "e3=30"]
    code, out, err = run_verb("eval", path, *sets, "--format", "json")
    assert code == 0, err
    doc = json.loads(out)
    want = rotvec(head_frame(np.radians([20]), np.radians([30]), *(np.array([100, -50, 30]) * ARCSEC)),
                  head_frame(np.radians([20]), np.radians([30])))[0]
    assert np.allclose(doc["orientation_error"]["exact"], want, rtol=0, atol=1e-15)
    assert np.allclose(doc["frame_x"], head_frame(np.radians([20]), np.radians([30]))[0][:, 0], atol=1e-15)
    code, out, err = run_verb("eval", path, *sets)
    assert code == 0, err
    line = out.split("orientation error")[1].splitlines()[3]
    assert line.split()[0] == "exact", out
    assert f"{want[0] / ARCSEC:.3f}" in line and f"{np.linalg.norm(want) / ARCSEC:.3f}" in line


@pytest.mark.slow
def test_budget_has_the_orientation_rows_on_a_long_chain(ur5f, tmp_path):
    """The UR5 (jets, no expansion): wx, wy, wz with the systematic error at a point the numpy
    model's rotation vector."""
    params = tmp_path / "p.yaml"
    params.write_text("machine: ur5\nvalues:\n  dtheta1: 25.0 arcsec\n  dalpha4: -25.0 arcsec\n  da2: 210 um\n")
    args = ["budget", ur5f.file, "--params", params, "--over", "q2", "--grid", "3", "--format", "json"]
    for a in ("q1", "q3", "q4", "q5", "q6"):
        args += ["--set", f"{a}=30"]
    code, out, err = run_verb(*args)
    assert code == 0, err
    doc = json.loads(out)
    comps = doc["components"]
    names = [c["component"] for c in comps] if isinstance(comps, list) else list(comps)
    assert {"wx", "wy", "wz"} <= set(names), names


# ---------------------------------------------------------------- the generated code

@pytest.mark.slow
def test_machines_without_a_frame_generate_what_they_did(tmp_path):
    """The pose layout of a frame is the point, the direction and the x axis; without a frame
    nothing changes (the bundled machines' files carry no trace of it)."""
    for name, path in (("ur5", str(no_frame_file(tmp_path, "ur5"))), ("angle_head", machine_path("angle_head"))):
        files = generate(load_machine(path), 2)
        assert "the frame's x axis" not in files[f"{name}.hpp"]
        assert "constexpr int kPoseSize = 6;  // tool point, tool direction\n" in files[f"{name}.hpp"]


@pytest.fixture(scope="module")
def ur5f_lib(ur5f, tmp_path_factory):
    tmp = tmp_path_factory.mktemp("ur5f_lib")
    env = dict(os.environ, XDG_CACHE_HOME=str(tmp / "cache"))
    proc = subprocess.run([sys.executable, "-m", "chaincomp.cli.main", "build", ur5f.file], capture_output=True,
                          text=True, cwd=ROOT, env=env, timeout=900)
    assert proc.returncode == 0, proc.stderr
    lib = ctypes.CDLL(proc.stdout.strip().splitlines()[-1])
    lib.chaincomp_model_library.restype = ctypes.POINTER(Library)
    entry = lib.chaincomp_model_library().contents.entry.contents
    model = ctypes.create_string_buffer(entry.model_size + entry.model_align)
    addr = (ctypes.addressof(model) + entry.model_align - 1) // entry.model_align * entry.model_align
    return entry, ctypes.c_void_p(addr), lib, model


def gain_row(g, row):
    """One row of JetModel.gains at one pose (entries: numbers or arrays of one)."""
    return np.array([float(np.ravel(v)[0]) for v in g[row]])


@pytest.mark.slow
def test_generated_frame_code_against_python_and_numpy(ur5f, ur5f_lib):
    entry, model, *_ = ur5f_lib
    rng = np.random.default_rng(11)
    params = [s for s in ur5f.symbols if s.role != "axis"]
    errs = random_errors(ur5f, rng)
    entry.prepare(arr([errs[s.name] if s.role == "error" else s.to_internal(s.nominal) for s in params]), model)
    jets = JetModel(ur5f, 2)
    n_err = len(ur5f.errors)
    for _ in range(5):
        q = random_q(rng, 1)
        qa = arr(list(q[0]))
        R, point = ur5_frame(q, errs)
        pose = arr([0.0] * 9)
        entry.pose_exact(model, qa, pose)
        assert np.allclose(list(pose), np.concatenate([point[0], R[0][:, 2], R[0][:, 0]]), rtol=0, atol=1e-10)
        R0, p0 = ur5_frame(q)
        entry.pose_nominal(model, qa, pose)
        assert np.allclose(list(pose), np.concatenate([p0[0], R0[0][:, 2], R0[0][:, 0]]), rtol=0, atol=1e-10)
        values = by_name(ur5f, q) | errs
        for k in (1, 2):
            out = arr([0.0] * 9)
            assert entry.error(model, qa, k, out)
            want = np.array(jets.pose_error(values, k), float).ravel()
            assert np.allclose(list(out), want, rtol=1e-12, atol=1e-13)
            p, dd = jets.error(values, k)
            assert np.allclose(want[:6], np.ravel(list(p) + list(dd)), rtol=0, atol=0)
        # the gain: 9 rows (point, direction, x axis); the rotation vector's rows from them
        jac, gain = arr([0.0] * 9 * 6), arr([0.0] * 9 * n_err)
        entry.pose_jacobian_gain(model, qa, pose, jac, gain)
        G = np.array(list(gain)).reshape(n_err, 9).T
        g = jets.gains(by_name(ur5f, q))
        for r, row in enumerate(("dx", "dy", "dz", "dkx", "dky", "dkz")):
            assert np.allclose(G[r], gain_row(g, row), rtol=1e-12, atol=1e-12), row
        z0, x0 = R0[0][:, 2], R0[0][:, 0]
        w = np.cross(z0, G[3:6].T).T + np.outer(z0, np.cross(z0, x0) @ G[6:9])
        want_w = np.array([gain_row(g, row) for row in ("wx", "wy", "wz")])
        assert np.allclose(w, want_w, rtol=1e-12, atol=1e-12)
        # the Jacobian against central differences of the numpy model
        J = np.array(list(jac)).reshape(6, 9).T
        for j in range(6):
            up, down = q.copy(), q.copy()
            up[0, j] += 1e-6
            down[0, j] -= 1e-6
            (Ru, pu), (Rd, pd) = ur5_frame(up, errs), ur5_frame(down, errs)
            fd = np.concatenate([pu[0] - pd[0], Ru[0][:, 2] - Rd[0][:, 2], Ru[0][:, 0] - Rd[0][:, 0]]) / 2e-6
            assert np.allclose(J[:, j], fd, atol=1e-6)


@pytest.mark.slow
def test_a_five_axis_machine_with_a_frame_compensates_as_without(tmp_path):
    """Two rotary axes cannot turn the tool about its axis: with a frame the point and the
    direction are corrected as before (same statuses, same corrections to rounding)."""
    import csv
    if not os.path.isfile(os.path.join(ROOT, "build", "bin", "chaincomp_replay")):
        pytest.skip("no C++ build (tools/setup)")
    plain = machine_path("five_axis_ac")
    with open(plain) as f:
        text = f.read()
    assert "\ntool:\n  point: [0, 0, 0]\n  direction: [0, 0, 1]\n" in text
    framed = tmp_path / "five_axis_ac.yaml"
    framed.write_text(text.replace("  direction: [0, 0, 1]\n", "  direction: [0, 0, 1]\n  reference: [1, 0, 0]\n"))
    log = tmp_path / "path.lcmlog"
    assert run_verb("simulate-log", plain, "-o", log, "--seconds", "0.2")[0] == 0
    params = os.path.join(ROOT, "configs", "params", "five_axis_ac-demo.yaml")
    config = os.path.join(ROOT, "tests", "e2e", "config_test.yaml")
    rows = []
    for m in (plain, framed):
        out = tmp_path / f"{len(rows)}.csv"
        code, _, err = run_verb("replay", m, log, "--params", params, "--config", config, "--csv", out)
        assert code == 0, err
        with open(out) as f:
            rows.append(list(csv.DictReader(f)))
    a, b = rows
    assert [r["status"] for r in a] == [r["status"] for r in b]
    keys = [k for k in a[0] if k.startswith("corrected_")]
    assert max(abs(float(x[k]) - float(y[k])) for x, y in zip(a, b) for k in keys) < 1e-9   # deg


@pytest.mark.slow
@pytest.mark.parametrize("arm", ["ur5", "panda"])
def test_bundled_arms_order_two_orientation_falls_as_the_errors_cubed(arm):
    """The bundled arms' frames at order 2 (symbolic and jets) against the exact rotation
    vector of the chain multiplied numerically: the miss falls 8x when the errors halve. (To
    order 2, ω is the skew part of (R - R0)·R0ᵀ alone; this holds that shortcut to the truth.)"""
    from helpers import truncated
    m = load_machine(machine_path(arm))
    rng = np.random.default_rng(17)
    q = {a.name: rng.uniform(-2.5, 2.5, 8) for a in m.axes}
    e = {s.name: rng.uniform(-1, 1) * (1e-3 if s.unit.kind == "angle" else 0.5) for s in m.errors}
    exact, jets, trunc = ExactModel(m), JetModel(m, 2), truncated(machine_path(arm), 2)
    for model in (lambda v: jets.orientation_error(v, 2), lambda v: trunc.orientation_error(v, 2)):
        miss = []
        for scale in (4, 2, 1):
            v = {**q, **{k: scale * x for k, x in e.items()}}
            miss.append(np.abs(np.array(model(v), float) - np.array(exact.orientation_error(v), float)).max())
        assert 6 < miss[0] / miss[1] < 10 and 6 < miss[1] / miss[2] < 10, miss
