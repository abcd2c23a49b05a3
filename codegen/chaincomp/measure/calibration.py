"""Synthetic laser-interferometer calibrations: each slide's component errors as smooth,
plausible tables over its travel (ISO 230-1 component errors as an ISO 230-2 style
measurement would give them), for trying tables without a machine at hand.

A slide is a chain element translating along exactly one linear axis, followed directly
by an error block (``errors: {dx: .., ey: ..}``) whose symbols are all errors: those are
the slide's component errors. Each is classed from the chain itself: a translation along
the slide's direction is its positioning error, across it a straightness, a rotation about
the slide's direction its roll, about another axis a tilt (pitch or yaw).

Shapes (each a random draw from the seed):
  * tilts and roll: a bow and a few long waves, a few arcsec peak to peak, zero at the
    first point (a laser angular measurement is relative to its start);
  * positioning: a linear scale error of 5-15 µm/m plus waves of about 1-3 µm, zero at
    the first point;
  * straightness: what the slide's tilts make of the travel (the integral of the angle
    that turns the direction of travel towards that direction), with the best-fit line
    removed as ISO 230-1 reports it, plus a fraction of a µm of waviness.
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass

import numpy as np
import sympy as sp

from ..errors import ChaincompError
from ..escape import one_line
from ..model.machine import Machine, Rotation, Translation
from ..model.varying import MAX_TABLE_KNOTS, MAX_VARYING_ERRORS, Varying

ARCSEC = math.pi / 648000.0
# The table's value unit per error kind (values written with 4 decimals: 0.1 nm, 0.0001")
VALUE_UNIT = {"length": "um", "angle": "arcsec", "ratio": "ppm"}
VALUE_SCALE = {"length": 1e-3, "angle": ARCSEC, "ratio": 1e-6}   # one value unit, internal
_AXIS_VEC = {"x": np.array([1.0, 0, 0]), "y": np.array([0, 1.0, 0]), "z": np.array([0, 0, 1.0])}


@dataclass
class Component:
    error: str       # symbol name
    kind: str        # positioning | straightness | roll | tilt
    coeff: float     # d (translation component or rotation angle) / d error at zero errors
    direction: np.ndarray  # translation: the component's unit vector; rotation: its axis


@dataclass
class Slide:
    axis: str
    direction: np.ndarray   # unit vector of travel at zero errors
    components: list[Component]
    line: int


def _groups(chain):
    out: list[list] = []
    for el in chain:
        if out and out[-1][0].line == el.line:
            out[-1].append(el)
        else:
            out.append([el])
    return out


def _free(el) -> set:
    exprs = (el.angle,) if isinstance(el, Rotation) else el.vector
    return set().union(*(e.free_symbols for e in exprs))


def find_slides(machine: Machine) -> list[Slide]:
    """The slides of ``machine`` with the component errors of the block after each."""
    roles = {s.sym: s for s in machine.symbols}
    base = {s.sym: 0.0 for s in machine.errors}
    base.update({s.sym: s.to_internal(s.nominal) for s in machine.constants})
    slides: list[Slide] = []

    def error_block(g) -> bool:
        syms = set().union(*(_free(e) for e in g)) if g else set()
        return bool(syms) and all(roles[s].role == "error" for s in syms)

    def negated(g) -> bool:  # every error entered with a minus sign: the inverse of a tool-side block
        return all(float(sp.diff(v, sym).subs(base)) < 0 for el in g for sym in _free(el)
                   for v in ((el.angle,) if isinstance(el, Rotation) else el.vector) if sym in v.free_symbols)

    for chain, workpiece in ((machine.tool_chain, False), (machine.workpiece_chain, True)):
        groups = _groups(chain)
        for i, g in enumerate(groups):
            syms = set().union(*(_free(e) for e in g))
            axes = [s for s in syms if roles[s].role == "axis"]
            if len(axes) != 1 or roles[axes[0]].unit.kind != "length" or \
                    not all(isinstance(e, Translation) for e in g):
                continue
            before = groups[i - 1] if i > 0 else None
            after = groups[i + 1] if i + 1 < len(groups) else None
            # a moving table written as the docs say (errors negated, then the translation:
            # the inverse of the tool-side pair) has its block before; otherwise it follows
            if workpiece and error_block(before) and negated(before):
                nxt = before
            elif error_block(after):
                nxt = after
            else:
                continue
            ax = axes[0]
            at0 = {**base, ax: 0.0}
            u = np.array([sum(float(sp.diff(v, ax).subs(at0)) for e in g for v in (e.vector[c],))
                          for c in range(3)])
            if not np.linalg.norm(u) > 0:
                continue
            u = u / np.linalg.norm(u)
            comps = []
            for el in nxt:
                for sym in sorted(_free(el), key=str):
                    if isinstance(el, Translation):
                        for c in range(3):
                            k = float(sp.diff(el.vector[c], sym).subs(at0))
                            if k:
                                vec = np.eye(3)[c]
                                kind = "positioning" if abs(vec @ u) > 0.99 else "straightness"
                                comps.append(Component(str(sym), kind, k, vec))
                    else:
                        k = float(sp.diff(el.angle, sym).subs(at0))
                        w = _AXIS_VEC[el.axis]
                        comps.append(Component(str(sym), "roll" if abs(w @ u) > 0.99 else "tilt", k, w))
            slides.append(Slide(roles[ax].name, u, comps, g[0].line))
    return slides


def slide_axis(machine: Machine, error: str) -> str | None:
    """The axis of the slide whose error block holds ``error``, or None."""
    return next((sl.axis for sl in find_slides(machine) if any(c.error == error for c in sl.components)), None)


_ISO_NAME = re.compile(r"E[XYZABC]([A-Z])")   # ISO 230-1: E, the component, the axis (EXX, EBY, ...)


def varying_axis(machine: Machine, error: str) -> str | None:
    """The axis an error varies along, by its ISO 230-1 name (EXX: along X) where the machine has
    that axis, else the slide whose error block holds it; None when neither tells."""
    m = _ISO_NAME.fullmatch(error)
    if m and m.group(1) in {a.name for a in machine.axes}:
        return m.group(1)
    return slide_axis(machine, error)


def _smooth(rng, s: np.ndarray, cycles: tuple[float, float], waves: int = 3, bow: float = 1.0) -> np.ndarray:
    """A smooth random curve over s in [0, 1], unit peak to peak."""
    f = bow * rng.uniform(-1, 1) * (s - 0.5) ** 2 + 0.3 * bow * rng.uniform(-1, 1) * (s - 0.5) ** 3
    for j in range(waves):
        f = f + rng.uniform(0.3, 1.0) / (j + 1) * np.sin(2 * np.pi * rng.uniform(*cycles) * s
                                                         + rng.uniform(0, 2 * np.pi))
    span = np.ptp(f)
    return f / span if span > 0 else f


def simulate(machine: Machine, knots: int, seed: int) -> dict[str, tuple[str, np.ndarray, np.ndarray]]:
    """{error: (axis, positions in the axis' declared unit, values in VALUE_UNIT)} for every
    slide's component errors."""
    if not 2 <= knots <= MAX_TABLE_KNOTS:   # the loaders' bound (runtime: kMaxTableKnots)
        raise ChaincompError(f"--knots must be between 2 and {MAX_TABLE_KNOTS}, got {knots}")
    slides = find_slides(machine)
    if not slides:
        raise ChaincompError(f"{machine.name} has no slide followed by an error block (a translation along "
                             "one linear axis, then 'errors: {...}') to tabulate", machine.file)
    n_tables = sum(len(s.components) for s in slides)
    if n_tables > MAX_VARYING_ERRORS:
        raise ChaincompError(f"{machine.name}'s slides have {n_tables} component errors, more tables than a "
                             f"params file may hold ({MAX_VARYING_ERRORS})", machine.file)
    rng = np.random.default_rng(seed)
    out = {}
    for slide in slides:
        a = machine.symbol(slide.axis)
        lo, hi = a.limits
        pos = np.linspace(lo, hi, knots)
        fine = np.linspace(lo, hi, 20 * (knots - 1) + 1)
        s = (fine - lo) / (hi - lo)
        angles = {}                               # actual rotation (rad) about each world axis, on `fine`
        values = {}                               # internal units on `fine`
        for c in slide.components:
            if c.kind in ("roll", "tilt"):
                pp = rng.uniform(4, 10) if c.kind == "tilt" else rng.uniform(2, 6)
                theta = _smooth(rng, s, (0.5, 3.0)) * pp * ARCSEC
                theta = theta - theta[0]
                angles[c.error] = (c.direction, theta * 1.0)
                values[c.error] = theta / c.coeff
        for c in slide.components:
            if c.kind == "positioning":
                scale = rng.uniform(5, 15) * rng.choice([-1, 1]) * 1e-6   # per unit length
                waves = _smooth(rng, s, (2.0, 8.0), bow=0.3) * rng.uniform(1, 3) * 1e-3
                d = scale * (fine - lo) * a.unit.to_internal + waves - waves[0]
                values[c.error] = d / c.coeff
            elif c.kind == "straightness":
                # d s_v / d x = sum over tilts of theta_w (w x u) . v
                rate = np.zeros_like(fine)
                for w, theta in angles.values():
                    rate = rate + theta * (np.cross(w, slide.direction) @ c.direction)
                dx = np.diff(fine) * a.unit.to_internal
                d = np.concatenate([[0.0], np.cumsum(0.5 * (rate[1:] + rate[:-1]) * dx)])
                d = d + _smooth(rng, s, (1.0, 6.0), bow=0.5) * rng.uniform(0.3, 0.8) * 1e-3
                line = np.polyfit(s, d, 1)
                d = d - np.polyval(line, s)
                values[c.error] = d / c.coeff
        for c in slide.components:
            kind = machine.symbol(c.error).unit.kind
            v = values[c.error][::20] / VALUE_SCALE[kind]
            out[c.error] = (slide.axis, pos, np.round(v, 4) + 0.0)
    return out


def _num(v: float) -> str:
    text = f"{v:.10g}"
    return "0" if text == "-0" else text


def write(path: str, machine: Machine, tables: dict, constants: dict, header: list[str],
          interpolation: str, outside: str) -> None:
    """A params file: the tables, then every other error as a constant in its declared unit."""
    lines = [f"# {one_line(h)}" if h else "#" for h in header]
    lines += [f"machine: {machine.name}", "description: synthetic laser calibration (chaincomp "
              "simulate-calibration); not measured on any machine", "values:"]
    for s in machine.errors:
        if s.name in tables:
            axis, pos, vals = tables[s.name]
            a = machine.symbol(axis)
            unit = VALUE_UNIT[s.unit.kind]
            lines += [f"  {s.name}:   # {one_line(s.meaning)}",
                      f"    axis: {axis}",
                      f"    units: [{a.unit.name}, {unit}]",
                      f"    interpolation: {interpolation}",
                      f"    outside: {outside}",
                      "    table:"]
            lines += [f"      - [{_num(p)}, {v:.4f}]" for p, v in zip(pos, vals)]
        elif s.name in constants:
            v = constants[s.name]
            if isinstance(v, Varying):
                raise ChaincompError(f"--base gives {s.name} as a table or polynomial: give constants for the "
                                     "errors that are not tabulated")
            lines.append(f"  {s.name}: {s.from_internal(v):.10g} {s.unit.name}   # {one_line(s.meaning)}")
    _write_loadable(path, "\n".join(lines) + "\n", machine)


def _write_loadable(path: str, text: str, machine: Machine) -> None:
    """Write text to path only once the product's own loader reads it back: written beside
    it first, loaded, then renamed over it (an old file at path stays whole until then)."""
    from ..model.params import load_params
    from ..output import write_file

    def check(tmp: str) -> None:
        try:
            load_params(tmp, machine)
        except ChaincompError as exc:
            raise ChaincompError(f"refusing to write a file that would not load back: {exc.message}", path,
                                 exc.line, exc.field) from None
    write_file(path, text, check)
