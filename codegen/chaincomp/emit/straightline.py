"""Straight-line C++ for long chains: the chain propagated element by element into a small
IR of hash-consed operations (one node per distinct (op, args): common subexpressions are
shared by construction), constant-folded, and printed directly; no sympy cse, count_ops or
code printer over large trees. Only the chain's elements (small expressions) go through
sympy, for their Taylor coefficients and derivatives.

- pose_exact / pose_nominal: the chain applied to the tool point and direction from the right.
- error_order{k}: univariate truncated Taylor propagation in one scalar eps, every error
  e_i -> eps*e_i at its value in m.params; the coefficient of eps^j is the degree-j part of
  the multivariate series, so error_order_k (the sum of the eps^1..eps^k coefficients) is
  the order-k truncated error, at a cost linear in the chain and independent of the number
  of errors.
- pose_jacobian(_gain): the frames of the chain from the base (rotation R_i, origin o_i); a
  rotation by theta about frame axis u moves the point by dtheta * u x (P - o), a translation
  t by R dt (the geometric Jacobian), for the axes at the errors' values and for the errors
  at zero (the gain matrix).
"""

from __future__ import annotations

import math

import sympy as sp

from ..errors import ChaincompError
from ..model.machine import ROT_PLANE, Machine, Rotation

_FUNCTIONS = {sp.sin: "std::sin", sp.cos: "std::cos", sp.tan: "std::tan", sp.asin: "std::asin",
              sp.acos: "std::acos", sp.atan: "std::atan", sp.atan2: "std::atan2"}
_PRECEDENCE = {"add": 1, "sub": 1, "mul": 2, "div": 2, "neg": 3}


