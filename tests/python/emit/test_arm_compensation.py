"""Compensation of arms with a tool frame (issue #17 item 4): the generated library's
compensate (cold and through a workspace), called with ctypes, on the UR5 (six joints: a
square system, position and full orientation) and the Panda (seven: damped least squares,
the minimum-norm correction), with the bundled synthetic errors.

Truth from outside the code: numpy models of both arms written here (UR's standard DH with
Hayati's beta; Franka's modified DH and flange), scipy's rotation log, and numpy's SVD for the
null space of the Panda's Jacobian.
"""

from __future__ import annotations

import ctypes
import math
import os
import subprocess
import sys

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from chaincomp import load_machine, load_params

from helpers import PARAMS, ROOT
from helpers import FRAME_ARMS as ARMS
from model_library import Library, arr

INT, VOID_P, DBL_P = ctypes.c_int, ctypes.c_void_p, ctypes.POINTER(ctypes.c_double)
COMPENSATE = ctypes.CFUNCTYPE(INT, VOID_P, VOID_P, DBL_P, ctypes.c_double, DBL_P, DBL_P, DBL_P)
INIT = ctypes.CFUNCTYPE(None, VOID_P)
BOUND = 0.0175   # rad: kMaxAngularCorrection


class Arm:
    """An arm's library through its function table, with the bundled synthetic errors."""

    def __init__(self, name, tmp):
        self.machine = load_machine(str(ARMS[name][0](tmp)))
        self.numpy = ARMS[name][1]
        env = dict(os.environ, XDG_CACHE_HOME=str(tmp / "cache"))
        proc = subprocess.run([sys.executable, "-m", "chaincomp.cli.main", "build", self.machine.file],
                              capture_output=True, text=True, cwd=ROOT, env=env, timeout=900)
        assert proc.returncode == 0, proc.stderr
        self.lib = ctypes.CDLL(proc.stdout.strip().splitlines()[-1])
        self.lib.chaincomp_model_library.restype = ctypes.POINTER(Library)
        self.entry = e = self.lib.chaincomp_model_library().contents.entry.contents
        self.values = load_params(os.path.join(PARAMS, f"{name}-demo.yaml"), self.machine)
        params = [s for s in self.machine.symbols if s.role != "axis"]
        self._model = ctypes.create_string_buffer(e.model_size + e.model_align)
        self.model = VOID_P(_aligned(self._model, e.model_align))
        e.prepare(arr([self.values.get(s.name, 0.0) if s.role == "error" else s.to_internal(s.nominal)
                       for s in params]), self.model)
        self.errors = {s.name: self.values.get(s.name, 0.0) for s in self.machine.errors}
        self._compensate = COMPENSATE(e.compensate)
        self._ws = ctypes.create_string_buffer(e.workspace_size + e.workspace_align)
        self.workspace = VOID_P(_aligned(self._ws, e.workspace_align))
        INIT(e.init_workspace)(self.workspace)
        self.n = len(self.machine.axes)

    def compensate(self, q, warm=False):
        """(status, corrected (n), residual (point mm, orientation rad)) for one command."""
        out, res = arr([0.0] * self.n), arr([0.0, 0.0])
        s = self._compensate(self.model, self.workspace if warm else None, arr(list(q)), 100.0, out, res, None)
        return s, np.array(list(out)), np.array(list(res))

    def miss(self, command, corrected):
        """(point miss mm, orientation miss rad) of the numpy arm at the corrected joints
        against the nominal pose at the commanded ones."""
        R1, p1 = self.numpy(corrected, self.errors)
        R0, p0 = self.numpy(command)
        w = Rotation.from_matrix(R1 @ np.swapaxes(R0, -1, -2)).as_rotvec()
        return np.linalg.norm(p1 - p0, axis=1), np.linalg.norm(w, axis=1)

    def jacobian(self, q, errors=None):
        """6 x n: d(point mm, rotation vector rad x 100 mm) / dq by central differences, numpy."""
        return self.jacobians(q[None], errors)[0]

    def jacobians(self, q, errors=None):
        """(poses, 6, n): jacobian at each row of q, the poses at once."""
        h, cols = 1e-6, []
        for j in range(self.n):
            up, down = q.copy(), q.copy()
            up[:, j] += h
            down[:, j] -= h
            (Ru, pu), (Rd, pd) = self.numpy(up, errors), self.numpy(down, errors)
            dw = Rotation.from_matrix(Ru @ np.swapaxes(Rd, -1, -2)).as_rotvec()
            cols.append(np.concatenate([(pu - pd) / (2 * h), 100 * dw / (2 * h)], axis=1))
        return np.stack(cols, axis=-1)


def _aligned(buf, align):
    return (ctypes.addressof(buf) + align - 1) // align * align


@pytest.fixture(scope="module", params=["ur5", "panda"])
def arm(request, tmp_path_factory):
    return Arm(request.param, tmp_path_factory.mktemp(request.param))


def regular_poses(arm, rng, count):
    """Random joints within the limits whose weighted 6 x n Jacobian (numpy) has its smallest
    singular value above 20 mm: away from wrist, elbow and shoulder singularities."""
    lo = np.array([a.to_internal(a.limits[0]) for a in arm.machine.axes])
    hi = np.array([a.to_internal(a.limits[1]) for a in arm.machine.axes])
    out = np.zeros((0, arm.n))
    while len(out) < count:   # candidates in batches, tested at once; kept in the order drawn
        q = rng.uniform(np.maximum(lo, -math.pi) + BOUND, np.minimum(hi, math.pi) - BOUND, (max(count, 16), arm.n))
        out = np.concatenate([out, q[np.linalg.svd(arm.jacobians(q), compute_uv=False)[:, -1] > 20]])
    return out[:count]


