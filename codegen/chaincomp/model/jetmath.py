"""Truncated Taylor arithmetic on jets, numerically: a jet is a dict from a monomial of error
indices (a sorted tuple, as in chaincomp.series; () the constant term) to a number, numpy
array or mpmath number. Products drop terms of degree above k; functions of a jet are the
Taylor series of the function at the jet's constant term composed with the rest."""

from __future__ import annotations

import math
from fractions import Fraction


def mul_all(a: dict, b: dict, k: int) -> dict:
    """Product of two jets to degree k, keeping every coefficient (numpy arrays cannot be
    tested for zero)."""
    out: dict = {}
    for ma, ca in a.items():
        room = k - len(ma)
        for mb, cb in b.items():
            if len(mb) > room:
                continue
            m = tuple(sorted(ma + mb)) if (ma and mb) else (ma or mb)
            c = ca * cb
            out[m] = out[m] + c if m in out else c
    return out


def lin(a: dict, ca, b: dict, cb) -> dict:
    """ca·a + cb·b for jets a, b and scalars (or arrays) ca, cb."""
    out = {m: ca * v for m, v in a.items()}
    for m, v in b.items():
        out[m] = out[m] + cb * v if m in out else cb * v
    return out


def split(a: dict):
    """(the constant term, the rest)."""
    return a.get((), 0), {m: v for m, v in a.items() if m}


def compose(coeffs: list, delta: dict, k: int) -> dict:
    """Σ coeffs[n]·delta^n for a jet ``delta`` without constant term."""
    out = {(): coeffs[0]}
    power: dict = {(): 1}
    for n in range(1, k + 1):
        power = mul_all(power, delta, k)
        if not power:
            break
        out = lin(out, 1, power, coeffs[n])
    return out


def _times(x, q: Fraction):
    return x * q.numerator / q.denominator if q.denominator != 1 else x * q.numerator


def power(a: dict, p: Fraction, k: int, pow_) -> dict:
    """a^p (p a constant fraction; pow_(number, fraction) raises a number): natural powers by
    products, others by the generalised binomial series about a's constant term."""
    p = Fraction(p)
    a0, delta = split(a)
    if not delta:
        return {(): pow_(a0, p)}
    if p.denominator == 1 and p >= 0:
        out: dict = {(): 1}
        for _ in range(int(p)):
            out = mul_all(out, a, k)
        return out
    coeffs, binom = [], Fraction(1)
    for n in range(k + 1):
        coeffs.append(_times(pow_(a0, p - n), binom))
        binom = binom * (p - n) / (n + 1)
    return compose(coeffs, delta, k)


def sin_cos(delta: dict, k: int) -> tuple[dict, dict]:
    """sin and cos of a jet without constant term, to order k."""
    s: dict = {}
    c: dict = {(): 1}
    pw: dict = {(): 1}
    for j in range(1, k + 1):
        pw = mul_all(pw, delta, k)
        if not pw:
            break
        sign = -1 if (j // 2) % 2 else 1
        target = s if j % 2 else c
        for m, v in pw.items():
            term = sign * v / math.factorial(j)
            target[m] = target[m] + term if m in target else term
    return s, c


def sin_cos_at(a: dict, k: int, sin, cos) -> tuple[dict, dict]:
    """sin and cos of a jet: sin(a0 + d) = sin a0·cos d + cos a0·sin d, and so on."""
    a0, delta = split(a)
    s0, c0 = sin(a0), cos(a0)
    if not delta:
        return {(): s0}, {(): c0}
    s_d, c_d = sin_cos(delta, k)
    return lin(c_d, s0, s_d, c0), lin(c_d, c0, s_d, -s0)


# The derivative of each, as u(t)^p with u a quadratic in t about the constant term a0.
_DERIVATIVE = {"atan": (lambda a0: (1 + a0 * a0, 2 * a0, 1), Fraction(-1), 1),
               "asin": (lambda a0: (1 - a0 * a0, -2 * a0, -1), Fraction(-1, 2), 1),
               "acos": (lambda a0: (1 - a0 * a0, -2 * a0, -1), Fraction(-1, 2), -1)}


def inverse_trig(name: str, a: dict, k: int, f, pow_) -> dict:
    """atan, asin or acos of a jet: the Taylor coefficients of f at a0, from the series of its
    derivative u(t)^p (Miller's recurrence for a power of a series) integrated term by term."""
    a0, delta = split(a)
    if not delta:
        return {(): f(a0)}
    quad, p, sign = _DERIVATIVE[name]
    u = quad(a0)
    w = [pow_(u[0], p)]
    for n in range(1, k):
        total = 0
        for j in range(1, min(n, 2) + 1):
            total = total + _times(u[j] * w[n - j], (p + 1) * j - n)
        w.append(total / (n * u[0]))
    return compose([f(a0)] + [sign * w[n - 1] / n for n in range(1, k + 1)], delta, k)


def atan2(y: dict, x: dict, k: int, atan2_, pow_) -> dict:
    """atan2(y, x) = atan2(y0, x0) + atan(cross/dot), cross = x0·y − y0·x (no constant term),
    dot = x0·x + y0·y: the angle of (x + iy)·conj(x0 + i·y0)."""
    y0, x0 = y.get((), 0), x.get((), 0)
    base = atan2_(y0, x0)
    if not (split(y)[1] or split(x)[1]):
        return {(): base}
    cross = split(lin(y, x0, x, -y0))[1]
    dot = lin(x, x0, y, y0)
    t = mul_all(cross, power(dot, Fraction(-1), k, pow_), k)
    out = inverse_trig("atan", t, k, lambda v: 0 * v, pow_)
    out[()] = out.get((), 0) + base
    return out