class Graph:
    """Hash-consed nodes: ('const', value), ('in', name), (op, a, b), ('neg', a),
    ('call', function, a, ...). A node is its index; arguments precede their users."""

    def __init__(self):
        self.nodes: list[tuple] = []
        self._index: dict[tuple, int] = {}

    def _node(self, key: tuple) -> int:
        if key not in self._index:
            self._index[key] = len(self.nodes)
            self.nodes.append(key)
        return self._index[key]

    def const(self, v: float) -> int:
        v = float(v)
        if not math.isfinite(v):
            raise ChaincompError(f"a constant of the chain evaluates to {v}")
        return self._node(("const", v + 0.0))  # -0.0 and 0.0 are one node

    def input(self, name: str) -> int:
        return self._node(("in", name))

    def value(self, a: int):
        n = self.nodes[a]
        return n[1] if n[0] == "const" else None

    def neg(self, a: int) -> int:
        n = self.nodes[a]
        if n[0] == "const":
            return self.const(-n[1])
        if n[0] == "neg":
            return n[1]
        if n[0] == "sub":  # -(x - y) is y - x exactly
            return self.sub(n[2], n[1])
        return self._node(("neg", a))

    def add(self, a: int, b: int) -> int:
        va, vb = self.value(a), self.value(b)
        if va is not None and vb is not None:
            return self.const(va + vb)
        if va == 0:
            return b
        if vb == 0:
            return a
        if self.nodes[b][0] == "neg":
            return self.sub(a, self.nodes[b][1])
        if self.nodes[a][0] == "neg":
            return self.sub(b, self.nodes[a][1])
        return self._node(("add", min(a, b), max(a, b)))

    def sub(self, a: int, b: int) -> int:
        va, vb = self.value(a), self.value(b)
        if va is not None and vb is not None:
            return self.const(va - vb)
        if vb == 0:
            return a
        if va == 0:
            return self.neg(b)
        if a == b:
            return self.const(0.0)
        if self.nodes[b][0] == "neg":
            return self.add(a, self.nodes[b][1])
        return self._node(("sub", a, b))

    def mul(self, a: int, b: int) -> int:
        va, vb = self.value(a), self.value(b)
        if va is not None and vb is not None:
            return self.const(va * vb)
        if vb is not None:
            a, b, va, vb = b, a, vb, va
        if va is not None:  # a constant times b
            if va == 0:
                return self.const(0.0)
            if va == 1:
                return b
            if va < 0:
                return self.neg(self.mul(self.const(-va), b))
        na, nb = self.nodes[a], self.nodes[b]
        if na[0] == "neg" or nb[0] == "neg":  # negations move outwards, where they fold into a sub
            prod = self.mul(na[1] if na[0] == "neg" else a, nb[1] if nb[0] == "neg" else b)
            return prod if na[0] == nb[0] else self.neg(prod)
        return self._node(("mul", min(a, b), max(a, b)))

    def div(self, a: int, b: int) -> int:
        va, vb = self.value(a), self.value(b)
        if vb is not None and vb != 0 and va is not None:
            return self.const(va / vb)
        if vb == 1:
            return a
        if va == 0:
            return self.const(0.0)
        return self._node(("div", a, b))

    def call(self, fn: str, *args: int) -> int:
        return self._node(("call", fn) + tuple(args))

    def sum(self, terms) -> int:
        out = self.const(0.0)
        for t in terms:
            out = self.add(out, t)
        return out

    def dot(self, u, v) -> int:
        return self.sum(self.mul(a, b) for a, b in zip(u, v))

    def cross(self, u, v) -> list[int]:
        return [self.sub(self.mul(u[1], v[2]), self.mul(u[2], v[1])),
                self.sub(self.mul(u[2], v[0]), self.mul(u[0], v[2])),
                self.sub(self.mul(u[0], v[1]), self.mul(u[1], v[0]))]

    def evaluate(self, inputs: dict[str, float]) -> list[float]:
        """Every node's value (the tests' reference for what the printed code computes)."""
        fns = {"std::sin": math.sin, "std::cos": math.cos, "std::tan": math.tan, "std::asin": math.asin,
               "std::acos": math.acos, "std::atan": math.atan, "std::atan2": math.atan2,
               "std::sqrt": math.sqrt, "std::pow": math.pow}
        out: list[float] = []
        for node in self.nodes:
            op, args = node[0], node[1:]
            if op == "const":
                out.append(args[0])
            elif op == "in":
                out.append(inputs[args[0]])
            elif op == "call":
                out.append(fns[args[0]](*[out[a] for a in args[1:]]))
            elif op == "neg":
                out.append(-out[args[0]])
            else:
                a, b = out[args[0]], out[args[1]]
                out.append({"add": a + b, "sub": a - b, "mul": a * b}[op] if op != "div" else a / b)
        return out

    # ---- printing

    def emit(self, outputs: list[tuple[str, int]], temp: str = "t") -> tuple[int, list[str], list[str]]:
        """(operations, names of the inputs read, statements) computing ``outputs``: a node
        read twice or more is a temporary, one read once is written inline where it is read."""
        uses: dict[int, int] = {}
        stack = [n for _, n in outputs]
        seen: set[int] = set()
        while stack:
            n = stack.pop()
            if n in seen:
                continue
            seen.add(n)
            for a in self._args(n):
                uses[a] = uses.get(a, 0) + 1
                stack.append(a)
        for _, n in outputs:
            uses[n] = uses.get(n, 0) + 1
        text: dict[int, tuple[str, int]] = {}
        lines, inputs, ops = [], [], 0
        for n in sorted(seen):  # arguments precede their users: a valid order, and deterministic
            node = self.nodes[n]
            op = node[0]
            if op == "const":
                v = node[1]
                text[n] = (repr(v) if v >= 0 else f"({v!r})", 9)
                continue
            if op == "in":
                inputs.append(node[1])
                text[n] = (node[1], 9)
                continue
            ops += 1
            if op == "call":
                s, prec = f"{node[1]}({', '.join(text[a][0] for a in node[2:])})", 9
            elif op == "neg":
                s, prec = "-" + self._wrap(text[node[1]], 3), 3
            else:
                p = _PRECEDENCE[op]
                left = self._wrap(text[node[1]], p)
                right = self._wrap(text[node[2]], p + 1)  # as the IR associates, so as it rounds
                s, prec = f"{left} {dict(add='+', sub='-', mul='*', div='/')[op]} {right}", p
            if uses.get(n, 0) > 1:
                name = f"{temp}{len(lines)}"
                lines.append(f"const double {name} = {s};")
                text[n] = (name, 9)
            else:
                text[n] = (s, prec)
        lines += [f"{target} = {text[n][0]};" for target, n in outputs]
        return ops, inputs, lines

    def _args(self, n: int):
        node = self.nodes[n]
        if node[0] in ("const", "in"):
            return ()
        return node[2:] if node[0] == "call" else node[1:]

    @staticmethod
    def _wrap(t: tuple[str, int], need: int) -> str:
        return t[0] if t[1] >= need else f"({t[0]})"


