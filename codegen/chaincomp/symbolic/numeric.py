"""Numeric evaluation: the exact model (the chain multiplied without truncation) and
the truncated models, with numpy (arrays broadcast) or mpmath (high precision). Errors that
vary along an axis (chaincomp.varying) are evaluated at the axis values given. The exact
model evaluates the machine's expression trees directly: no sympy."""

from __future__ import annotations

from typing import TYPE_CHECKING

from ..errors import ChaincompError
from ..model.machine import ROT_PLANE, Machine, Rotation
from ..model.varying import resolve
from .orientation import rotation_vector

if TYPE_CHECKING:
    from .derive import Derivation

BACKENDS = ("numpy", "mpmath")


def _lib(backend: str):
    if backend == "numpy":
        import numpy as lib
    elif backend == "mpmath":
        import mpmath as lib
    else:
        raise ValueError(f"unknown backend {backend!r}")
    return lib


def complete(machine: Machine, values: dict) -> dict:
    """``values`` (internal units: mm, rad) with every symbol the caller left out filled in:
    constants at their nominal value, errors at zero. Axes must be given; a name the machine
    does not declare is an error (a misspelt name would otherwise be ignored silently)."""
    unknown = sorted(set(values) - {s.name for s in machine.symbols})
    if unknown:
        raise ChaincompError(f"unknown symbol {unknown[0]!r} for machine {machine.name!r} "
                             f"(known: {', '.join(s.name for s in machine.symbols)})")
    out = dict(values)
    for s in machine.symbols:
        if s.name in out:
            continue
        if s.role == "axis":
            raise ChaincompError(f"no value for axis {s.name!r} (internal units: "
                                 f"{'rad' if s.unit.kind == 'angle' else 'mm'})")
        out[s.name] = 0.0 if s.role == "error" else s.to_internal(s.nominal)
    return out


class ExactModel:
    """Tool point and direction from the chain, multiplied numerically, no truncation.

    ``values`` map symbol names to internal values (mm, rad; numbers or numpy arrays, which
    broadcast); constants left out take their nominal value and errors zero."""

    def __init__(self, machine: Machine):
        self.machine = machine
        self._cache: dict[str, tuple] = {}

    def _compiled(self, backend: str):
        """Each element's expressions as functions of the values (rightmost element first), and
        the tool point's, direction's and frame x axis's."""
        if backend not in self._cache:
            lib = _lib(backend)
            steps = []
            for el in reversed(self.machine.chain):
                if isinstance(el, Rotation):
                    steps.append(("rot", ROT_PLANE[el.axis], el.expr.function(lib)))
                else:
                    steps.append(("trans", [e.function(lib) for e in el.exprs]))
            m = self.machine
            vectors = [None if v is None else [e.function(lib) for e in v] for v in (m.point, m.direction, m.reference)]
            self._cache[backend] = (steps, vectors)
        return self._cache[backend]

    def pose(self, values: dict, backend: str = "numpy"):
        """(point, direction or None) for ``values`` (internal units, every symbol by name)."""
        p, d, _ = self.frame(values, backend)
        return p, d

    def frame(self, values: dict, backend: str = "numpy"):
        """(point, direction or None, the tool frame's x axis or None) for ``values``."""
        lib = _lib(backend)
        steps, fns = self._compiled(backend)
        values = resolve(complete(self.machine, values))
        p, d, x = (None if v is None else [f(values) for f in v] for v in fns)
        vectors = [v for v in (p, d, x) if v is not None]
        for step in steps:
            if step[0] == "rot":
                (i, j), angle = step[1], step[2](values)
                c, s = lib.cos(angle), lib.sin(angle)
                for v in vectors:
                    v[i], v[j] = c * v[i] - s * v[j], s * v[i] + c * v[j]
            else:
                for c_, f in enumerate(step[1]):
                    p[c_] = p[c_] + f(values)
        return p, d, x

    def error(self, values: dict, backend: str = "numpy"):
        """Exact tool error: pose with the errors minus pose with every error at zero."""
        values = resolve(complete(self.machine, values))
        nominal_values = dict(values)
        for s in self.machine.errors:
            nominal_values[s.name] = 0 * values[s.name]
        p1, d1 = self.pose(values, backend)
        p0, d0 = self.pose(nominal_values, backend)
        dp = [a - b for a, b in zip(p1, p0)]
        dd = [a - b for a, b in zip(d1, d0)] if d1 else None
        return dp, dd

    def _nominal(self, values: dict) -> dict:
        values = resolve(complete(self.machine, values))
        out = dict(values)
        for s in self.machine.errors:
            out[s.name] = 0 * values[s.name]
        return out

    def orientation_error(self, values: dict, backend: str = "numpy"):
        """The exact orientation error ω = log(R_actual·R_nominalᵀ) (rad, 3 components; the
        convention of chaincomp.orientation) with a tool frame, else None."""
        if self.machine.reference is None:
            return None
        _, z1, x1 = self.frame(values, backend)
        _, z0, x0 = self.frame(self._nominal(values), backend)
        return rotation_vector((z1, x1), (z0, x0), _lib(backend))


class TruncatedModel:
    """Order-k error of a derivation as compiled functions of every symbol (values as for
    ExactModel)."""

    def __init__(self, derivation: Derivation):
        self.d = derivation
        self.machine = derivation.machine
        self.symbols = [s.sym for s in self.machine.symbols]
        self._cache: dict = {}

    def _fn(self, which: str, order: int, backend: str):
        key = (which, order, backend)
        if key not in self._cache:
            vec = {"point": self.d.point, "direction": self.d.direction, "orientation": self.d.orientation}[which]
            exprs = [self.d.error(s, order) for s in vec]
            import sympy as sp   # the truncated formulas are sympy's: the symbolic verbs' model
            self._cache[key] = [sp.lambdify(self.symbols, e, modules=backend) for e in exprs]
        return self._cache[key]

    def error(self, values: dict, order: int, backend: str = "numpy"):
        """(point error, direction error or None) of the order-``order`` truncated model."""
        values = resolve(complete(self.machine, values))
        args = [values[s.name] for s in self.machine.symbols]
        dp = [f(*args) for f in self._fn("point", order, backend)]
        dd = [f(*args) for f in self._fn("direction", order, backend)] if self.d.direction else None
        return dp, dd

    def orientation_error(self, values: dict, order: int, backend: str = "numpy"):
        """ω (rad) of the order-``order`` truncated model with a tool frame, else None."""
        if self.d.orientation is None:
            return None
        values = resolve(complete(self.machine, values))
        args = [values[s.name] for s in self.machine.symbols]
        return [f(*args) for f in self._fn("orientation", order, backend)]

