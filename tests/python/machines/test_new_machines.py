"""vmc_xyz and trunnion_ac against models written here from the standards' definitions.

Each machine is rebuilt in numpy as 4x4 homogeneous transforms, without chaincomp's chain
or parser: the table's error motion as the matrix inverse of the ISO 230-1 error block
(the standard's errors are the tool's relative to the workpiece), squareness as a
rotation of an axis' direction of travel, a rotary axis as a Rodrigues rotation about
its actual axis line (ISO 230-7 location errors: a point and a direction). The tool
relative to the workpiece is inv(W)·T. chaincomp's nominal pose, Jacobian, first-order
gain matrix and exact error must agree with it, the gains with its central finite
differences, and the gains of single errors with what the standards say they mean.
"""

import math

import numpy as np
import pytest
import sympy as sp

from chaincomp import load_machine, load_params
from chaincomp.symbolic.derive import derive

from helpers import PARAMS, eval_json, machine_path
from machine_models import MODELS, rot


ROWS = ("dx", "dy", "dz", "dkx", "dky", "dkz")


class Derived:
    """chaincomp's first-order derivation of a machine, as numpy functions."""

    def __init__(self, name):
        self.name, self.m = name, load_machine(machine_path(name))
        d = derive(self.m, 1)
        self.gm = d.gain_matrix()
        self.errors = [e.name for e in self.m.errors]
        symbols = [s.sym for s in self.m.symbols]
        nominal = [d.nominal(s) for s in d.point + d.direction]
        self._gains = sp.lambdify(symbols, [[self.gm[r][j] for j in range(len(self.errors))] for r in ROWS])
        self._nominal = sp.lambdify(symbols, nominal)
        self._jacobian = sp.lambdify(symbols, [[sp.diff(e, a.sym) for a in self.m.axes] for e in nominal])

    def args(self, v):
        return [v[s.name] for s in self.m.symbols]

    def gains(self, v):
        return np.array(self._gains(*self.args(v)), float)

    def gain(self, err, v):
        return self.gains(v)[:, self.errors.index(err)]

    def nominal(self, v):
        return np.array(self._nominal(*self.args(v)), float)

    def jacobian(self, v):
        return np.array(self._jacobian(*self.args(v)), float)

    def samples(self, n, seed):
        """n random axis positions within the limits; constants nominal, errors zero."""
        rng = np.random.default_rng(seed)
        out = []
        for _ in range(n):
            v = self.m.nominal_values()
            for a in self.m.axes:
                v[a.name] = a.to_internal(rng.uniform(*a.limits))
            out.append(v)
        return out


_DERIVED: dict = {}


def derived(name):
    if name not in _DERIVED:
        _DERIVED[name] = Derived(name)
    return _DERIVED[name]


@pytest.fixture(params=sorted(MODELS))
def case(request):
    return derived(request.param)


def central(name, v, sym, h):
    """Central difference of our pose (point and direction) in one symbol."""
    plus, minus = dict(v), dict(v)
    plus[sym] = v[sym] + h
    minus[sym] = v[sym] - h
    return np.concatenate([np.subtract(*x) for x in zip(MODELS[name](plus), MODELS[name](minus))]) / (2 * h)


def test_nominal_pose_and_jacobian(case):
    for v in case.samples(20, 1):
        p, k = MODELS[case.name](v)
        got = case.nominal(v)
        assert np.allclose(got[:3], p, rtol=0, atol=1e-9) and np.allclose(got[3:], k, rtol=0, atol=1e-12), v
        jac = case.jacobian(v)
        for i, a in enumerate(case.m.axes):
            fd = central(case.name, v, a.name, 1e-6)
            # truncation ~h^2 * third derivative (~1e3 mm), rounding ~1e-16 * 1e3 mm / h
            assert np.allclose(jac[:, i], fd, rtol=0, atol=1e-6 * (1 + np.abs(fd).max())), (a.name, jac[:, i], fd)


def test_gain_matrix_against_central_differences(case):
    """Each error's first-order gain equals the central difference of our model at zero
    errors: truncation ~h^2 * 1e3 mm, rounding ~1e-16 * 1e3 mm / h, both below 1e-6."""
    for v in case.samples(6, 2):
        g = case.gains(v)
        for j, err in enumerate(case.errors):
            fd = central(case.name, v, err, 1e-7)
            assert np.allclose(g[:, j], fd, rtol=0, atol=1e-6 * (1 + np.abs(fd).max())), (err, g[:, j], fd)