class Builder:
    """Sympy expressions of one machine into a Graph: axes q_NAME, parameters p_NAME, the
    hoisted parameter-only functions kN, and with ``trig`` the axes' sin and cos s_NAME, c_NAME
    (from the Trig argument)."""

    def __init__(self, machine: Machine, hoist, trig: bool):
        self.g = Graph()
        self.hoist, self.trig = hoist, trig
        self.axes = {a.sym: a for a in machine.axes}
        self.angular = {a.sym for a in machine.axes if a.unit.kind == "angle"}
        self.params = {s.sym: s for s in machine.symbols if s.role != "axis"}
        self._memo: dict = {}

    def leaf(self, sym: sp.Symbol) -> int:
        if sym in self.axes:
            return self.g.input("q_" + sym.name)
        if sym in self.params:
            return self.g.input("p_" + sym.name)
        return self.g.input(sym.name)  # a parameter-only function hoisted into m.k (emit._Hoister)

    def axis_sin_cos(self, sym: sp.Symbol) -> tuple[int, int]:
        if self.trig:
            return self.g.input("s_" + sym.name), self.g.input("c_" + sym.name)
        q = self.leaf(sym)
        return self.g.call("std::sin", q), self.g.call("std::cos", q)

    def expr(self, e: sp.Expr) -> int:
        """The node of ``e`` (parameter-only functions hoisted into k first)."""
        return self._expr(self.hoist(sp.sympify(e)))

    def _expr(self, e: sp.Expr) -> int:
        if e in self._memo:
            return self._memo[e]
        g = self.g
        if not e.free_symbols:
            try:
                out = g.const(float(e))
            except TypeError:
                raise ChaincompError(f"the constant {e} of the chain is not a real number") from None
        elif e.is_Symbol:
            out = self.leaf(e)
        elif e.is_Add:
            out = g.sum(self._expr(a) for a in e.args)
        elif e.is_Mul:
            out = g.const(1.0)
            for a in e.args:
                out = g.mul(out, self._expr(a))
        elif e.is_Pow and e.exp.is_Integer:
            n = int(e.exp)
            base = self._expr(e.base)
            p = base
            for _ in range(abs(n) - 1):
                p = g.mul(p, base)
            out = p if n > 0 else g.div(g.const(1.0), p)
        elif e.is_Pow and e.exp == sp.Rational(1, 2):
            out = g.call("std::sqrt", self._expr(e.base))
        elif e.is_Pow and e.exp == sp.Rational(-1, 2):
            out = g.div(g.const(1.0), g.call("std::sqrt", self._expr(e.base)))
        elif e.is_Pow:
            out = g.call("std::pow", self._expr(e.base), self._expr(e.exp))
        elif isinstance(e, (sp.sin, sp.cos)) and e.args[0] in self.angular:
            s, c = self.axis_sin_cos(e.args[0])
            out = s if isinstance(e, sp.sin) else c
        elif type(e) in _FUNCTIONS:
            out = g.call(_FUNCTIONS[type(e)], *[self._expr(a) for a in e.args])
        else:
            raise ChaincompError(f"cannot emit {e} as straight-line code")
        self._memo[e] = out
        return out

    def sin_cos(self, angle: sp.Expr) -> tuple[int, int]:
        """sin and cos of an angle: of an angular axis plus parameters by the angle-sum
        formulas (the axis' from the Trig argument, the parameters' hoisted into prepare)."""
        terms = sp.Add.make_args(angle)
        moving = [t for t in terms if t.free_symbols & self.axes.keys()]
        fixed = sp.Add(*[t for t in terms if not t.free_symbols & self.axes.keys()])
        if not moving:
            return self.expr(sp.sin(angle)), self.expr(sp.cos(angle))
        x = sp.Add(*moving)
        if x in self.angular:
            sx, cx = self.axis_sin_cos(x)
        elif -x in self.angular:  # a rotation of the workpiece branch, inverted
            sx, cx = self.axis_sin_cos(-x)
            sx = self.g.neg(sx)
        else:
            node = self.expr(x)
            sx, cx = self.g.call("std::sin", node), self.g.call("std::cos", node)
        if fixed == 0:
            return sx, cx
        sp_, cp = self.expr(sp.sin(fixed)), self.expr(sp.cos(fixed))
        g = self.g
        return g.add(g.mul(sx, cp), g.mul(cx, sp_)), g.sub(g.mul(cx, cp), g.mul(sx, sp_))


