"""The orientation error of a tool frame as a rotation vector.

Convention: R = [x y z] is the tool frame in the chain's base frame (the workpiece), with
the errors (actual) and without (nominal). The orientation error is the rotation vector ω
(rad) with R_actual = exp([ω]×)·R_nominal, i.e. ω = log(R_actual·R_nominalᵀ): a small
rotation about the base frame's x, y and z axes (not the tool's). To first order
δv = ω × v for each axis v of the frame.

As series in the errors (derive, jets): E = (R − R₀)·R₀ᵀ has no term of degree 0
(R₀·R₀ᵀ = I), so log(I + E) = E − E²/2 + E³/3 − … truncates after the order, and ω is the
skew part of it. The same function serves the symbolic ring series and the numeric jets:
only their product and linear combination differ.
"""

from __future__ import annotations

from fractions import Fraction

ROWS = ("wx", "wy", "wz")


def rotation_vector_series(axes: list[list[dict]], k: int, mul, lin, scale) -> list[dict]:
    """ω to order k from the frame's three axes (x, y, z: 3 series each, monomial -> coefficient).

    ``mul(a, b)``: the product truncated at k; ``lin(a, ca, b, cb)``: ca·a + cb·b with
    Fraction coefficients; ``scale(a, c)``: c·a.

    To order 2, ω is the skew part of E alone: E's degree-1 part is [ω₁]× exactly, so the
    degree-2 part of E²/2 is [ω₁]×²/2, symmetric. Skipping E² (and E's diagonal) saves the
    products of the big series of long chains: the framed Panda's order 2 derives in about a
    second instead of minutes."""
    E = [[{} for _ in range(3)] for _ in range(3)]
    for v in axes:
        delta = [{m: c for m, c in comp.items() if m} for comp in v]
        nominal = [{(): comp[()]} if () in comp else {} for comp in v]
        for a in range(3):
            for b in range(3):
                if a != b or k > 2:
                    E[a][b] = lin(E[a][b], 1, mul(delta[a], nominal[b]), 1)
    log = [[dict(e) for e in row] for row in E]
    power = E
    for n in range(3 if k <= 2 else 2, k + 1):
        power = [[_dot(power, E, a, b, mul, lin) for b in range(3)] for a in range(3)]
        sign = -1 if n % 2 == 0 else 1
        log = [[lin(log[a][b], 1, power[a][b], Fraction(sign, n)) for b in range(3)] for a in range(3)]
    return [scale(lin(log[2][1], 1, log[1][2], -1), Fraction(1, 2)),
            scale(lin(log[0][2], 1, log[2][0], -1), Fraction(1, 2)),
            scale(lin(log[1][0], 1, log[0][1], -1), Fraction(1, 2))]


def _dot(A, B, a, b, mul, lin):
    out: dict = {}
    for j in range(3):
        out = lin(out, 1, mul(A[a][j], B[j][b]), 1)
    return out


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