@pytest.mark.slow
def test_away_from_singularities_point_to_1_nm_and_orientation_to_1e_9_rad(arm):
    rng = np.random.default_rng(17)
    q = regular_poses(arm, rng, 2000)
    results = [arm.compensate(c) for c in q]
    status = np.array([r[0] for r in results])
    corrected = np.array([r[1] for r in results])
    assert (status == 0).all(), np.unique(status, return_counts=True)
    point, angle = arm.miss(q, corrected)
    assert point.max() < 1e-6 and angle.max() < 1e-9, (point.max(), angle.max())
    before_point, before_angle = arm.miss(q, q)
    assert before_point.min() > 0.01 and before_angle.min() > 1e-5   # there was something to correct
    assert np.abs(corrected - q).max() < BOUND


def closest_correction(arm, c):
    """Of all joints that put the numpy arm (with its errors) at the nominal pose of command c,
    the one closest to c: the fixed point of q = c + J(q)^+ (J(q)(q - c) - F(q)), F the pose
    residual (point mm, rotation vector x 100 mm), J its Jacobian by central differences."""
    R0, p0 = arm.numpy(c[None])

    def F(q):
        R, p = arm.numpy(q[None], arm.errors)
        return np.concatenate([p[0] - p0[0], 100 * Rotation.from_matrix(R[0] @ R0[0].T).as_rotvec()])

    q = c.copy()
    for _ in range(20):
        J = np.array([(F(q + h) - F(q - h)) / 2e-7 for h in np.eye(arm.n) * 1e-7]).T
        q_next = c + np.linalg.pinv(J) @ (J @ (q - c) - F(q))
        if np.abs(q_next - q).max() < 1e-14:
            break
        q = q_next
    return q_next


@pytest.mark.slow
def test_a_redundant_arm_takes_the_correction_closest_to_the_command(arm):
    """Seven joints, six conditions: the correction is the smallest that holds the pose (the
    step is the least-squares one of the Jacobian at the command: no part along its null
    space), to first order: it differs from the exact closest correction, computed here, by
    about the correction squared (0.2 % of it at these errors; a correction with a part along
    the null space would differ by that part). A six-joint arm's correction is unique."""
    rng = np.random.default_rng(23)
    for c in regular_poses(arm, rng, 20):
        s, corrected, _ = arm.compensate(c)
        assert s == 0
        best = closest_correction(arm, c)
        dq = best - c
        bound = 1e-2 * np.linalg.norm(dq) if arm.n > 6 else 1e-9
        assert np.linalg.norm(corrected - best) < bound, (corrected - c, dq)
        if arm.n > 6:   # not by accident: another correction that holds the pose is much farther
            null = np.linalg.svd(arm.jacobian(c, arm.errors))[2][6:]
            assert np.linalg.norm(null @ dq) < 1e-2 * np.linalg.norm(dq)


@pytest.mark.slow
def test_near_singular_poses_each_correction_within_its_bound_and_the_residual_reported(arm):
    """The wrist straight (UR5 q5 = 0, Panda q6 = 0 is off its limit: q4 near its -4 deg
    stop with q6 near 0 instead), the elbow stretched (UR5 q3 = 0): either corrected (0) or
    the best correction within the bounds (1) with the residual the numpy arm leaves."""
    rng = np.random.default_rng(29)
    q = rng.uniform(-2.5, 2.5, (300, arm.n))
    if arm.machine.name == "ur5":
        q[:100, 4] = rng.normal(0, 1e-3, 100)      # wrist
        q[100:200, 2] = rng.normal(0, 1e-3, 100)   # elbow
        q[200:, 1] = -math.pi / 2                  # shoulder: the wrist centre over the base axis
        q[200:, 2] = rng.normal(0, 1e-3, 100)
        q[200:, 3] = rng.normal(0, 1e-3, 100)
    else:
        q[:, 3] = np.radians(-4) - np.abs(rng.normal(0, 1e-3, 300))
        q[:150, 5] = np.abs(rng.normal(0, 1e-3, 150))
        q[150:, 1] = rng.normal(0, 1e-3, 150)
    results = [arm.compensate(c) for c in q]
    status = np.array([r[0] for r in results])
    corrected = np.array([r[1] for r in results])
    residual = np.array([r[2] for r in results])
    assert set(status) <= {0, 1}, np.unique(status, return_counts=True)
    assert (status == 1).sum() >= 10   # singular poses are there
    assert np.abs(corrected - q).max() <= BOUND + 1e-12
    point, angle = arm.miss(q, corrected)
    ok = status == 0
    assert point[ok].max() < 1e-6 and angle[ok].max() < 1e-9
    # reported: the point residual as the numpy arm leaves it; the orientation's to first order
    assert np.allclose(residual[~ok, 0], point[~ok], rtol=1e-6, atol=1e-9)
    assert np.allclose(residual[~ok, 1], angle[~ok], rtol=1e-2, atol=1e-9)


def test_a_stream_warm_agrees_with_cold_in_the_pose(arm):
    rng = np.random.default_rng(31)
    start = regular_poses(arm, rng, 1)[0]
    path = start + np.outer(np.linspace(0, 0.05, 200), rng.normal(size=arm.n))
    warm = [arm.compensate(c, warm=True) for c in path]
    assert all(s == 0 for s, _, _ in warm)
    point, angle = arm.miss(path, np.array([c for _, c, _ in warm]))
    assert point.max() < 1e-6 and angle.max() < 1e-9