def eps_coefficients(e: sp.Expr, errors: list[sp.Symbol], k: int) -> list[sp.Expr]:
    """Taylor coefficients of e(eps * errors) in eps, degrees 0..k (a small expression)."""
    present = [s for s in errors if s in e.free_symbols]
    if not present or k == 0:
        return [e.xreplace({s: 0 for s in present})] + [sp.Integer(0)] * k
    eps = sp.Dummy("eps")
    f = e.xreplace({s: eps * s for s in present})
    out = []
    for j in range(k + 1):
        out.append(sp.expand(f.subs(eps, 0) / math.factorial(j)))
        f = sp.diff(f, eps)
    return out


def _series_mul(g: Graph, a: list[int], b: list[int]) -> list[int]:
    return [g.sum(g.mul(a[i], b[n - i]) for i in range(n + 1)) for n in range(len(a))]


def pose_series(b: Builder, machine: Machine, k: int, scaled: bool) -> list[list[int]]:
    """The tool point (and direction) as eps-series of degree k, applied from the right. With
    ``scaled`` false the errors are not scaled (k must be 0): the exact pose."""
    g = b.g
    errors = [s.sym for s in machine.errors]

    def lift(e: sp.Expr) -> list[int]:
        return [b.expr(c) for c in eps_coefficients(e, errors, k)] if scaled else [b.expr(e)]

    p = [lift(v) for v in machine.tool_point]
    dirs = [[lift(v) for v in axis] for axis in machine.tool_axes]
    for el in reversed(machine.chain):
        if not isinstance(el, Rotation):
            for c in range(3):
                p[c] = [g.add(x, y) for x, y in zip(p[c], lift(el.vector[c]))]
            continue
        coeffs = eps_coefficients(el.angle, errors, k) if scaled else [el.angle]
        s0, c0 = b.sin_cos(coeffs[0])
        theta = [None] + [b.expr(c) for c in coeffs[1:]]
        s, c = [s0], [c0]
        for n in range(1, k + 1):  # n s_n = sum j theta_j c_(n-j);  n c_n = -sum j theta_j s_(n-j)
            ds = g.sum(g.mul(g.const(j), g.mul(theta[j], c[n - j])) for j in range(1, n + 1))
            dc = g.sum(g.mul(g.const(j), g.mul(theta[j], s[n - j])) for j in range(1, n + 1))
            s.append(g.mul(g.const(1.0 / n), ds))
            c.append(g.neg(g.mul(g.const(1.0 / n), dc)))
        i, j = ROT_PLANE[el.axis]
        for vec in [p] + dirs:
            vi, vj = vec[i], vec[j]
            vec[i] = [g.sub(x, y) for x, y in zip(_series_mul(g, c, vi), _series_mul(g, s, vj))]
            vec[j] = [g.add(x, y) for x, y in zip(_series_mul(g, s, vi), _series_mul(g, c, vj))]
    return p + [c for axis in dirs for c in axis]


