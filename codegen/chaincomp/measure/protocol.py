"""Measurement protocol: the search of Freeman & Ford (2003) §5, automated.

The first-order tool-point equations are written at every set-up of the rotary axes over
an angle grid; for each measured coordinate, the sum and the difference of every pair of
set-ups gives a candidate equation. Errors are then taken one at a time: the next one is
the error that the simplest equation (fewest unknowns, then fewest terms) isolates, given
the errors already identified. Where no equation isolates any error, the smallest set of
errors that a group of equations determines is reported as a simultaneous set, or, when
the errors of the set enter every equation in the same combination, as a combination
that the set-ups can measure but not split.

Numbers decide (zero tests and ranks at the nominal constants, columns scaled to unit
norm); sympy only writes the chosen equations, exactly, in the machine's constants.
"""

from __future__ import annotations

import itertools
import random
from dataclasses import dataclass, field

import numpy as np
import sympy as sp

from ..errors import ChaincompError
from ..escape import one_line
from ..model.machine import Machine, Symbol
from ..symbolic.derive import COMPONENTS, derive

_TOL = 1e-9          # relative: coefficient zero tests and ranks
# The search pairs every two set-ups: 168 set-ups of five_axis_ac take 19 s and 230 MB,
# 361 ran out of memory after 50 s (2 cores, 2026-12).
MAX_SETUPS = 200
_EXACT_FACTOR = {"deg": sp.pi / 180, "arcsec": sp.pi / 648000}


def exact_internal(sym: Symbol, value: float) -> sp.Expr:
    """``value`` (declared unit) in internal units, exact where it can be: 90 deg -> pi/2."""
    factor = _EXACT_FACTOR.get(sym.unit.name, sp.Rational(repr(sym.unit.to_internal)))
    return sp.Rational(repr(float(value))) * factor


