"""Shared by the end-to-end scenarios: the default machine, its toolpath, the exact check."""

import math
import os

import numpy as np

from chaincomp import load_machine, load_params
from chaincomp.symbolic.numeric import ExactModel

from lcm_harness import ROOT

MACHINE = os.path.join(ROOT, "configs", "machines", "five_axis_ac.yaml")
# CHAINCOMP_E2E_PARAMS runs the scenarios with another params file (e.g. one with tables)
PARAMS = os.environ.get("CHAINCOMP_E2E_PARAMS") or os.path.join(ROOT, "configs", "params", "five_axis_ac-demo.yaml")
HERE = os.path.dirname(os.path.abspath(__file__))


def toolpath(n: int) -> np.ndarray:
    """A tilted-tool circle (mm, deg), sampled so consecutive steps stay small."""
    t = np.linspace(0, 2 * math.pi, n, endpoint=False)
    return np.stack([100 * np.cos(t), 80 * np.sin(t), -200 + 20 * np.sin(2 * t),
                     30 + 10 * np.sin(t), -45 + 40 * np.sin(t)], axis=1)


def exact_check(commands: np.ndarray, targets: np.ndarray, machine: str = MACHINE,
                params: str = PARAMS) -> tuple[float, float]:
    """Largest point (mm) and direction (rad) difference between the actual pose at the
    targets and the nominal pose at the commands, by the independent exact chain."""
    dp, dd = exact_errors(commands, targets, machine, params)
    return float(np.max(dp)), float(np.max(dd))


def exact_errors(commands: np.ndarray, targets: np.ndarray, machine: str = MACHINE,
                 params: str = PARAMS, added: dict | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Per target: the point (mm) and direction (rad) difference between the actual pose at
    the target and the nominal pose at its command, by the independent exact chain; `added`:
    values (internal units, one per target) added to some errors (a thermal drift)."""
    m = load_machine(machine)
    exact = ExactModel(m)
    base = m.nominal_values()
    base.update(load_params(params, m))
    for name, extra in (added or {}).items():
        base[name] = base[name] + np.asarray(extra, float)
    nominal = {k: (0.0 if m.symbol(k).role == "error" else v) for k, v in base.items()}
    def pose(values, axes):
        v = dict(values)
        for i, a in enumerate(m.axes):
            v[a.name] = axes[:, i] * a.unit.to_internal
        p, d = exact.pose(v)
        return np.array(p), np.array(d)
    p_act, d_act = pose(base, targets)
    p_nom, d_nom = pose(nominal, commands)
    return np.linalg.norm(p_act - p_nom, axis=0), np.linalg.norm(d_act - d_nom, axis=0)
