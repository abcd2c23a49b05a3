"""Modelling mistakes that load without error but cannot be what the author meant: an
error symbol that never moves the tool (its gain is zero on every component at every pose),
an axis that never moves it. Loading already refuses what is wrong outright (unknown or
unused symbols, expressions that are not finite, real and analytic in the errors).

The check is numeric: central differences of the exact model at a few poses drawn within
the axis limits (seeded, so the findings do not change from run to run); a gain that is
not identically zero vanishes at all of them only by coincidence of measure zero.
"""

from __future__ import annotations

import itertools
import math
from dataclasses import dataclass

import numpy as np

from ..model.machine import Machine, Rotation
from ..symbolic.numeric import ExactModel, complete

POSES = 8
_STEP = 1e-6          # internal units (mm, rad)
_ZERO = 1e-9          # |d pose / d symbol| below this counts as zero (mm/mm, mm/rad, 1/rad)


@dataclass(frozen=True)
class Finding:
    level: str        # "warning"
    message: str
    line: int
    field: str

    def __str__(self) -> str:
        return f"{self.line}: {self.field}: {self.message}" if self.line else f"{self.field}: {self.message}"


def _where(machine: Machine, name: str) -> int:
    """The first line of the chain where ``name`` enters (or its declaration)."""
    for el in machine.tool_chain + machine.workpiece_chain:
        exprs = (el.expr,) if isinstance(el, Rotation) else el.exprs
        if any(name in e.names for e in exprs) and el.line:
            return el.line
    return machine.symbol(name).line


def _poses(machine: Machine) -> dict[str, np.ndarray]:
    rng = np.random.default_rng(20031)
    return {s.name: s.to_internal(rng.uniform(*s.limits, POSES)) for s in machine.axes}


def _moves_tool(model: ExactModel, values: dict, name: str) -> bool | None:
    """Whether ``name`` moves the tool point, direction or frame (its x axis: a turn about the
    tool axis moves only that), read at the poses where the model is finite (a NaN gain is no
    zero gain: _not_real names the expression); None where it is finite at none."""
    up, down = dict(values), dict(values)
    # _STEP, or a step a value of its size can resolve: beyond about 1e6 (an axis of travel 1e11 m
    # at 1e14 mm), 1e14 + 1e-6 is 1e14 and every gain would read zero
    step = np.maximum(_STEP, np.abs(values[name]) * 1e-12)
    up[name] = values[name] + step
    down[name] = values[name] - step
    plus, minus = model.frame(up), model.frame(down)
    gains = np.array([np.broadcast_to(np.abs((np.asarray(a) - np.asarray(b)) / (2 * step)), (POSES,))
                      for u, v in zip(plus, minus) if u is not None for a, b in zip(u, v)])
    finite = np.all(np.isfinite(gains), axis=0)   # the poses where every gain can be read
    if not finite.any():
        return None
    return bool(np.any(gains[:, finite] > _ZERO))


def _not_real(machine: Machine, values: dict) -> list[Finding]:
    """The expressions of the chain and tool point that are not finite and real somewhere
    within the axis limits (errors zero), at the corners of the limits of their axes or at the
    sampled poses: sqrt(X) with X in [-100, 100], acos(X/50) with |X| beyond 50, a divisor
    that vanishes there. The loader checks them at one pose only."""
    out, seen = [], set()
    parts = [(el.line, "chain", (el.expr,) if isinstance(el, Rotation) else el.exprs)
             for el in machine.tool_chain + machine.workpiece_chain]
    tool = next((i for i, t in enumerate(machine.source_text.splitlines(), 1) if t.startswith("tool:")), 0)
    for line, fld, exprs in parts + [(tool, "tool.point", machine.point)]:
        for e in exprs:
            axes = [s for s in machine.axes if s.name in e.names]
            if e.source in seen or not axes or len(axes) > 8:
                continue
            corners = list(itertools.product(*(s.limits for s in axes)))
            at = {s.name: values[s.name][0] for s in machine.axes}   # (the others: e does not read them)
            at.update({s.name: np.concatenate([s.to_internal(np.array([c[k] for c in corners])), values[s.name]])
                       for k, s in enumerate(axes)})
            at = complete(machine, {**at, **{s.name: 0.0 for s in machine.errors}})
            with np.errstate(all="ignore"):
                v = np.broadcast_to(np.asarray(e.function(np)(at), dtype=float), (len(corners) + POSES,))
            bad = np.flatnonzero(~np.isfinite(v))
            if not len(bad):
                continue
            seen.add(e.source)
            i = bad[0]
            pose = ", ".join(f"{s.name} = {s.from_internal(at[s.name][i]):.6g} {s.unit.name}" for s in axes)
            what = "not finite" if np.isinf(v[i]) else "not real (or not finite)"
            out.append(Finding("warning", f"{e.source!r} is {what} at {pose}, within the axis limits (at {len(bad)} "
                                          f"of the {len(v)} poses lint tries: the limits' corners and {POSES} "
                                          f"within), so no gain can be read there; write it so that it is real "
                                          f"over the limits, or narrow them", line, fld))
    return out