@pytest.mark.slow
def test_exact_error_with_demo_params(case):
    """chaincomp eval's exact error (no truncation) at the demo values equals ours."""
    params = f"{PARAMS}/{case.name}-demo.yaml"
    values = case.m.nominal_values()
    values.update(load_params(params, case.m))
    for v in case.samples(2, 3):
        sets = [x for a in case.m.axes for x in ("--set", f"{a.name}={v[a.name] / a.to_internal(1.0)!r}")]
        out = eval_json(machine_path(case.name), "--params", params, *sets)
        p1, k1 = MODELS[case.name]({**values, **{a.name: v[a.name] for a in case.m.axes}})
        p0, k0 = MODELS[case.name](v)
        assert np.allclose(out["position"], p0, rtol=0, atol=1e-9)
        assert np.allclose(out["error"]["exact"], p1 - p0, rtol=0, atol=1e-11), (out["error"]["exact"], p1 - p0)
        assert np.allclose(out["direction_error"]["exact"], k1 - k0, rtol=0, atol=1e-13)
        assert np.abs(p1 - p0).max() > 1e-4  # the demo errors move the tool by µm: the test can fail


# ---- what the standards say the errors mean, error by error (first order)

@pytest.mark.parametrize("axis", "XYZ")
def test_vmc_iso230_signs(axis):
    """ISO 230-1: EXX, EYX, EZX (and those of Y and Z) move the tool relative to the
    workpiece by +1 along x, y, z; EAX, EBX, ECX turn it by +1 about x, y, z around the
    axis' pivot (the tool tip lies at (0, Y, H+Z-L) from X's pivot, (0, 0, H+Z-L) from
    Y's, (0, 0, -L) from Z's: the machine file's comment), so the tool axis turns by
    e × z; table or head alike."""
    vmc = derived("vmc_xyz")
    for v in vmc.samples(5, 4):
        h = v["H"] + v["Z"] - v["L"]
        lever = {"X": (0, v["Y"], h), "Y": (0, 0, h), "Z": (0, 0, -v["L"])}[axis]
        for i, c in enumerate("XYZ"):
            assert np.allclose(vmc.gain(f"E{c}{axis}", v), np.eye(6)[i], rtol=0, atol=1e-12)
            turn = np.eye(3)[i]
            expect = np.concatenate([np.cross(turn, lever), np.cross(turn, [0, 0, 1])])
            assert np.allclose(vmc.gain(f"E{'ABC'[i]}{axis}", v), expect, rtol=0, atol=1e-9), (c, axis)


def test_vmc_squareness_meaning():
    """EC0Y turns Y's travel about +z (toward -x for +Y), EB0Z turns Z's about +y (toward
    +x for +Z), EA0Z turns Z's about +x (toward -y for +Z); the tool axis does not turn."""
    vmc = derived("vmc_xyz")
    Y, Z = (vmc.m.symbol(n).sym for n in "YZ")
    expect = {"EC0Y": [-Y, 0, 0], "EB0Z": [Z, 0, 0], "EA0Z": [0, -Z, 0]}
    for err, vec in expect.items():
        got = [vmc.gm[r][vmc.errors.index(err)] for r in ROWS]
        assert [sp.simplify(a - b) for a, b in zip(got, vec + [0, 0, 0])] == [0] * 6, (err, got)


def test_trunnion_location_errors_meaning():
    """ISO 230-7: a displaced or tilted axis line moves nothing at angle 0; only the zero
    errors act there (EA0A > 0: the tool turned further about +x, relative to the
    workpiece, around A's line). At A = 0 a C line displaced by (EX0C, EY0C) moves the
    tool point by (I - Rz(C))·offset: the offset seen from the workpiece the table turned."""
    tr = derived("trunnion_ac")
    zero = tr.m.nominal_values()  # axes at 0, constants nominal, errors 0
    tip = np.array([0.0, 0.0, zero["H"] - zero["L"]])  # tool tip from the A/C intersection
    for err in tr.errors:
        g = tr.gain(err, zero)
        if err == "EA0A":
            assert np.allclose(g, np.concatenate([np.cross([1, 0, 0], tip), np.cross([1, 0, 0], [0, 0, 1])]))
        else:  # EC0C too: the tool tip and axis lie on C's line at X = Y = 0
            assert np.allclose(g, 0, atol=1e-12), (err, g)
    for c in np.radians([30, 90, 200]):
        at = dict(zero, C=c)
        for err, offset in (("EX0C", [1, 0, 0]), ("EY0C", [0, 1, 0])):
            expect = np.asarray(offset) - rot("z", c)[:3, :3] @ offset
            assert np.allclose(tr.gain(err, at)[:3], expect, rtol=0, atol=1e-12), err
    # EC0C > 0 turns the tool relative to the workpiece further about +z: at X = 100 the
    # tool point moves along +y (seen from the workpiece, turned by C)
    at = dict(zero, X=100.0, C=math.radians(40))
    assert np.allclose(tr.gain("EC0C", at)[:3], 100.0 * (rot("z", math.radians(40))[:3, :3] @ [0, 1, 0]))