def _reduced(e: sp.Expr, f) -> dict:
    """Terms of ``e`` with even powers of ``f`` (sin or cos) of each angle rewritten through
    sin² + cos² = 1: a canonical form, so that sums and differences cancel what they should."""
    g = sp.cos if f is sp.sin else sp.sin
    reps = {p: f(p.base.args[0]) ** (int(p.exp) % 2) * (1 - g(p.base.args[0]) ** 2) ** (int(p.exp) // 2)
            for p in e.atoms(sp.Pow) if isinstance(p.base, f) and p.exp.is_Integer and p.exp >= 2}
    return sp.expand(e.xreplace(reps)).as_coefficients_dict() if reps else e.as_coefficients_dict()


def check_errors(machine: Machine, names, option: str) -> list[str]:
    """Validate error names given on the command line."""
    out = []
    for name in names:
        try:
            sym = machine.symbol(name)
        except KeyError:
            raise ChaincompError(f"{option}: unknown error {name!r} for machine {machine.name!r} "
                                 f"(errors: {', '.join(s.name for s in machine.errors)})") from None
        if sym.role != "error":
            raise ChaincompError(f"{option}: {name!r} is {'an' if sym.role == 'axis' else 'a'} "
                                 f"{sym.role}, not an error")
        if name not in out:
            out.append(name)
    return out


def check_measure(measure) -> list[str]:
    """Validate --measure: tool-point coordinates x, y, z (any case), each once, at least one."""
    out = [c.lower() for c in measure]
    for i, c in enumerate(out):
        if c not in COMPONENTS:
            raise ChaincompError(f"--measure: unknown coordinate {c!r} (expected x, y, z)")
        if c in out[:i]:
            raise ChaincompError(f"--measure: {c!r} named twice")
    if not out:
        raise ChaincompError("--measure: name at least one coordinate (x, y, z)")
    return out


@dataclass
class Equation:
    """``coord`` at set-up ``setups[0]`` plus ``sign`` times it at ``setups[1]``."""
    coord: str
    setups: tuple[int, int]
    sign: int                      # -1 difference, +1 sum
    unknowns: tuple[str, ...]      # errors not yet known when the equation was chosen
    nominal: sp.Expr               # the error-free part (mm)
    error: sp.Expr                 # the first-order error part (errors in mm, rad)

    @property
    def rhs(self) -> sp.Expr:
        return self.nominal + self.error


@dataclass
class Step:
    kind: str                      # "test" | "simultaneous" | "combination"
    errors: tuple[str, ...]
    equations: list[Equation]
    combination: sp.Expr | None = None   # kind "combination": what the set-ups measure


@dataclass
class Protocol:
    machine: Machine
    grid_axes: list[str]
    grid: dict[str, list[float]]          # grid axis -> values used (declared unit)
    left_out: dict[str, list[float]]      # grid axis -> values outside its limits
    fixed: dict[str, float]               # other axes -> value (declared unit)
    setups: list[dict[str, float]]
    measured: list[str]
    assumed_zero: list[str]
    steps: list[Step] = field(default_factory=list)
    unidentifiable: dict[str, str] = field(default_factory=dict)

    def label(self, i: int) -> str:
        return "(" + ",".join(f"{self.setups[i][a]:g}" for a in self.grid_axes) + ")"

    def lhs(self, eq: Equation) -> str:
        a, b = eq.setups
        return (f"{eq.coord.upper()}{'diff' if eq.sign < 0 else 'sum'} {self.label(a)} "
                f"{'-' if eq.sign < 0 else '+'} {self.label(b)}")


def build_protocol(machine: Machine, angles=(0.0, 90.0, 180.0, 270.0), assume_zero=(),
                   measure=COMPONENTS, fixed: dict[str, float] | None = None, prefer=()) -> Protocol:
    """Search the set-ups of ``machine``'s rotary axes over ``angles`` for the simplest tests."""
    assume_zero = check_errors(machine, assume_zero, "--assume-zero")
    prefer = check_errors(machine, prefer, "--prefer")
    measure = check_measure(measure)
    grid_axes = [s for s in machine.axes if s.unit.kind == "angle"]
    if not grid_axes:
        raise ChaincompError(f"machine {machine.name!r} has no rotary axis to set over the angle grid")
    fixed = dict(fixed or {})
    for name in fixed:
        if name in [s.name for s in grid_axes]:
            raise ChaincompError(f"--set: {name} is a rotary axis: it takes the values of --angles")
        if name not in [s.name for s in machine.axes]:
            raise ChaincompError(f"--set: {name!r} is not an axis of {machine.name!r} "
                                 f"(axes: {', '.join(s.name for s in machine.axes)})")
    for s in machine.axes:
        if s not in grid_axes and s.name not in fixed:
            fixed[s.name] = s.default_position
    grid, left_out = {}, {}
    for s in grid_axes:
        lo, hi = s.limits
        grid[s.name] = [a for a in angles if lo <= a <= hi]
        left_out[s.name] = [a for a in angles if not lo <= a <= hi]
    counts = {k: len(v) for k, v in grid.items()}
    for name, n in counts.items():
        if not n:
            lo, hi = machine.symbol(name).limits
            raise ChaincompError(f"--angles: no value within the limits of {name} [{lo:g}, {hi:g}]")
    total = int(np.prod(list(counts.values())))
    if total > MAX_SETUPS:
        raise ChaincompError(f"--angles: {' x '.join(f'{n} ({k})' for k, n in counts.items())} = {total} set-ups, "
                             f"at most {MAX_SETUPS}: give fewer angles")
    setups = [dict(zip(grid, combo)) for combo in itertools.product(*grid.values())]
    proto = Protocol(machine, list(grid), grid, {k: v for k, v in left_out.items() if v}, fixed,
                     setups, measure, assume_zero)
    _search(proto, prefer)
    return proto


class _Equations:
    """Every set-up's first-order equations, exact (sympy) and numeric, and their pairings."""

    def __init__(self, proto: Protocol):
        m = proto.machine
        d = derive(m, 1)
        gains = d.gain_matrix()
        self.names = [s.name for s in m.errors]
        self.syms = [s.sym for s in m.errors]
        consts = {s.sym: m.nominal_values()[s.name] for s in m.constants}
        rng = random.Random(12345)   # a second, generic point: a zero test that no nominal fools
        generic = {k: v * (1.0 + 0.3 * rng.random()) + 0.1 * rng.random() for k, v in consts.items()}
        axis = {s.name: s for s in m.axes}
        n_s, n_c, n_e = len(proto.setups), len(proto.measured), len(self.names)
        self.expr = np.empty((n_s, n_c, n_e), dtype=object)   # as_coefficients_dict of each gain
        self.nom = np.empty((n_s, n_c), dtype=object)
        self.num = np.zeros((2, n_s, n_c, n_e))
        self.moves = [set() for _ in self.names]     # coordinates each error moves somewhere
        for si, setup in enumerate(proto.setups):
            sub = {axis[k].sym: exact_internal(axis[k], v) for k, v in {**setup, **proto.fixed}.items()}
            for k, c in enumerate(COMPONENTS):
                ci = proto.measured.index(c) if c in proto.measured else None
                if ci is not None:
                    nom = sp.expand(d.nominal(d.point[k]).xreplace(sub))
                    self.nom[si, ci] = (_reduced(nom, sp.sin), _reduced(nom, sp.cos))
                for j, g in enumerate(gains[f"d{c}"]):
                    e = sp.expand(g.xreplace(sub))
                    values = float(e.xreplace(consts)), float(e.xreplace(generic))
                    if any(values):
                        self.moves[j].add(c)
                    if ci is not None:
                        self.expr[si, ci, j] = (_reduced(e, sp.sin), _reduced(e, sp.cos))
                        self.num[:, si, ci, j] = values
        # the pool: coordinate x pair x (difference, sum), as index arrays and coefficient rows
        pi, pk = np.triu_indices(n_s, 1)
        rows = [(ci, i, k, sign) for ci in range(n_c) for sign in (-1, 1) for i, k in zip(pi, pk)]
        self.rows = rows
        if rows:
            ci, i, k, sign = (np.array(v) for v in zip(*rows))
            both = self.num[:, i, ci, :] + sign[None, :, None] * self.num[:, k, ci, :]
        else:
            both = np.zeros((2, 0, n_e))
        scale = np.abs(self.num).max(axis=(1, 2))   # (2, n_e): size of each error's column
        scale[scale == 0] = 1.0
        self.nz = (np.abs(both) > _TOL * scale[:, None, :]).any(axis=0)
        self.nz[:, [self.names.index(n) for n in proto.assumed_zero]] = False   # zero: out of every equation
        self.a = both[0] / scale[0]        # nominal constants, columns scaled
        self._terms: dict[int, tuple[int, int]] = {}
        self.measured = proto.measured

    def _merge(self, r: int, j: int | None) -> dict:
        """Terms of the coefficient of error ``j`` (or of the nominal part) in pool row ``r``:
        the shorter of the two canonical forms."""
        ci, i, k, sign = self.rows[r]
        a, b = (self.nom[i, ci], self.nom[k, ci]) if j is None else (self.expr[i, ci, j], self.expr[k, ci, j])
        forms = []
        for x, y in zip(a, b):
            out = dict(x)
            for term, coeff in y.items():
                out[term] = out.get(term, 0) + sign * coeff
            forms.append({t: c for t, c in out.items() if c != 0})
        return min(forms, key=len)

    def terms(self, r: int) -> tuple[int, int]:
        """(terms of the error part, terms of the nominal part) of pool row ``r``."""
        if r not in self._terms:
            err = sum(len(self._merge(r, j)) for j in np.flatnonzero(self.nz[r]))
            self._terms[r] = (err, len(self._merge(r, None)))
        return self._terms[r]

    def key(self, r: int, n_unknowns: int):
        ci, i, k, sign = self.rows[r]
        return (n_unknowns, *self.terms(r), sign > 0, ci, i, k)

    def equation(self, r: int, unknowns) -> Equation:
        ci, i, k, sign = self.rows[r]
        def to_expr(terms: dict) -> sp.Expr:
            e = sp.Add(*[c * t for t, c in terms.items()])
            if sp.count_ops(e) > _SIMPLIFY_OPS:   # trigsimp of such a sum takes seconds and rarely helps
                return sp.factor(e)
            return min(sp.factor(e), sp.factor(sp.trigsimp(e)), key=sp.count_ops)

        error = sp.Add(*[to_expr(self._merge(r, j)) * self.syms[j] for j in np.flatnonzero(self.nz[r])])
        return Equation(self.measured[ci], (int(i), int(k)), int(sign), tuple(unknowns),
                        to_expr(self._merge(r, None)), error)


# Coefficients larger than this (sympy's count_ops) are only factored, not trigsimp'd: the bundled
# machines' are at most 9; a URDF arm's, with its origins' angles folded in as numbers (rpy 0.1,
# -0.2, 0.3), reach 136, and trigsimp made 'protocol' take 24 s of CPU for two set-ups.
_SIMPLIFY_OPS = 40


def _rank(a: np.ndarray) -> int:
    if a.size == 0:
        return 0
    s = np.linalg.svd(a, compute_uv=False)
    return int((s > _TOL * max(s[0], 1e-300)).sum())


def _search(proto: Protocol, prefer: list[str]) -> None:
    eqs = _Equations(proto)
    names = eqs.names
    unknown = []
    for j, n in enumerate(names):
        if n in proto.assumed_zero:
            continue
        if not eqs.nz[:, j].any():
            proto.unidentifiable[n] = _invisible_reason(proto, eqs.moves[j])
            continue
        unknown.append(j)
    rank_order = {n: i for i, n in enumerate(prefer)}

    while unknown:
        u = np.array(unknown)
        masks = eqs.nz[:, u]
        live = np.flatnonzero(masks.any(axis=1))
        sets = sorted({tuple(masks[r]) for r in live}, key=lambda s: (sum(s), s))
        found = _resolve(eqs, u, masks, live, sets, rank_order)
        if found is None:   # try unions of two, then everything left
            unions = sorted({tuple(np.logical_or(a, b)) for a, b in itertools.combinations(sets, 2)},
                            key=lambda s: (sum(s), s))
            found = _resolve(eqs, u, masks, live, unions, rank_order) or \
                _resolve(eqs, u, masks, live, [tuple([True] * len(u))], rank_order)
        S, rows, rank = found
        errs = tuple(names[j] for j in u[list(S)])
        chosen = [eqs.equation(r, [names[j] for j in u[masks[r]]]) for r in rows]
        if len(errs) == 1:
            step = Step("test", errs, chosen)
        elif rank == len(errs):
            step = Step("simultaneous", errs, chosen)
        else:
            step = _combination(eqs, errs, chosen, proto)
        proto.steps.append(step)
        unknown = [j for j in unknown if names[j] not in errs]


def _resolve(eqs: _Equations, u, masks, live, candidates, rank_order):
    """The best set among the smallest ``candidates`` that its own equations determine."""
    best = None
    for size, group in itertools.groupby(candidates, key=sum):
        for S in group:
            S = np.array(S)
            inside = live[~(masks[live] & ~S).any(axis=1)]
            cols = u[S]
            rank_all = _rank(eqs.a[:, cols])
            if _rank(eqs.a[np.ix_(inside, cols)]) != rank_all:
                continue
            rows, basis = [], np.zeros((0, len(cols)))
            for r in sorted(inside, key=lambda r: eqs.key(r, int(masks[r].sum()))):
                trial = np.vstack([basis, eqs.a[r, cols]])
                if _rank(trial) > len(rows):
                    rows.append(int(r))
                    basis = trial
                if len(rows) == rank_all:
                    break
            names = [eqs.names[j] for j in cols]
            pref = min((rank_order.get(n, len(rank_order)) for n in names))
            key = (pref, [eqs.key(r, int(masks[r].sum())) for r in rows], list(cols))
            if best is None or key < best[0]:
                best = (key, (S, rows, rank_all))
        if best is not None:
            return best[1]
    return None


def _combination(eqs: _Equations, errs, chosen: list[Equation], proto: Protocol) -> Step:
    """A set its equations determine only partly: name the errors that cannot be split."""
    j = [eqs.names.index(n) for n in errs]
    a = eqs.a[:, j]
    null = np.linalg.svd(a)[2][_rank(a):]
    inseparable = [n for n, size in zip(errs, np.abs(null).max(axis=0)) if size > 1e-6]
    cols = [eqs.names.index(n) for n in inseparable]
    combination = None
    if _rank(eqs.a[:, cols]) == 1:   # one combination: read it off an equation
        syms = [sp.Symbol(n, real=True) for n in inseparable]
        for eq in chosen:
            part = sp.Add(*[t for t in sp.Add.make_args(sp.expand(sp.expand_trig(eq.error)))
                            if t.free_symbols & set(syms)])
            if part != 0:
                combination = sp.factor_terms(part).as_independent(*syms, as_Add=False)[1]
                if combination.coeff(syms[0]).could_extract_minus_sign():
                    combination = -combination
                break
    test = len(proto.steps) + 1
    for n in inseparable:
        others = ", ".join(o for o in inseparable if o != n)
        seen = (f"only as {combination}" if combination is not None
                else f"only in {_rank(eqs.a[:, cols])} combinations")
        proto.unidentifiable[n] = (f"cannot be told apart from {others}: the set-ups see them {seen} "
                                   f"(Test {test}); assume all but one of them zero to give it a value")
    return Step("combination", tuple(errs), chosen, combination)


def _invisible_reason(proto: Protocol, moves: set) -> str:
    measured = ", ".join(c.upper() for c in proto.measured)
    if not moves:
        where = "".join(f", {k} = {v:g} {proto.machine.symbol(k).unit.name}" for k, v in proto.fixed.items())
        return f"does not move the tool point at any set-up of the grid{where} (to first order)"
    if not moves & set(proto.measured):
        return (f"moves only {', '.join(c.upper() for c in COMPONENTS if c in moves)}, "
                f"which is not measured (measured: {measured})")
    return f"needs at least two set-ups: the grid has {len(proto.setups)}"


# ----------------------------------------------------------------------------- reports

def to_json(proto: Protocol) -> dict:
    m = proto.machine

    def eq_json(eq: Equation) -> dict:
        return {"coordinate": eq.coord, "operation": "difference" if eq.sign < 0 else "sum",
                "setups": [proto.setups[i] for i in eq.setups], "lhs": proto.lhs(eq),
                "unknowns": list(eq.unknowns), "nominal": str(eq.nominal), "error": str(eq.error),
                "equation": str(eq.rhs)}

    return {
        "machine": m.name, "file": m.file, "order": 1,
        "grid": proto.grid, "left_out": proto.left_out, "fixed": proto.fixed,
        "measured": proto.measured, "assumed_zero": proto.assumed_zero,
        "units": {"internal": "mm and rad: every symbol enters the equations in internal units",
                  "setups": {a: m.symbol(a).unit.name for a in proto.grid_axes}},
        "tests": [{"test": i + 1, "kind": st.kind, "errors": list(st.errors),
                   **({"combination": str(st.combination)} if st.combination is not None else {}),
                   "equations": [eq_json(e) for e in st.equations]} for i, st in enumerate(proto.steps)],
        "unidentifiable": proto.unidentifiable,
    }


def to_text(proto: Protocol) -> str:
    m = proto.machine
    units = {m.symbol(a).unit.name for a in proto.grid_axes}
    lines = [f"PROTOCOL EQUATIONS for {m.name} ({one_line(m.file)}), first order",
             f"Set-ups ({', '.join(proto.grid_axes)}) over "
             + "; ".join(f"{a} in {{{', '.join(f'{v:g}' for v in vals)}}}" for a, vals in proto.grid.items())
             + f" {'/'.join(sorted(units))}: {len(proto.setups)} set-ups"]
    if proto.fixed:
        lines.append("Other axes at " + ", ".join(f"{k} = {v:g} {m.symbol(k).unit.name}"
                                                   for k, v in proto.fixed.items()))
    for a, vals in proto.left_out.items():
        lines.append(f"Left out: {a} = {', '.join(f'{v:g}' for v in vals)} (outside its limits)")
    lines.append(f"Measured: {', '.join(c.upper() for c in proto.measured)}")
    lines.append(f"Parameters assumed zero: {' '.join(proto.assumed_zero) or '(none)'}")
    notes = []
    for i, st in enumerate(proto.steps):
        head = f"Test {i + 1:<3} "
        if st.kind == "test":
            eq = st.equations[0]
            lines.append(f"{head}{st.errors[0]} from {proto.lhs(eq)} = {eq.rhs}")
            continue
        if st.kind == "combination" and st.combination is not None and len(st.equations) == 1:
            eq = st.equations[0]
            lines.append(f"{head}{'/'.join(st.errors)} as {st.combination} from {proto.lhs(eq)} = {eq.rhs}")
        else:
            lines.append(f"{head}{'/'.join(st.errors)} from {len(st.equations)} simultaneous equations:")
            lines += [f"{'':9}{proto.lhs(eq)} = {eq.rhs}" for eq in st.equations]
        if st.kind == "simultaneous":
            notes.append(f"Test {i + 1} is a set of simultaneous equations for {', '.join(st.errors)}.")
        else:
            split = [n for n in st.errors if n not in proto.unidentifiable]
            what = f"the combination {st.combination}" if st.combination is not None else "combinations"
            notes.append(f"Test {i + 1} measures only {what} of "
                         f"{', '.join(n for n in st.errors if n in proto.unidentifiable)}"
                         + (f" (and {', '.join(split)})" if split else "") + ".")
    lines.append("Notes - Xdiff (a) - (b) is X at the tool tip measured at set-up (a) minus X at set-up (b), "
                 f"set-ups written ({','.join(proto.grid_axes)}); Xsum likewise; errors in mm and rad.")
    lines += [f"      - {n}" for n in notes]
    if proto.unidentifiable:
        lines.append("Not identifiable:")
        lines += [f"  {n}: {why}" for n, why in proto.unidentifiable.items()]
    return "\n".join(lines)
