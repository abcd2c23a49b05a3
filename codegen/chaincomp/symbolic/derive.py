"""Derivation of a machine's tool pose as truncated series in its error symbols.

The chain is applied to the tool point (and tool direction) from the right, one
elementary transform at a time, multiplying truncated series: never the full product
expanded and trimmed afterwards (design §5).
"""

from __future__ import annotations

import sys
import time
from dataclasses import dataclass, field

import sympy as sp

from ..errors import ChaincompError
from ..model.expressions import sin_cos
from ..model.machine import ROT_PLANE, Machine, Rotation
from . import series as S
from .orientation import ROWS as ORIENTATION_ROWS, rotation_vector_series

COMPONENTS = ("x", "y", "z")

# Up to this many terms in the expanded series (orders 1..k, every pose component) a machine
# is a short chain: generate evaluates the expanded forms and budget lambdifies them; beyond
# it they propagate through the chain instead (chaincomp.straightline, chaincomp.jets). The
# expansion grows with every rotation (a UR5 with its twists as parameters: 32 883 terms,
# minutes to derive). The machine tools of configs/machines have at most 1239 terms
# (five_axis_ac) and keep the code their tests and figures were made with; from the bundled
# UR5 (4402 terms) on, the straight-line code is smaller in every function but the exact pose
# (its gain matrix 754 operations instead of 1893, error_order2 648 instead of 5493; generated
# in 0.5 s instead of 17 s).
EXPANDED_TERMS_LIMIT = 2000

# At most this many terms in every series derive() holds after any element, counted before
# expanding (_predicted_terms: each product as if no terms merged, so at least the true count).
# Modest expressions followed by many rotations with errors multiply the terms element by element
# (12 rotations: 236 s, 2.5 GB); past the bound derive refuses at the element's line. Calibrated
# (docs/reference/errors.md; tests/python/symbolic/test_chain_growth.py) on the bundled machines and
# the example-robot-data arms at orders 1-2 and the Panda at 3-4: the largest count is xArm7's at
# order 2, 546 143 (true 501 852: derive 26 s, the derive verb 56 s and 1.2 GB), so 1.46x room.
EXPANSION_LIMIT = 800_000


class Progress:
    """Reports steps on stderr, but only once the work has taken longer than a second."""

    def __init__(self, what: str, enabled: bool = True, after: float = 1.0):
        self.what, self.enabled, self.after = what, enabled, after
        self.start = time.monotonic()
        self.spoke = False

    def step(self, message: str) -> None:
        elapsed = time.monotonic() - self.start
        if self.enabled and elapsed > self.after:
            print(f"{self.what}: {message} ({elapsed:.1f} s)", file=sys.stderr, flush=True)
            self.spoke = True

    def done(self) -> None:
        if self.spoke:
            print(f"{self.what}: done in {time.monotonic() - self.start:.1f} s", file=sys.stderr, flush=True)


@dataclass
class Derivation:
    """The tool point and direction of a machine as order-k series in its errors."""

    machine: Machine
    order: int
    small: list[sp.Symbol]
    point: list[dict]                  # 3 series
    direction: list[dict] | None       # 3 series, or None
    columns: list[list[dict]] | None   # the 4x4 HTM's columns, when asked for
    _restore: dict = field(repr=False, default_factory=dict)
    # With a tool frame: its x axis (3 series) and the orientation error ω (3 series without a
    # term of degree 0: chaincomp.orientation), else None.
    reference: list[dict] | None = None
    orientation: list[dict] | None = None

    # ---- conversion to sympy
    def expr(self, poly) -> sp.Expr:
        """A ring coefficient as a sympy expression in the machine's symbols."""
        return poly.as_expr().xreplace(self._restore) if poly else sp.Integer(0)

    def degree_part(self, s: dict, degree: int) -> sp.Expr:
        """Sum of the terms of exactly ``degree`` in the small symbols."""
        terms = []
        for mono, coeff in s.items():
            if len(mono) == degree:
                terms.append(self.expr(coeff) * sp.Mul(*[self.small[i] for i in mono]))
        return sp.Add(*terms)

    def nominal(self, s: dict) -> sp.Expr:
        return self.degree_part(s, 0)

    def error(self, s: dict, order: int | None = None) -> sp.Expr:
        """Truncated error: all terms of degree 1..order (default: the derivation's order)."""
        order = self.order if order is None else order
        if order > self.order:
            raise ValueError(f"derived to order {self.order}, asked for order {order}")
        return sp.Add(*[self.degree_part(s, d) for d in range(1, order + 1)])

    def gain(self, s: dict) -> list[sp.Expr]:
        """First-order coefficient of each error symbol (a row of the error gain matrix)."""
        return [self.expr(s.get((i,), 0)) for i in range(len(self.small))]

    def gain_matrix(self) -> dict[str, list[sp.Expr]]:
        out = {f"d{c}": self.gain(self.point[i]) for i, c in enumerate(COMPONENTS)}
        if self.direction is not None:
            for i, c in enumerate(COMPONENTS):
                out[f"dk{c}"] = self.gain(self.direction[i])
        if self.orientation is not None:
            for row, s in zip(ORIENTATION_ROWS, self.orientation):
                out[row] = self.gain(s)
        return out

    def term_count(self, s: dict, degree: int) -> int:
        return sum(len(c.terms()) for m, c in s.items() if len(m) == degree)


