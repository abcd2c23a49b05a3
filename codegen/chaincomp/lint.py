"""Modelling mistakes that load without error but cannot be what the author meant: an
error symbol that never moves the tool (its gain is zero on every component at every pose),
an axis that never moves it. Loading already refuses what is wrong outright (unknown or
unused symbols, expressions that are not finite, real and analytic in the errors).

The check is numeric: central differences of the exact model at a few poses drawn within
the axis limits (seeded, so the findings do not change from run to run); a gain that is
not identically zero vanishes at all of them only by coincidence of measure zero.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .machine import Machine, Rotation
from .numeric import ExactModel

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
    sym = machine.symbol(name).sym
    for el in machine.tool_chain + machine.workpiece_chain:
        exprs = (el.angle,) if isinstance(el, Rotation) else el.vector
        if any(sym in e.free_symbols for e in exprs) and el.line:
            return el.line
    return machine.symbol(name).line


def _poses(machine: Machine) -> dict[str, np.ndarray]:
    rng = np.random.default_rng(20031)
    return {s.name: s.to_internal(rng.uniform(*s.limits, POSES)) for s in machine.axes}


def _moves_tool(model: ExactModel, values: dict, name: str) -> bool:
    up, down = dict(values), dict(values)
    up[name] = values[name] + _STEP
    down[name] = values[name] - _STEP
    (p1, d1), (p0, d0) = model.pose(up), model.pose(down)
    parts = list(p1) + (list(d1) if d1 else [])
    base = list(p0) + (list(d0) if d0 else [])
    return any(np.max(np.abs((np.asarray(a) - np.asarray(b)) / (2 * _STEP))) > _ZERO for a, b in zip(parts, base))


def lint(machine: Machine, model: ExactModel | None = None) -> list[Finding]:
    """Warnings about ``machine``, in the order of its symbols."""
    model = model or ExactModel(machine)
    values = {**_poses(machine), **{s.name: np.zeros(POSES) for s in machine.errors}}
    findings = []
    what = "tool point or direction" if machine.tool_direction else "tool point"
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
        if moves or s.unobservable:
            continue
        if s.role == "error":
            message = (f"error {s.name} never moves the {what}: its gain is zero at every pose "
                       f"(line {line}); it cannot be measured or compensated — check where it sits in the "
                       f"chain (e.g. a rotation about an axis through the tool point, or a translation "
                       f"cancelled later); if that is known, mark it 'unobservable: true'")
        else:
            message = f"axis {s.name} never moves the {what} (line {line})"
        findings.append(Finding("warning", message, s.line, f"symbols.{s.name}"))
    return findings
