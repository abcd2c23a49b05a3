"""Numeric jets through the chain (chaincomp.symbolic.jets) against the symbolic derivation on every
bundled machine, and on a six-joint arm (UR5, standard DH, 24 errors; Universal Robots'
published parameters) against the exact model: residuals falling as eps^(k+1) and gains
against central finite differences. The arm is written here, not bundled."""

import glob
import math
import os

import numpy as np
import pytest

from chaincomp import ExactModel, load_machine
from chaincomp.symbolic.jets import JetModel

from arm_models import UR5_A, UR5_D, ur5 as ur5_frame
from helpers import ROOT, truncated

BUNDLED = sorted(glob.glob(os.path.join(ROOT, "configs", "machines", "*.yaml")))

# the UR5's twists as the YAML writes them (arm_models.UR5_ALPHA in rad)
UR5_ALPHA = ["pi/2", "0", "0", "pi/2", "-pi/2", "0"]


def ur5_yaml() -> str:
    lines = ["name: ur5_dh", "rotation_sense: right_hand", "symbols:"]
    lines += [f"  - {{name: q{i}, role: axis, unit: deg, limits: [-360, 360]}}" for i in range(1, 7)]
    for i in range(1, 7):
        if UR5_D[i - 1]:
            lines.append(f"  - {{name: d{i}, role: constant, unit: mm, nominal: {UR5_D[i - 1]}}}")
        if UR5_A[i - 1]:
            lines.append(f"  - {{name: a{i}, role: constant, unit: mm, nominal: {UR5_A[i - 1]}}}")
    for i in range(1, 7):
        for e, u in (("dth", "arcsec"), ("dd", "um"), ("da", "um"), ("dal", "arcsec")):
            lines.append(f"  - {{name: {e}{i}, role: error, unit: {u}}}")
    lines.append("chain:")
    for i in range(1, 7):
        dz = f"d{i} + dd{i}" if UR5_D[i - 1] else f"dd{i}"
        dx = f"a{i} + da{i}" if UR5_A[i - 1] else f"da{i}"
        lines += [f"  - {{rotate: z, angle: q{i} + dth{i}}}", f"  - {{translate: [0, 0, {dz}]}}",
                  f"  - {{translate: [{dx}, 0, 0]}}", f"  - {{rotate: x, angle: {UR5_ALPHA[i - 1]} + dal{i}}}"]
    lines += ["tool:", "  point: [0, 0, 0]", "  direction: [0, 0, 1]"]
    return "\n".join(lines) + "\n"


@pytest.fixture(scope="module")
def ur5(tmp_path_factory):
    path = tmp_path_factory.mktemp("ur5") / "ur5.yaml"
    path.write_text(ur5_yaml())
    return load_machine(str(path))


def random_values(m, rng, scale):
    v = {s.name: s.to_internal(rng.uniform(*s.limits)) for s in m.axes}
    v.update({s.name: scale * rng.normal() for s in m.errors})
    return v


@pytest.mark.slow
@pytest.mark.parametrize("path", BUNDLED, ids=os.path.basename)
def test_jets_equal_the_symbolic_truncated_models(path):
    m = load_machine(path)
    rng = np.random.default_rng(7)
    symbolic, jets = truncated(path, 2), JetModel(m, 2)
    for _ in range(3):
        v = random_values(m, rng, 1e-3)
        for k in (1, 2):
            a, b = symbolic.error(v, k), jets.error(v, k)
            for u, w in zip(a, b):
                if u is not None:
                    assert np.allclose(u, w, rtol=1e-12, atol=1e-15)


def test_ur5_point_matches_a_numpy_dh_product(ur5):
    """The nominal tool point against the textbook DH product Rz(q) Tz(d) Tx(a) Rx(alpha)."""
    rng = np.random.default_rng(3)
    q = rng.uniform(-math.pi, math.pi, 6)
    T = ur5_frame(q)
    point, direction = ExactModel(ur5).pose({f"q{i + 1}": q[i] for i in range(6)})
    assert np.allclose(point, T[:3, 3], atol=1e-9)
    assert np.allclose(direction, T[:3, 2], atol=1e-12)


def test_ur5_residuals_fall_as_eps_to_the_k_plus_1(ur5):
    rng = np.random.default_rng(5)
    v = random_values(ur5, rng, 1.0)
    exact, jets = ExactModel(ur5), JetModel(ur5, 3)
    for k in (1, 2, 3):
        res = []
        for eps in ((1e-3, 1e-4) if k < 3 else (1e-2, 1e-3)):  # above the rounding floor (~1e-13 mm)
            w = dict(v) | {s.name: eps * v[s.name] for s in ur5.errors}
            e = np.array(exact.error(w)[0])
            res.append(np.abs(np.array(jets.error(w, k)[0]) - e).max())
        slope = math.log10(res[0] / res[1])
        assert abs(slope - (k + 1)) < 0.2, (k, res)


def test_ur5_gains_against_central_differences(ur5):
    rng = np.random.default_rng(11)
    v = random_values(ur5, rng, 0.0)
    g = JetModel(ur5, 1).gains(v)
    exact, h = ExactModel(ur5), 1e-6
    for i, s in enumerate(ur5.errors):
        up, down = dict(v), dict(v)
        up[s.name], down[s.name] = h, -h
        fd = (np.array(exact.pose(up)[0]) - np.array(exact.pose(down)[0])) / (2 * h)
        assert np.allclose([g["dx"][i], g["dy"][i], g["dz"][i]], fd, atol=1e-5 * max(1, np.abs(fd).max()))