def lint(machine: Machine, model: ExactModel | None = None) -> list[Finding]:
    """Warnings about ``machine``, in the order of its symbols."""
    model = model or ExactModel(machine)
    values = {**_poses(machine), **{s.name: np.zeros(POSES) for s in machine.errors}}
    findings = _not_real(machine, values)
    what = ("tool frame (point and orientation)" if machine.reference is not None
            else "tool point or direction" if machine.direction else "tool point")
    for s in machine.symbols:
        if s.role == "constant":
            continue
        with np.errstate(all="ignore"):
            moves = _moves_tool(model, values, s.name)
        line = _where(machine, s.name)
        if s.unobservable and moves:
            findings.append(Finding("warning", f"error {s.name} is marked unobservable but moves the {what} "
                                               f"(line {line})", s.line, f"symbols.{s.name}.unobservable"))
            continue
        if moves or moves is None or s.unobservable:   # None: finite nowhere (_not_real said where)
            continue
        if s.role == "error":
            message = (f"error {s.name} never moves the {what}: its gain is zero at every pose "
                       f"(line {line}); it cannot be measured or compensated — check where it sits in the "
                       f"chain (e.g. a rotation about an axis through the tool point, or a translation "
                       f"cancelled later); if that is known, mark it 'unobservable: true'")
        else:
            message = f"axis {s.name} never moves the {what} (line {line})"
        findings.append(Finding("warning", message, s.line, f"symbols.{s.name}"))
    return _limit_units(machine) + findings + _parallel_axes(machine) + _exact_irrational_angles(machine)


# limits in rad written for an axis declared in deg (or the other way round): pi/2, pi, 2 pi
# as degrees, or 90, 180, 360 as radians (14, 29, 57 turns)
_RAD_LIKE = {math.pi / 2: "pi/2", math.pi: "pi", 2 * math.pi: "2 pi"}
_DEG_LIKE = (90.0, 180.0, 270.0, 360.0, 720.0)


def _limit_units(machine: Machine) -> list[Finding]:
    """An angular axis whose limits read as written in the other unit of angle."""
    out = []
    for s in machine.axes:
        lo, hi = s.limits
        if s.unit.name == "deg":
            words = ["0" if x == 0 else next((("-" if x < 0 else "") + w for v, w in _RAD_LIKE.items()
                                               if abs(abs(x) - v) <= 5e-3 * v), None) for x in (lo, hi)]
            if None not in words and words != ["0", "0"]:
                out.append(Finding("warning", f"axis {s.name}'s limits [{lo:g}, {hi:g}] deg look like radians "
                                              f"({', '.join(words)}): a travel of only {hi - lo:.3g} deg; if they "
                                              f"are radians, write [{math.degrees(lo):.4g}, {math.degrees(hi):.4g}] "
                                              "or declare the axis in rad", s.line, f"symbols.{s.name}.limits"))
        elif s.unit.name == "rad" and any(abs(abs(x) - v) < 1e-9 for x in (lo, hi) for v in _DEG_LIKE):
            turns = (hi - lo) / (2 * math.pi)
            out.append(Finding("warning", f"axis {s.name}'s limits [{lo:g}, {hi:g}] rad are {turns:.3g} turns: if "
                                          "they are degrees, declare the axis in deg",
                               s.line, f"symbols.{s.name}.limits"))
    return out