def _terms(vectors) -> int:
    return sum(len(c) for vec, _ in vectors for s in vec for m, c in s.items() if m)


def derive(machine: Machine, order: int = 1, htm: bool = False, progress: bool = False,
           max_terms: int | None = None) -> Derivation | None:
    """Derive the tool pose of ``machine`` to ``order`` in its error symbols. With ``max_terms``:
    None as soon as the point and direction hold more terms of degree 1..order than that
    (the expansion of a long chain grows with every rotation; this stops it early)."""
    if order < 0:
        raise ValueError("order must be >= 0")
    k = order
    small, atoms, R, steps, vectors, n_tool = _prepare(machine, k, htm)
    one = R.one
    dir0, frame = machine.tool_direction, machine.tool_frame

    over = next(((el, n) for el, n in _predicted_terms(machine, steps, vectors, k) if n > EXPANSION_LIMIT), None)
    if over is not None:
        if max_terms is not None:   # the caller has a way for long chains
            return None
        element, size = over
        raise ChaincompError(
            f"the tool pose to order {k} could expand to up to {float(size):.3g} terms by this element, applying "
            f"the chain from the tool (at most {EXPANSION_LIMIT:g}; every rotation with errors multiplies them): "
            f"use fewer rotations with errors, fewer symbols in their angles, or a lower --order",
            machine.file, element.line or None, "loop" if machine.workpiece_chain else "chain")

    # Apply the chain from the right.
    prog = Progress(f"derive {machine.name} (order {k})", progress)
    n = len(steps)
    for idx, step in enumerate(reversed(steps)):
        if step[0] == "rot":
            _, axis, cos0, sin0, delta = step
            s_d, c_d = S.sin_cos(delta, k, one)
            c0 = {(): cos0} if cos0 else {}
            s0 = {(): sin0} if sin0 else {}
            cos_t = S.add(S.mul(c0, c_d, k), S.mul(s0, s_d, k), -1)
            sin_t = S.add(S.mul(s0, c_d, k), S.mul(c0, s_d, k))
            i, j = ROT_PLANE[axis]
            for vec, _w in vectors:
                vi, vj = vec[i], vec[j]
                vec[i] = S.add(S.mul(cos_t, vi, k), S.mul(sin_t, vj, k), -1)
                vec[j] = S.add(S.mul(sin_t, vi, k), S.mul(cos_t, vj, k))
        else:
            t = step[1]
            for vec, w in vectors:
                if w:
                    for c in range(3):
                        vec[c] = S.add(vec[c], t[c])
        if max_terms is not None and _terms(vectors[:n_tool]) > max_terms:
            return None
        prog.step(f"element {n - idx}/{n}")

    point = vectors[0][0]
    direction = vectors[1][0] if dir0 else None
    columns = [v for v, _ in vectors[-4:]] if htm else None
    reference = orientation = None
    if frame:
        prog.step("orientation error")
        x, y = vectors[n_tool][0], vectors[n_tool + 1][0]
        reference = x
        orientation = rotation_vector_series(
            [x, y, direction], k, S.mul,
            lambda a, ca, b, cb: S.add(_scale(a, ca), _scale(b, cb)), _scale,
            S.pythagoras(R, atoms.restore()))
    prog.done()
    return Derivation(machine, k, small, point, direction, columns, atoms.restore(), reference, orientation)


