"""The orientation error of a tool frame as a rotation vector.

Convention: R = [x y z] is the tool frame in the chain's base frame (the workpiece), with
the errors (actual) and without (nominal). The orientation error is the rotation vector ω
(rad) with R_actual = exp([ω]×)·R_nominal, i.e. ω = log(R_actual·R_nominalᵀ): a small
rotation about the base frame's x, y and z axes (not the tool's). To first order
δv = ω × v for each axis v of the frame.

As series in the errors (derive, jets): s, the skew part of E = (R − R₀)·R₀ᵀ, is sin θ
times ω's axis (θ = |ω|), so ω = s·arcsin|s|/|s|, a series in n = s·s that truncates after
the order (rotation_vector_series). The same function serves the symbolic ring series and
the numeric jets: only their product and linear combination differ.
"""

from __future__ import annotations

import math
from fractions import Fraction

import numpy as np

ROWS = ("wx", "wy", "wz")


def rotation_vector_series(axes: list[list[dict]], k: int, mul, lin, scale, reduce=None) -> list[dict]:
    """ω to order k from the frame's three axes (x, y, z: 3 series each, monomial -> coefficient).

    ``mul(a, b, order)``: the product truncated at ``order``; ``lin(a, ca, b, cb)``: ca·a + cb·b
    with Fraction coefficients; ``scale(a, c)``: c·a; ``reduce(a)``: optional, the same
    function of the errors in a shorter form (the symbolic series modulo sin² + cos² = 1),
    taken for the factors of the terms of degree 3 and above.

    The skew part of R·R₀ᵀ = exp([ω]×) is sin θ·u (θ = |ω|, u its axis), so with
    s = vec(skew E), E = (R − R₀)·R₀ᵀ (the same skew part: I is symmetric), |s| = sin θ and
    ω = s·arcsin(|s|)/|s| = s·(1 + n/6 + 3n²/40 + …), n = s·s. n starts at degree 2: to order
    2, ω is s alone; to order 3, ω = s + n₂·s₁/6. This needs only E's off-diagonal entries (each
    axis' error times a nominal component, no products of series) and n's low degrees: the
    products of log(I + E) = E − E²/2 + E³/3 − … took the framed UR5's order 3 past 15 minutes.
    The same function of the errors as the log series (both are its Taylor series), so the
    same values; as polynomials in sin and cos of the axes they may differ by sin² + cos² − 1."""
    def entry(a: int, b: int) -> dict:
        out: dict = {}
        for v in axes:
            delta = {m: c for m, c in v[a].items() if m}
            nominal = {(): v[b][()]} if () in v[b] else {}
            out = lin(out, 1, mul(delta, nominal, k), 1)
        return out
    s = [scale(lin(entry(2, 1), 1, entry(1, 2), -1), Fraction(1, 2)),
         scale(lin(entry(0, 2), 1, entry(2, 0), -1), Fraction(1, 2)),
         scale(lin(entry(1, 0), 1, entry(0, 1), -1), Fraction(1, 2))]
    if k < 3:
        return s

    def low(a: dict, degree: int) -> dict:
        part = {m: c for m, c in a.items() if len(m) <= degree}
        return reduce(part) if reduce is not None else part
    n: dict = {}
    for si in s:   # n = s·s to degree k - 1 (ω takes it times s, of degree 1 at least)
        part = low(si, k - 2)
        n = lin(n, 1, mul(part, part, k - 1), 1)
    if reduce is not None:
        n = reduce(n)
    omega = s
    term = s
    for j in range(1, (k - 1) // 2 + 1):
        # n^j·s, and arcsin(x)/x = Σ (2j)!/(4^j (j!)² (2j + 1)) x^(2j)
        term = [mul(n, low(t, k - 2), k) for t in term]
        if reduce is not None:
            term = [reduce(t) for t in term]
        c = Fraction(math.factorial(2 * j), 4 ** j * math.factorial(j) ** 2 * (2 * j + 1))
        omega = [lin(w, 1, t, c) for w, t in zip(omega, term)]
    return omega


def cross(u, v):
    return [u[1] * v[2] - u[2] * v[1], u[2] * v[0] - u[0] * v[2], u[0] * v[1] - u[1] * v[0]]


def rotation_vector(actual: tuple, nominal: tuple, lib=None):
    """ω = log(R_actual·R_nominalᵀ) exactly, from each frame's (z, x) axes (numbers or
    numpy arrays, which broadcast). ``lib``: numpy (default) or mpmath."""
    if lib is None:
        import numpy as lib
    (za, xa), (zn, xn) = actual, nominal
    ya, yn = cross(za, xa), cross(zn, xn)
    # M = Σ_i a_i n_iᵀ over the three axes
    M = [[xa[r] * xn[c] + ya[r] * yn[c] + za[r] * zn[c] for c in range(3)] for r in range(3)]
    s = [(M[2][1] - M[1][2]) / 2, (M[0][2] - M[2][0]) / 2, (M[1][0] - M[0][1]) / 2]  # sin θ · u
    cos_t = (M[0][0] + M[1][1] + M[2][2] - 1) / 2
    sin_t = lib.sqrt(s[0] ** 2 + s[1] ** 2 + s[2] ** 2)
    theta = lib.atan2(sin_t, cos_t) if hasattr(lib, "atan2") else lib.arctan2(sin_t, cos_t)
    # θ / sin θ, by its series where sin θ is tiny (1 + θ²/6 to 1e-17 below 1e-4)
    if lib.__name__ == "numpy":
        tiny = sin_t < 1e-4
        ratio = lib.where(tiny, 1 + theta ** 2 / 6, theta / lib.where(tiny, 1.0, sin_t))
    else:
        ratio = 1 + theta ** 2 / 6 if sin_t < 1e-4 else theta / sin_t
    return [ratio * c for c in s]


def angle_between(a, b):
    """Angle (rad) between vectors a and b (along the last axis), stable for tiny angles."""
    a, b = np.asarray(a, float), np.asarray(b, float)
    return np.arctan2(np.linalg.norm(np.cross(a, b), axis=-1), np.sum(a * b, axis=-1))
