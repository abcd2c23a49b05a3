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

    # Pass 2: into the coefficient ring; apply the chain from the right.
    R = atoms.make_ring()
    one = R.one

    def to_ring(series):
        return {m: R.from_expr(c) if c != 0 else R.zero for m, c in series.items() if c != 0}

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

    prog = Progress(f"derive {machine.name} (order {k})", progress)
    n = len(steps)
    for idx, step in enumerate(reversed(steps)):
        if step[0] == "rot":
            _, axis, cos0, sin0, delta = step
            s_d, c_d = S.sin_cos(to_ring(delta), k, one)
            c0, s0 = {(): R.from_expr(cos0)}, {(): R.from_expr(sin0)}
            c0 = {m: v for m, v in c0.items() if v}
            s0 = {m: v for m, v in s0.items() if v}
            cos_t = S.add(S.mul(c0, c_d, k), S.mul(s0, s_d, k), -1)
            sin_t = S.add(S.mul(s0, c_d, k), S.mul(c0, s_d, k))
            i, j = ROT_PLANE[axis]
            for vec, _w in vectors:
                vi, vj = vec[i], vec[j]
                vec[i] = S.add(S.mul(cos_t, vi, k), S.mul(sin_t, vj, k), -1)
                vec[j] = S.add(S.mul(sin_t, vi, k), S.mul(cos_t, vj, k))
        else:
            t = [to_ring(v) for v in step[1]]
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


def _scale(a: dict, c) -> dict:
    """c·a for a ring series and a Fraction c."""
    if c == 1:
        return a
    q = S.QQ(c.numerator, c.denominator)
    return {m: v * q for m, v in a.items()}
