"""Numeric evaluation: the exact model (the chain multiplied without truncation) and
the truncated models, with numpy (arrays broadcast) or mpmath (high precision). Errors that
vary along an axis (chaincomp.varying) are evaluated at the axis values given."""

from __future__ import annotations

import sympy as sp

from .derive import Derivation
from .errors import ChaincompError
from .machine import ROT_PLANE, Machine, Rotation
from .orientation import rotation_vector
from .varying import resolve

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
        self.symbols = [s.sym for s in machine.symbols]
        self._cache: dict[str, tuple] = {}

    def _compiled(self, backend: str):
        """One function of every symbol giving every element's numbers (one lambdify: one per
        element cost ~14 ms each, a second on a six-joint arm), and where each element's are."""
        if backend not in self._cache:
            exprs, steps = [], []
            for el in reversed(self.machine.chain):
                if isinstance(el, Rotation):
                    steps.append(("rot", ROT_PLANE[el.axis], len(exprs)))
                    exprs.append(el.angle)
                else:
                    steps.append(("trans", len(exprs)))
                    exprs.extend(el.vector)
            point = len(exprs)
            exprs.extend(self.machine.tool_point)
            direction = reference = None
            if self.machine.tool_direction:
                direction = len(exprs)
                exprs.extend(self.machine.tool_direction)
            if self.machine.tool_reference:
                reference = len(exprs)
                exprs.extend(self.machine.tool_reference)
            fn = sp.lambdify(self.symbols, exprs, modules=backend)
            self._cache[backend] = (fn, steps, point, direction, reference)
        return self._cache[backend]

    def pose(self, values: dict, backend: str = "numpy"):
        """(point, direction or None) for ``values`` (internal units, every symbol by name)."""
        p, d, _ = self.frame(values, backend)
        return p, d

    def frame(self, values: dict, backend: str = "numpy"):
        """(point, direction or None, the tool frame's x axis or None) for ``values``."""
        lib = _lib(backend)
        fn, steps, point, direction, reference = self._compiled(backend)
        values = resolve(complete(self.machine, values))
        numbers = fn(*[values[s.name] for s in self.machine.symbols])
        p = list(numbers[point:point + 3])
        d = list(numbers[direction:direction + 3]) if direction is not None else None
        x = list(numbers[reference:reference + 3]) if reference is not None else None
        vectors = [v for v in (p, d, x) if v is not None]
        for step in steps:
            if step[0] == "rot":
                (i, j), angle = step[1], numbers[step[2]]
                c, s = lib.cos(angle), lib.sin(angle)
                for v in vectors:
                    v[i], v[j] = c * v[i] - s * v[j], s * v[i] + c * v[j]
            else:
                for c_ in range(3):
                    p[c_] = p[c_] + numbers[step[1] + c_]
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
        if self.machine.tool_reference is None:
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

