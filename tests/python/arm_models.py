"""Independent numpy models of the test arms: the truth the tests compare chaincomp against.

Plain numpy; never import chaincomp here. Every function broadcasts: an angle or length may be
a scalar or an array, and the result is (..., 4, 4). Lengths in mm, angles in rad.

Tables, from the makers' published parameters (m there, mm here):
- UR5 (CB3), standard Denavit-Hartenberg, from Universal Robots' "DH parameters for
  calculations of kinematics and dynamics": d1 0.089159, a2 -0.425, a3 -0.39225, d4 0.10915,
  d5 0.09465, d6 0.0823; alpha1 pi/2, alpha4 pi/2, alpha5 -pi/2; theta offsets 0.
- Franka Emika Panda, Craig's modified DH, from Franka's "Robot and interface
  specifications" (FCI documentation): joint 1 d 0.333; 2 alpha -pi/2; 3 d 0.316, alpha pi/2;
  4 a 0.0825, alpha pi/2; 5 a -0.0825, d 0.384, alpha -pi/2; 6 alpha pi/2; 7 a 0.088,
  alpha pi/2; flange d 0.107.
"""

import math

import numpy as np

UR5_D = [89.159, 0.0, 0.0, 109.15, 94.65, 82.3]
UR5_A = [0.0, -425.0, -392.25, 0.0, 0.0, 0.0]
UR5_ALPHA = [math.pi / 2, 0.0, 0.0, math.pi / 2, -math.pi / 2, 0.0]

PANDA_ALPHA = [0.0, -math.pi / 2, math.pi / 2, math.pi / 2, -math.pi / 2, math.pi / 2, math.pi / 2]
PANDA_A = [0.0, 0.0, 0.0, 82.5, -82.5, 0.0, 88.0]
PANDA_D = [333.0, 0.0, 316.0, 0.0, 384.0, 0.0, 0.0]
PANDA_FLANGE = 107.0

# per joint: the names of the theta, d, a, alpha errors ({} = joint number, from 1)
DH_ERRORS = ("dtheta{}", "dd{}", "da{}", "dalpha{}")


def _eye(shape):
    m = np.zeros(shape + (4, 4))
    m[..., 0, 0] = m[..., 1, 1] = m[..., 2, 2] = m[..., 3, 3] = 1.0
    return m


def _rot(i, j, a):
    a = np.asarray(a, float)
    m = _eye(a.shape)
    c, s = np.cos(a), np.sin(a)
    m[..., i, i], m[..., i, j], m[..., j, i], m[..., j, j] = c, -s, s, c
    return m


def rx(a):
    return _rot(1, 2, a)


def ry(a):
    return _rot(2, 0, a)


def rz(a):
    return _rot(0, 1, a)


def tr(x, y, z):
    x, y, z = np.broadcast_arrays(*(np.asarray(v, float) for v in (x, y, z)))
    m = _eye(x.shape)
    m[..., 0, 3], m[..., 1, 3], m[..., 2, 3] = x, y, z
    return m


def rot(axis, angle):
    """Right-handed rotation about "x", "y" or "z"."""
    return {"x": rx, "y": ry, "z": rz}[axis](angle)


def trans(axis, length):
    """Translation along "x", "y" or "z"."""
    return tr(*(length if axis == c else 0.0 for c in "xyz"))


def block(dx, dy, dz, ex, ey, ez):
    """A 6-DOF error block of order txyz: T(dx, dy, dz) Rx(ex) Ry(ey) Rz(ez)."""
    return tr(dx, dy, dz) @ rx(ex) @ ry(ey) @ rz(ez)


def std_link(theta, d, a, alpha):
    """Standard DH link Rz(theta) Tz(d) Tx(a) Rx(alpha), written out as the textbook's matrix."""
    theta, d, a, alpha = np.broadcast_arrays(*(np.asarray(v, float) for v in (theta, d, a, alpha)))
    ct, st, ca, sa = np.cos(theta), np.sin(theta), np.cos(alpha), np.sin(alpha)
    m = _eye(theta.shape)
    m[..., 0, :3] = np.stack([ct, -st * ca, st * sa], -1)
    m[..., 1, :3] = np.stack([st, ct * ca, -ct * sa], -1)
    m[..., 2, 1], m[..., 2, 2] = sa, ca
    m[..., 0, 3], m[..., 1, 3], m[..., 2, 3] = a * ct, a * st, d
    return m


