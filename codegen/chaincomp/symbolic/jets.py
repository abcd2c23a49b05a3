"""The order-k models evaluated numerically: truncated Taylor arithmetic in the error symbols
(jets) carried through the chain, with no symbolic expansion of the product.

A jet is a dict from a monomial of error indices (as in chaincomp.series) to a number or a
numpy array (values broadcast over poses). Each chain element's expression tree gives its jet
at the large values (chaincomp.expressions, chaincomp.jetmath: no sympy); the chain is then
applied to the tool point and direction from the right, multiplying truncated jets, exactly
as the symbolic derivation multiplies truncated series. The cost is linear in the number of
elements, so a six-joint arm evaluates in milliseconds where its expanded formulas take
minutes to derive.
"""

from __future__ import annotations

from ..model.jetmath import lin as _lin, mul_all, sin_cos as _sin_cos
from ..model.machine import ROT_PLANE, Machine, Rotation
from ..model.varying import resolve
from .numeric import _lib, complete
from .orientation import ROWS as ORIENTATION_ROWS, rotation_vector_series


class JetModel:
    """Tool point and direction of ``machine`` to ``order`` in its errors, numerically.

    ``error(values, order)`` gives what TruncatedModel(derive(machine, k)).error gives (the
    terms of degree 1..order at the error values), ``gains(values)`` the first-order
    coefficients (the error gain matrix) at the large values; values as for ExactModel."""

    def __init__(self, machine: Machine, order: int):
        if order < 1:
            raise ValueError("order must be >= 1")
        self.machine, self.order = machine, order
        self.small = [s.name for s in machine.errors]
        self._index = {name: i for i, name in enumerate(self.small)}
        # per element, rightmost first: (kind, axis or None, its expressions)
        self._layout = [("rot", el.axis, (el.expr,)) if isinstance(el, Rotation) else ("trans", None, el.exprs)
                        for el in reversed(machine.chain)]

    def jets(self, values: dict, backend: str = "numpy") -> tuple[list[dict], list[dict] | None]:
        """The jets of the tool point and direction (3 each) at the large values given."""
        p, d, _ = self._all_jets(self._resolved(values), backend)
        return p, d

    def pose_jets(self, values: dict, backend: str = "numpy"):
        """(point, direction or None, ω or None): the jets of every pose component at once."""
        return self._pose_jets(self._resolved(values), backend)

    def _pose_jets(self, values: dict, backend: str):
        p, d, frame = self._all_jets(values, backend)
        if not frame:
            return p, d, None
        k = self.order
        w = rotation_vector_series(frame + [d], k, mul_all,
                                   lambda a, ca, b, cb: _lin(a, float(ca), b, float(cb)),
                                   lambda a, c: {m: float(c) * v for m, v in a.items()})
        return p, d, w

    def _resolved(self, values: dict) -> dict:
        return resolve(complete(self.machine, values))

    def _all_jets(self, values: dict, backend: str):
        """Point, direction and frame jets at ``values`` already completed and resolved."""
        lib, k, m = _lib(backend), self.order, self.machine

        def jet(e):
            return e.jet(values, self._index, k, lib)

        p = [jet(e) for e in m.point]
        d = [jet(e) for e in m.direction] if m.direction else None
        # the frame's x and y axes ride along (the orientation error needs them): constants
        frame = [[{(): c} for c in axis] for axis in m.frame_numbers[:2]] if m.frame_numbers else []
        for kind, axis, exprs in self._layout:
            if kind == "trans":
                for c, e in enumerate(exprs):
                    for mono, v in jet(e).items():
                        p[c][mono] = p[c][mono] + v if mono in p[c] else v
                continue
            angle = jet(exprs[0])
            theta0 = angle.pop((), 0)
            c0, s0 = lib.cos(theta0), lib.sin(theta0)
            if angle:
                s_d, c_d = _sin_cos(angle, k)
                cos_t = _lin(c_d, c0, s_d, -s0)
                sin_t = _lin(c_d, s0, s_d, c0)
            else:
                cos_t, sin_t = {(): c0}, {(): s0}
            i, j = ROT_PLANE[axis]
            for vec in [p] + ([d] if d else []) + frame:
                vi, vj = vec[i], vec[j]
                if set(cos_t) <= {()} and set(sin_t) <= {()}:  # by a large angle only: no jet products
                    c, s = cos_t.get((), 0), sin_t.get((), 0)
                    vec[i], vec[j] = _lin(vi, c, vj, -s), _lin(vi, s, vj, c)
                else:
                    vec[i] = _lin(mul_all(cos_t, vi, k), 1, mul_all(sin_t, vj, k), -1)
                    vec[j] = _lin(mul_all(sin_t, vi, k), 1, mul_all(cos_t, vj, k), 1)
        return p, d, frame

    def _at_errors(self, jet: dict, eps: list, order: int):
        total = 0.0
        for m, c in jet.items():
            if 1 <= len(m) <= order:
                term = c
                for i in m:
                    term = term * eps[i]
                total = total + term
        return total

    def _evaluation(self, values: dict, order: int | None) -> tuple[int, dict, list]:
        """(the order asked, the values completed and resolved, the errors' values)."""
        order = self.order if order is None else order
        self._check_order(order)
        values = self._resolved(values)
        return order, values, [values[s.name] for s in self.machine.errors]

    def _check_order(self, order: int) -> None:
        if not 1 <= order <= self.order:
            raise ValueError(f"order {order}: this model has orders 1..{self.order}")

    def error(self, values: dict, order: int | None = None, backend: str = "numpy"):
        """(point error, direction error or None): the terms of degree 1..order."""
        order, values, eps = self._evaluation(values, order)
        p, d, _ = self._all_jets(values, backend)
        dp = [self._at_errors(j, eps, order) for j in p]
        dd = [self._at_errors(j, eps, order) for j in d] if d else None
        return dp, dd

    def orientation_error(self, values: dict, order: int | None = None, backend: str = "numpy"):
        """ω (rad, 3 components) to degree 1..order with a tool frame, else None."""
        order, values, eps = self._evaluation(values, order)
        w = self._pose_jets(values, backend)[2]
        return [self._at_errors(j, eps, order) for j in w] if w else None

    def pose_error(self, values: dict, order: int | None = None, backend: str = "numpy") -> list:
        """The error of every component of the generated Pose (point, direction, the frame's
        x axis: chaincomp.emit), degrees 1..order, flat."""
        order, values, eps = self._evaluation(values, order)
        p, d, frame = self._all_jets(values, backend)
        vectors = [p] + ([d] if d else []) + frame[:1]
        return [self._at_errors(j, eps, order) for v in vectors for j in v]

    def all_errors(self, values: dict, order: int | None = None, backend: str = "numpy"):
        """(point error, direction error or None, ω or None) of degree 1..order, one pass."""
        order = self.order if order is None else order
        return self.errors_by_order(values, (order,), backend)[order]

    def errors_by_order(self, values: dict, orders: tuple = (1, 2), backend: str = "numpy") -> dict:
        """{order: (point error, direction error or None, ω or None)} for each of ``orders``,
        from one pass of the jets through the chain."""
        for order in orders:
            self._check_order(order)
        values = self._resolved(values)
        eps = [values[s.name] for s in self.machine.errors]
        jets = self._pose_jets(values, backend)
        return {order: tuple(None if v is None else [self._at_errors(j, eps, order) for j in v] for v in jets)
                for order in orders}

    def gains(self, values: dict, backend: str = "numpy") -> dict[str, list]:
        """The first-order error gain matrix at the large values: {dx: [gain per error], ...}."""
        p, d, w = self.pose_jets(values, backend)
        out = {f"d{c}": [j.get((i,), 0.0) for i in range(len(self.small))] for c, j in zip("xyz", p)}
        if d:
            out.update({f"dk{c}": [j.get((i,), 0.0) for i in range(len(self.small))] for c, j in zip("xyz", d)})
        if w:
            out.update({row: [j.get((i,), 0.0) for i in range(len(self.small))] for row, j in zip(ORIENTATION_ROWS, w)})
        return out