def _prepare(machine: Machine, k: int, htm: bool):
    """The chain's elements and the vectors it turns, as series in the coefficient ring:
    (small symbols, atoms, ring, steps, vectors, how many of the vectors are the point and
    direction)."""
    small = [s.sym for s in machine.errors]
    large = [s.sym for s in machine.symbols if not s.small]
    atoms = S.Atoms(large)
    zero = {s: 0 for s in small}

    # Pass 1: every matrix entry as Taylor coefficients (sympy), atomized.
    def taylor(e):
        return {m: atoms.atomize(c) for m, c in S.taylor(e, small, k).items()}

    steps = []
    for el in machine.chain:
        if isinstance(el, Rotation):
            theta0 = el.angle.xreplace(zero)
            delta = taylor(el.angle - theta0)
            delta.pop((), None)
            sin0, cos0 = sin_cos(theta0)
            steps.append(("rot", el.axis, atoms.atomize(cos0), atoms.atomize(sin0), delta))
        else:
            steps.append(("trans", [taylor(v) for v in el.vector]))
    point0 = [taylor(v) for v in machine.tool_point]
    dir0 = [taylor(v) for v in machine.tool_direction] if machine.tool_direction else None
    frame = machine.tool_frame
    frame0 = [[taylor(v) for v in axis] for axis in frame[:2]] if frame else []   # its x and y axes

    # Pass 2: into the coefficient ring.
    R = atoms.make_ring()
    one = R.one

    def to_ring(series):
        return {m: R.from_expr(c) if c != 0 else R.zero for m, c in series.items() if c != 0}

    steps = [("rot", st[1], R.from_expr(st[2]), R.from_expr(st[3]), to_ring(st[4])) if st[0] == "rot"
             else ("trans", [to_ring(v) for v in st[1]]) for st in steps]

    vectors: list[tuple[list[dict], int]] = [([to_ring(v) for v in point0], 1)]
    if dir0:
        vectors.append(([to_ring(v) for v in dir0], 0))
    n_tool = len(vectors)   # point and direction: the terms max_terms counts
    for axis in frame0:   # ω needs all three axes of the frame
        vectors.append(([to_ring(v) for v in axis], 0))
    if htm:
        for i in range(3):
            vectors.append(([{(): one} if j == i else {} for j in range(3)], 0))
        vectors.append(([{}, {}, {}], 1))
    return small, atoms, R, steps, vectors, n_tool


def expansion_peak(machine: Machine, order: int) -> int:
    """The most terms derive(machine, order) could hold after any element (what EXPANSION_LIMIT
    bounds), without expanding: for calibrating the bound and for tests."""
    _, _, _, steps, vectors, _ = _prepare(machine, order, False)
    return max((n for _, n in _predicted_terms(machine, steps, vectors, order)), default=0)


def _sizes(series: dict, k: int) -> list[int]:
    """The terms of a ring series by degree 0..k."""
    out = [0] * (k + 1)
    for m, c in series.items():
        out[len(m)] += len(c)
    return out


def _mul_sizes(a: list[int], b: list[int]) -> list[int]:
    """At most the terms of a product by degree: each pair of terms gives one, none merge."""
    return [sum(a[i] * b[d - i] for i in range(d + 1)) for d in range(len(a))]


def _add_sizes(a: list[int], b: list[int]) -> list[int]:
    return [x + y for x, y in zip(a, b)]


def _predicted_terms(machine: Machine, steps: list, vectors: list, k: int):
    """For each element as derive() applies it (from the tool end): (the element, at most how many
    terms every series then holds). Counts, not polynomials: the terms of each series by degree,
    each product counted as if no two of its terms merged (an upper bound, which rotations about
    distinct angles, the growth that costs, reach). Microseconds per element, before expanding."""
    sizes = [[_sizes(s, k) for s in vec] for vec, _ in vectors]
    one = [1] + [0] * k
    elements = machine.chain
    for el, step in zip(reversed(elements), reversed(steps)):
        if step[0] == "rot":
            _, axis, cos0, sin0, delta = step
            d = _sizes(delta, k)
            s_d, c_d, power = [0] * (k + 1), one, one
            for j in range(1, k + 1):
                power = _mul_sizes(power, d)
                if j % 2:
                    s_d = _add_sizes(s_d, power)
                else:
                    c_d = _add_sizes(c_d, power)
            c0, s0 = [len(cos0)] + [0] * k, [len(sin0)] + [0] * k
            cos_t = _add_sizes(_mul_sizes(c0, c_d), _mul_sizes(s0, s_d))
            sin_t = _add_sizes(_mul_sizes(s0, c_d), _mul_sizes(c0, s_d))
            i, j = ROT_PLANE[axis]
            for vec in sizes:
                vi, vj = vec[i], vec[j]
                vec[i] = _add_sizes(_mul_sizes(cos_t, vi), _mul_sizes(sin_t, vj))
                vec[j] = _add_sizes(_mul_sizes(sin_t, vi), _mul_sizes(cos_t, vj))
        else:
            t = [_sizes(v, k) for v in step[1]]
            for vec, (_, w) in zip(sizes, vectors):
                if w:
                    for c in range(3):
                        vec[c] = _add_sizes(vec[c], t[c])
        yield el, sum(sum(s) for vec in sizes for s in vec)


def _scale(a: dict, c) -> dict:
    """c·a for a ring series and a Fraction c."""
    if c == 1:
        return a
    q = S.QQ(c.numerator, c.denominator)
    return {m: v * q for m, v in a.items()}