def pose_and_derivatives(b: Builder, machine: Machine, variables: list[sp.Symbol], at: dict
                         ) -> tuple[list[int], list[list[int]]]:
    """(pose, d pose / d v for v in variables) with the symbols in ``at`` replaced by their
    values there, by the frames of the chain from the base."""
    g = b.g
    zero, one = g.const(0.0), g.const(1.0)
    R = [[one if r == c else zero for c in range(3)] for r in range(3)]   # R[row][column]
    o = [zero, zero, zero]
    axis_col = {"x": 0, "y": 1, "z": 2}
    moves = []   # (kind, element, frame data) for the derivatives
    for el in machine.chain:
        if isinstance(el, Rotation):
            a = axis_col[el.axis]
            moves.append(("rot", el.angle, [R[r][a] for r in range(3)], list(o)))
            s, c = b.sin_cos(el.angle.xreplace(at))
            i, j = ROT_PLANE[el.axis]
            for r in range(3):
                ri, rj = R[r][i], R[r][j]
                R[r][i] = g.add(g.mul(c, ri), g.mul(s, rj))
                R[r][j] = g.sub(g.mul(c, rj), g.mul(s, ri))
        else:
            t = [b.expr(v.xreplace(at)) for v in el.vector]
            moves.append(("trans", el.vector, [row[:] for row in R], None))
            o = [g.add(o[r], g.dot(R[r], t)) for r in range(3)]
    tool = [b.expr(v.xreplace(at)) for v in machine.tool_point]
    P = [g.add(o[r], g.dot(R[r], tool)) for r in range(3)]
    Ks = []   # the direction and, with a frame, its x axis
    for axis in machine.tool_axes:
        k = [b.expr(v.xreplace(at)) for v in axis]
        Ks.append([g.dot(R[r], k) for r in range(3)])
    pose = P + [c for K in Ks for c in K]
    derivatives = []
    lever = {}  # per rotation: u x (P - o) and u x K, shared by every variable it moves
    for v in variables:
        col = [zero] * len(pose)
        for n, (kind, what, frame, origin) in enumerate(moves):
            if kind == "rot":
                dtheta = sp.diff(what, v)
                if dtheta == 0:
                    continue
                dt = b.expr(dtheta.xreplace(at))
                if n not in lever:
                    arm = g.cross(frame, [g.sub(P[r], origin[r]) for r in range(3)])
                    lever[n] = arm + [c for K in Ks for c in g.cross(frame, K)]
                col = [g.add(x, g.mul(dt, y)) for x, y in zip(col, lever[n])]
            else:
                dvec = [sp.diff(c, v) for c in what]
                if all(c == 0 for c in dvec):
                    continue
                dv = [b.expr(c.xreplace(at)) for c in dvec]
                for r in range(3):
                    col[r] = g.add(col[r], g.dot(frame[r], dv))
        dtool = [sp.diff(c, v) for c in machine.tool_point]
        if any(c != 0 for c in dtool):
            dv = [b.expr(c.xreplace(at)) for c in dtool]
            for r in range(3):
                col[r] = g.add(col[r], g.dot(R[r], dv))
        for n_axis, axis in enumerate(machine.tool_axes):
            dk = [sp.diff(c, v) for c in axis]
            if any(c != 0 for c in dk):
                dv = [b.expr(c.xreplace(at)) for c in dk]
                for r in range(3):
                    col[3 + 3 * n_axis + r] = g.add(col[3 + 3 * n_axis + r], g.dot(R[r], dv))
        derivatives.append(col)
    return pose, derivatives


def functions(machine: Machine, order: int, hoist) -> list[tuple[str, bool, Builder, list[tuple[str, int]]]]:
    """Per generated function: (name, takes Trig, builder, [(target, node)])."""
    axes = [a.sym for a in machine.axes]
    errors = [s.sym for s in machine.errors]
    zero = {e: sp.Integer(0) for e in errors}
    out = []

    def pose_fn(name, scaled):
        b = Builder(machine, hoist, trig=True)
        pose = [c[0] for c in pose_series(b, machine, 0, scaled)]
        out.append((name, True, b, [(f"out[{i}]", n) for i, n in enumerate(pose)]))

    pose_fn("pose_exact", False)
    pose_fn("pose_nominal", True)
    for name, gain in (("pose_jacobian", False), ("pose_jacobian_gain", True)):
        b = Builder(machine, hoist, trig=True)
        pose, jac = pose_and_derivatives(b, machine, axes, {})
        targets = [(f"out[{i}]", n) for i, n in enumerate(pose)]
        targets += [(f"J({i}, {j})", jac[j][i]) for i in range(len(pose)) for j in range(len(axes))]
        if gain:
            _, G = pose_and_derivatives(b, machine, errors, zero)
            targets += [(f"G({i}, {c})", G[c][i]) for i in range(len(pose)) for c in range(len(errors))]
        out.append((name, True, b, targets))
    for k in range(1, order + 1):
        b = Builder(machine, hoist, trig=False)
        series = pose_series(b, machine, k, True)
        out.append((f"error_order{k}", False, b,
                    [(f"out[{i}]", b.g.sum(c[1:])) for i, c in enumerate(series)]))
    return out
