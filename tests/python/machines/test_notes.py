"""ME220 course notes (Vijayaraghavan 2008; Chien, Helu & Warren 2008): the notes' HTMs,
multiplied numerically here, against the models derived from the bundled machine files."""

import random

import numpy as np
import sympy as sp

from chaincomp import load_machine
from chaincomp.symbolic.derive import derive
from chaincomp.symbolic.numeric import TruncatedModel

from helpers import machine_path


def first_order_part(f, errors: dict) -> np.ndarray:
    """Linear part of f at zero errors along ``errors``: sum_j e_j df/de_j.

    Each derivative by the complex step, Im f(i h e_j) / h, exact to rounding for the
    analytic operations used here (matrix products and inverses).
    """
    h = 1e-30
    zero = {k: 0.0 for k in errors}
    total = 0.0
    for name, value in errors.items():
        step = dict(zero)
        step[name] = 1j * h
        total = total + value * np.imag(f(step)) / h
    return total


def htm(rot, trans):
    m = np.eye(4, dtype=complex)
    m[:3, :3] = rot
    m[:3, 3] = trans
    return m


def small_rot(ex=0.0, ey=0.0, ez=0.0):
    """The notes' eq. 9 rotation part."""
    return np.array([[1, -ez, ey], [ez, 1, -ex], [-ey, ex, 1]], dtype=complex)


def test_me220_xz_first_order_equals_notes_eqs_11_12():
    m = load_machine(machine_path("me220_xz"))
    model = TruncatedModel(derive(m, 1))
    rng = random.Random(11)
    c = m.nominal_values()
    for _ in range(5):
        x, z = rng.uniform(-200, 200), rng.uniform(-150, 150)
        errs = {n: rng.uniform(-1e-3, 1e-3) for n in ("dx1", "ey1", "ez1", "dz2", "ey2")}

        def point(e):
            t01 = htm(small_rot(ey=e["ey1"], ez=e["ez1"]), [x + e["dx1"], c["Y1"], 0])   # eq. 11
            t12 = htm(small_rot(ey=e["ey2"]), [0, c["Y2"], z + e["dz2"]])                # eq. 12
            return (t01 @ t12 @ np.array([c["tx"], c["ty"], c["tz"], 1.0]))[:3]           # eq. 14

        ideal = np.array([c["tx"] + x, c["ty"] + c["Y1"] + c["Y2"], c["tz"] + z])       # eq. 13
        assert np.allclose(point({k: 0.0 for k in errs}).real, ideal)
        want = first_order_part(point, errs)
        values = dict(c, X=x, Z=z, **errs)
        got, _ = model.error(values, 1)
        assert np.allclose(got, want, rtol=0, atol=1e-12)


def test_mori_seiki_first_order_htm_and_gain():
    """inv(0T6)·0T5 from the §5 HTMs (with the machine file's axes added) against the chain."""
    m = load_machine(machine_path("mori_seiki_nv1500"))
    d = derive(m, 1, htm=True)
    names = [s.name for s in m.errors]
    rng = random.Random(5)
    c = m.nominal_values()
    syms = [s.sym for s in m.symbols]
    for _ in range(4):
        X, Y, Z = rng.uniform(-200, 200), rng.uniform(-150, 150), rng.uniform(-200, 100)
        errs = {n: rng.uniform(-1e-3, 1e-3) for n in names}

        def pose(e):
            t01 = htm(np.eye(3), [-c["dx01"], 0, c["dz01"]])
            t12 = htm(np.eye(3), [c["dx12"], 0, 0])
            t23 = htm(small_rot(ey=e["ey3"]), [0, 0, e["dz3"] - c["dz23"] + Z])
            t34 = htm(small_rot(ez=e["ez4"]), [e["dx4"], e["dy4"], -c["dz34"]])
            t45 = htm(np.eye(3), [e["dx5"], e["dy5"], -c["dz45"]])
            t09 = htm(np.eye(3), [0, 0, c["dz09"]])
            t98 = htm(small_rot(ez=e["ez8"]), [0, e["dy8"] + Y, c["dz98"]])
            t87 = htm(small_rot(ez=e["ez7"]), [e["dx7"] + X, 0, c["dz87"]])
            t76 = htm(np.eye(3), [0, 0, c["dz76"]])
            t05 = t01 @ t12 @ t23 @ t34 @ t45
            t06 = t09 @ t98 @ t87 @ t76
            return np.linalg.inv(t06) @ t05

        want = first_order_part(pose, errs)
        values = dict(c, X=X, Y=Y, Z=Z, **errs)
        args = [values[s.name] for s in m.symbols]
        got = np.zeros((4, 4))
        for col, vec in enumerate(d.columns):
            for row in range(3):
                got[row, col] = float(sp.lambdify(syms, d.error(vec[row], 1))(*args))
        assert np.allclose(got, want[:, :], rtol=0, atol=1e-12), (got, want)
        # gain matrix: the point column's first-order coefficients, one error at a time
        gains = d.gain_matrix()
        for j, n in enumerate(names):
            unit = {k: (1.0 if k == n else 0.0) for k in names}
            col = first_order_part(pose, unit)[:3, 3]
            g = [float(sp.lambdify(syms, gains[r][j])(*args)) for r in ("dx", "dy", "dz")]
            assert np.allclose(g, col, rtol=0, atol=1e-12), (n, g, col)