def _parallel_axes(machine: Machine) -> list[Finding]:
    """A d error next to (nearly) parallel consecutive joint axes is ill-conditioned: the
    common normal is then barely defined, and a tilt of micro-radians moves it by metres (the
    d values of calibrations that fit it run to hundreds of metres). Hayati's beta, a rotation
    about y, describes the same freedom well."""
    at = {s.name: s.reference_value for s in machine.symbols}
    # joints are numbered per loop branch: each branch starts again at 1
    branches: list[dict] = []
    for j in machine.joint_list:
        if j[0] == 1 or not branches:
            branches.append({})
        branches[-1][j[0]] = j
    out = []
    for joints in branches:
        out += _parallel_in_branch(machine, joints, at)
    return out


def _parallel_in_branch(machine: Machine, joints: dict, at: dict) -> list[Finding]:
    out = []
    for number, kind, alpha, _errors, line in joints.values():
        if abs(math.sin(alpha.value(at))) > 1e-3:
            continue
        # dh: joint J's alpha turns to joint J+1's axis, whose d is then ill-conditioned;
        # mdh: joint J's alpha is the twist from joint J-1's axis to its own, its own d (joint
        # 1's is from the base frame, which fixes d1). The beta tilting the later axis of the
        # pair about y sits after the earlier joint (Hayati's beta_J in link J); one after the
        # later joint tilts the next pair instead, where nothing is missing.
        first = number if kind == "dh" else number - 1
        target = joints.get(number + 1) if kind == "dh" else joints[number]
        if first not in joints or target is None or "d" not in target[3]:
            continue
        name = target[3]["d"]
        out.append(Finding("warning", f"joint {target[0]}'s axis is (nearly) parallel to joint "
                                      f"{first}'s (alpha {alpha.value(at):g} "
                                      f"rad, line {line}): its d error {name} is ill-conditioned; drop it and add "
                                      f"Hayati's {{beta: 0, errors: auto}} after joint {first}",
                           machine.symbol(name).line, f"symbols.{name}"))
    return out


def _exact_irrational_angles(machine: Machine) -> list[Finding]:
    """A rotation by a constant whose sine and cosine sympy keeps as exact irrationals (pi/4:
    sqrt(2)/2; pi/6: sqrt(3)/2). The derivation carries them as atoms, which the fast printer
    of derive and report does not take: they print through sympy, Franka's Panda (its hand
    turned by -pi/4) at order 2 in 35 s instead of 2 s. A decimal angle, or one whose sine and
    cosine are rational (pi/2, pi), is a number (expressions.sin_cos). Quarter turns are passed
    over by their value first, so that a load (eval) need not import sympy."""
    errors = {s.name for s in machine.errors}
    at_zero = dict.fromkeys(errors, 0.0)

    def quarter_turn(el) -> bool:
        k = el.expr.value(at_zero) / (math.pi / 2)
        return abs(k - round(k)) <= 1e-12 * max(1.0, abs(k))
    rotations = [el for el in machine.tool_chain + machine.workpiece_chain
                 if isinstance(el, Rotation) and el.expr.names <= errors and not quarter_turn(el)]
    if not rotations:
        return []
    import sympy as sp

    from ..model.expressions import sin_cos
    zero = {s.sym: sp.Integer(0) for s in machine.errors}
    out = []
    for el in rotations:
        angle = el.angle.xreplace(zero)
        if not angle.is_number:
            continue
        exact = [v for v in sin_cos(angle) if not (v.is_Rational or v.is_Float)]
        if exact:
            out.append(Finding("warning", f"the rotation by {el.expr.source} has the exact sine and cosine "
                                          f"{', '.join(map(sp.sstr, sin_cos(angle)))}: derive and report print "
                                          "formulas holding them through sympy, tens of times slower (Franka's Panda "
                                          "with pi/4 at order 2: 35 s, with 0.785398163397448: 2 s); write the "
                                          "angle as a decimal if its exact form does not matter",
                               el.line, "chain"))
    return out