def mod_link(alpha, a, theta, d):
    """Craig's modified DH link Rx(alpha) Tx(a) Rz(theta) Tz(d), the textbook's matrix."""
    alpha, a, theta, d = np.broadcast_arrays(*(np.asarray(v, float) for v in (alpha, a, theta, d)))
    ct, st, ca, sa = np.cos(theta), np.sin(theta), np.cos(alpha), np.sin(alpha)
    m = _eye(theta.shape)
    m[..., 0, :3] = np.stack([ct, -st, np.zeros_like(ct)], -1)
    m[..., 1, :3] = np.stack([st * ca, ct * ca, -sa], -1)
    m[..., 2, :3] = np.stack([st * sa, ct * sa, ca], -1)
    m[..., 0, 3], m[..., 1, 3], m[..., 2, 3] = a, -d * sa, d * ca
    return m


def _getter(e):
    e = e or {}
    return lambda pattern, n: e.get(pattern.format(n), 0.0)


def dh_chain(q, d, a, alpha, e=None, names=DH_ERRORS, betas=()):
    """Product of standard DH links; q: one angle (or array of them) per joint; e: error name
    -> value, missing errors 0; betas: joints followed by Hayati's Ry(dbeta<joint>)."""
    g = _getter(e)
    t = np.eye(4)
    for i in range(len(d)):
        n = i + 1
        t = t @ std_link(q[i] + g(names[0], n), d[i] + g(names[1], n), a[i] + g(names[2], n),
                         alpha[i] + g(names[3], n))
        if n in betas:
            t = t @ ry(g("dbeta{}", n))
    return t


def mdh_chain(q, alpha, a, d, e=None, names=DH_ERRORS, betas=()):
    """Product of Craig's modified DH links, with errors and betas as in dh_chain."""
    g = _getter(e)
    t = np.eye(4)
    for i in range(len(d)):
        n = i + 1
        t = t @ mod_link(alpha[i] + g(names[3], n), a[i] + g(names[2], n), q[i] + g(names[0], n),
                         d[i] + g(names[1], n))
        if n in betas:
            t = t @ ry(g("dbeta{}", n))
    return t


def ur5(q, e=None, names=DH_ERRORS, betas=()):
    """The UR5's flange frame (base to flange), q: six joint angles (rad)."""
    return dh_chain(q, UR5_D, UR5_A, UR5_ALPHA, e, names, betas)


def panda(q, e=None, names=DH_ERRORS):
    """The Panda's flange frame (base to flange, 107 mm past joint 7), q: seven joint angles."""
    return mdh_chain(q, PANDA_ALPHA, PANDA_A, PANDA_D, e, names) @ tr(0.0, 0.0, PANDA_FLANGE)


# The arms with the tool frames the tests give them (tests/python/helpers.py writes their files)
UR5_FRAME = np.array([[1, -1, 0], [1, 1, 0], [0, 0, math.sqrt(2)]]) / math.sqrt(2)   # columns x, y, z


UR5_POINT = np.array([40.0, 0.0, 100.0])



def ur5_frame(q, e=None):
    """(R, p): the tool frame (N x 3 x 3, columns x, y, z) and point (N x 3) of the UR5 variant."""
    e = e or {}
    g = lambda name: e.get(name, 0.0)  # noqa: E731
    t = np.broadcast_to(np.eye(4), (len(q), 4, 4))
    for j in range(6):
        n = j + 1
        t = t @ rot("z", q[:, j] + g(f"dtheta{n}")) @ trans("z", UR5_D[j] + g(f"dd{n}")) \
            @ trans("x", UR5_A[j] + g(f"da{n}")) @ rot("x", UR5_ALPHA[j] + g(f"dalpha{n}"))
        if n in (2, 3):
            t = t @ rot("y", g(f"dbeta{n}"))
    return t[:, :3, :3] @ UR5_FRAME, t[:, :3, :3] @ UR5_POINT + t[:, :3, 3]


PANDA_FRAME = np.array([[0, 1, 0], [0, 0, 1], [1, 0, 0.0]])   # columns x, y, z in the flange frame


PANDA_POINT = np.array([40.0, 0.0, 103.4])



def panda_frame(q, e=None):
    """(R, p): the Panda variant's tool frame (N x 3 x 3) and point (N x 3); q: N x 7 (rad)."""
    t = panda(q.T, e)
    return t[:, :3, :3] @ PANDA_FRAME, t[:, :3, :3] @ PANDA_POINT + t[:, :3, 3]
